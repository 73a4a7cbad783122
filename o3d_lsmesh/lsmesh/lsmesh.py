"""Least-squares meshes: geometry from connectivity and a few control points.

Sorkine and Cohen-Or, *Least-squares Meshes* (SMI 2004), eq. 3 and its weighted form of section 6; the
interpolatory scheme and the relaxed-anchor updates of Sorkine et al., *Geometry-aware Bases for Shape
Approximation* (sections II.A, II.B, III). Docs: ``docs/algorithms/least_squares_meshes.rst``.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from .._o3d import MeshData, new_mesh, read_mesh
from .._o3d.state import mesh_from_state, mesh_state
from ..core import operators
from ..core.connectivity import Connectivity
from ..core.errors import InputError, SingularSystemError
from ..core.progress import Progress
from ..core.solve import Plan, SPDSolver, check_constant_modes, check_finite, operator_scale, solver_backend
from ..core.tuning import DEFAULT_TOLERANCE
from ..core.validate import as_bool, as_choice, as_indices, as_positions, as_weights

if TYPE_CHECKING:
    from .._types import AnyMesh, MeshT

__all__ = ["LSMeshSolver", "LSMeshSystem", "check_components_constrained", "ls_mesh", "reconstruct_geometry"]


def check_components_constrained(
    graph: sp.spmatrix, constrained: np.ndarray, *, what: str, param: str | None = None
) -> np.ndarray:
    """Component labels ``(n,)`` of ``graph`` (an ``(n, n)`` matrix of the edge pattern), or
    :class:`SingularSystemError` if a component (an unreferenced vertex is one) has no ``constrained`` index."""
    count, labels = csgraph.connected_components(graph, directed=False)
    has = np.zeros(count, dtype=bool)
    has[labels[constrained]] = True
    missing = int(count - has.sum())
    if missing:
        first = int(np.flatnonzero(~has[labels])[0])
        raise SingularSystemError(
            f"every connected component needs at least one {what}, got {missing} of {count} components "
            f"without one (first at vertex {first}); the least-squares system would be singular",
            param=param,
        )
    return labels


class LSMeshSystem:
    """The array core of :class:`LSMeshSolver` (its options and methods) on ``(n, 3) float64`` vertices and
    ``(m, 3) int64`` triangles as :func:`~o3d_lsmesh.core.validate.mesh_arrays` returns them (held, not copied).

    >>> from o3d_lsmesh.core.validate import mesh_arrays
    >>> V, F = mesh_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1]], [[0, 1, 2], [1, 3, 2]])
    >>> LSMeshSystem(V, F, [0, 3], interpolate=True).solve().shape
    (4, 3)
    """

    def __init__(
        self,
        vertices: np.ndarray,
        triangles: np.ndarray,
        constraint_vertex_indices: Any,
        *,
        weights: Any = 1.0,
        interpolate: bool = False,
        laplacian: str = "uniform",
        backend: str = "auto",
        ordering: str = "default",
        solver: str = "auto",
        tol: float | None = None,
        progress: bool = False,
        _conn: Connectivity | None = None,
    ) -> None:
        n = len(vertices)
        indices = as_indices(
            constraint_vertex_indices, n, name="constraint_vertex_indices", allow_repeats=True
        )
        weights = as_weights(weights, len(indices), name="weights")
        as_choice(laplacian, operators.LAPLACIAN_KINDS, name="laplacian")
        interpolate = as_bool(interpolate, name="interpolate")
        # one lock: an update and a solve on other threads never see a half-updated system
        self._lock = threading.RLock()
        backend = solver_backend(solver, backend)
        # the caller's connectivity of these triangles when it holds one (one grouping per call)
        conn = Connectivity(triangles, n) if _conn is None else _conn
        L = operators.laplacian_of_kind(vertices, conn, laplacian).tocsr()
        labels = check_components_constrained(
            L, indices, what="control vertex", param="constraint_vertex_indices"
        )
        if not interpolate:
            # squares of huge weights overflow; tiny ones leave a component's translation to round-off
            check_finite(lambda: weights**2, name="weights", what="weights**2")
            pinned = np.zeros(n)
            np.add.at(pinned, indices, weights**2)
            check_constant_modes(
                L.T @ (L @ np.ones(n)) + pinned,
                labels,
                scale=operator_scale(L),
                name="weights",
                value=weights,
                what="the control weights",
            )
        del labels
        self._vertices, self._triangles = vertices, triangles
        self.interpolate = bool(interpolate)
        self.laplacian = laplacian
        self._hard = indices if self.interpolate else np.zeros(0, dtype=np.int64)
        self._soft = np.zeros(0, dtype=np.int64) if self.interpolate else indices
        self._soft_weights = np.zeros(0) if self.interpolate else weights
        self._hard_weights = weights if self.interpolate else np.zeros(0)
        self._positions = vertices[indices].copy()
        if self.interpolate:
            free = np.ones(n, dtype=bool)
            free[indices] = False
            self._free: np.ndarray | None = np.flatnonzero(free)
            # reduced index of every vertex (-1 for eliminated ones)
            self._reduced: np.ndarray | None = np.where(free, np.cumsum(free) - 1, -1)
            L = L.tocsc()
            L_free = L[:, self._free]
            operator = L_free.tocsr()
            product = operator.T  # L_free^T L_free as a product never formed (L_free's CSR arrays, shared)
            # -L_free^T L_ctrl maps control positions to the free rhs; a vertex fixed twice is one column
            _, first, self._hard_groups = np.unique(indices, return_index=True, return_inverse=True)
            self._hard_first = first if len(first) < len(indices) else None
            columns = indices if self._hard_first is None else indices[first]
            self._rhs_hard = -(L_free.T @ L[:, columns]).tocsr()
            locality = None
        else:
            self._free = self._reduced = None  # every vertex is unknown: no index arrays to hold
            # L^T L + W^2 = A A^T for A = [L^T | W] (one weighted column per control vertex), never formed
            controls = sp.csc_matrix((weights, indices, np.arange(len(indices) + 1)), shape=(n, len(indices)))
            product = sp.hstack([L.T, controls], format="csc")
            # the iterative path's locality order: the 1-ring, L^T, a view of the product's first n columns
            end = product.indptr[n]
            locality = sp.csc_matrix(
                (product.data[:end], product.indices[:end], product.indptr[: n + 1]), (n, n)
            )
            operator = None  # rebuilt for refinement: not held while the factor is formed
            self._rhs_hard = None
            self._hard_first = None
        self._operator = operator  # L (of the free columns) for the refinement residual L^T (L x)
        del L  # not held while CHOLMOD factors
        self._updated = False
        self._n = n
        self._unknowns = n if self._free is None else len(self._free)
        self._solver = SPDSolver(
            backend=backend,
            ordering=ordering,
            progress=progress,
            tol=DEFAULT_TOLERANCE if tol is None else tol,
            _plan=Plan(product_of=product, locality_of=locality),
        )

    def _reduce(self, indices: np.ndarray) -> np.ndarray:  # row of each (free) vertex in the reduced system
        return indices if self._reduced is None else self._reduced[indices]

    @property
    def backend(self) -> str:
        """Solver backend that ran: ``"cholmod"`` or ``"scipy"``."""
        return self._solver.backend

    @property
    def constraint_vertex_indices(self) -> np.ndarray:
        """All control vertices in order: the initial ones, then every added anchor."""
        with self._lock:  # never half of an add_anchors() running on another thread
            return np.concatenate([self._hard, self._soft])

    @property
    def weights(self) -> np.ndarray:
        """Weight of each control vertex, in :attr:`constraint_vertex_indices` order."""
        with self._lock:
            return np.concatenate([self._hard_weights, self._soft_weights])

    def solve(self, constraint_vertex_positions: Any = None, *, refine: bool | None = None) -> np.ndarray:
        """Vertex positions ``(n, 3)`` for control positions ``(k, 3)`` (default: those given so far), by
        back-substitution; ``refine``: one step of iterative refinement (default: only after :meth:`add_anchors`)."""
        refine = as_bool(refine, name="refine", allow_none=True)
        with self._lock:
            return self._solve(constraint_vertex_positions, refine)

    def _solve(self, constraint_vertex_positions: Any, refine: bool | None) -> np.ndarray:
        k = len(self._hard) + len(self._soft)
        if constraint_vertex_positions is None:
            positions = self._positions
        else:
            positions = as_positions(
                constraint_vertex_positions, k, name="constraint_vertex_positions", limit=True
            )
        # about the controls' centroid (L 1 = 0): the iterative path's residual measures the shape
        centre = positions.mean(axis=0) if len(positions) else np.zeros(3)
        original, positions = positions, positions - centre
        hard_pos, soft_pos = positions[: len(self._hard)], positions[len(self._hard) :]
        fixed = hard_pos
        if self._hard_first is not None:  # checked on the given rows (a disagreement in the caller's terms)
            fixed = self._fixed_positions(original[: len(self._hard)]) - centre
        rhs = np.zeros((self._unknowns, 3))
        if self.interpolate:
            rhs += self._rhs_hard @ fixed
        with np.errstate(over="ignore", invalid="ignore"):  # overflow reported below; add.at: repeats add up
            np.add.at(rhs, self._reduce(self._soft), (self._soft_weights**2)[:, None] * soft_pos)
        check_finite(rhs, name="constraint_vertex_positions", what="weights**2 * constraint_vertex_positions")
        start = None  # the iterative path starts from the mesh's own geometry
        if self._solver.backend == "iterative":
            start = (self._vertices if self._free is None else self._vertices[self._free]) - centre
        solution = self._solver.solve(rhs, x0=start)
        if self._updated if refine is None else refine:
            reduced_soft = self._reduce(self._soft)
            if self._operator is None:
                conn = Connectivity(self._triangles, len(self._vertices))
                self._operator = operators.laplacian_of_kind(self._vertices, conn, self.laplacian).tocsr()
            residual = -(self._operator.T @ (self._operator @ solution))
            if self.interpolate:
                residual += self._rhs_hard @ fixed
            np.add.at(
                residual, reduced_soft, (self._soft_weights**2)[:, None] * (soft_pos - solution[reduced_soft])
            )
            solution = solution + self._solver.solve(residual)
        solution += centre
        if not self.interpolate:
            return solution
        result = np.zeros((self._n, 3))
        result[self._free] = solution
        result[self._hard] = original[: len(self._hard)]  # the given positions, not shifted and back
        return result

    def _fixed_positions(self, hard_pos: np.ndarray) -> np.ndarray:
        """One position per distinct fixed vertex; the rows naming one vertex must agree."""
        fixed = hard_pos[self._hard_first]
        differ = (fixed[self._hard_groups] != hard_pos).any(axis=1)
        if differ.any():
            row = int(np.flatnonzero(differ)[0])
            raise InputError(
                "constraint_vertex_positions must agree where constraint_vertex_indices name one vertex "
                f"twice (copies of a welded vertex) with interpolate=True, got {hard_pos[row].tolist()} at "
                f"row {row} and {fixed[self._hard_groups[row]].tolist()}",
                param="constraint_vertex_positions",
            )
        return fixed

    def add_anchors(self, indices: Any, positions: Any = None, *, weights: Any = 1.0) -> None:
        """Add relaxed anchors by a rank-k update of the kept factor (bases paper, section III).

        ``indices (a,)``: new anchors, none already a control vertex; ``positions (a, 3)``: default the
        mesh's own; ``weights``: positive, a float or ``(a,)``. Adds ``w^2`` to the normal matrix's diagonal.
        """
        with self._lock:
            self._add_anchors(indices, positions, weights)

    def _add_anchors(self, indices: Any, positions: Any, weights: Any) -> None:
        n = self._n
        new = as_indices(indices, n, name="indices", allow_repeats=True)
        existing = np.zeros(n, dtype=bool)
        existing[self._hard] = existing[self._soft] = True  # (not the property: LSMeshSolver maps it)
        if existing[new].any():
            at = int(np.flatnonzero(existing[new])[0])
            raise InputError(
                f"indices must not already be control vertices, got {int(new[at])} at position {at}",
                param="indices",
            )
        w = as_weights(weights, len(new), name="weights")
        if positions is None:
            pos = self._vertices[new]
        else:
            pos = as_positions(positions, len(new), name="positions", limit=True)
        # one nonzero per column: the CSC arrays directly
        c = sp.csc_matrix((w, self._reduce(new), np.arange(len(new) + 1)), shape=(self._unknowns, len(new)))
        self._solver.update(c)
        self._updated = True
        self._soft = np.concatenate([self._soft, new])
        self._soft_weights = np.concatenate([self._soft_weights, w])
        self._positions = np.concatenate([self._positions, pos])

    def __getstate__(self) -> dict:
        with self._lock:
            state = self.__dict__.copy()
        del state["_lock"]
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._lock = threading.RLock()


class LSMeshSolver(LSMeshSystem):
    """A least-squares mesh system with its Cholesky factor kept for editing.

    Minimizes ``||L X||^2 + sum_s w_s^2 |X_s - C_s|^2`` (eq. 3, section 6): :meth:`solve` is a
    back-substitution, :meth:`add_anchors` a rank-k update. Thread-safe; pickles. Docs:
    ``docs/algorithms/least_squares_meshes.rst``.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
        Its connectivity and default control positions; equal-coordinate vertices (UV seams) are welded.
    constraint_vertex_indices : (k,) int array-like
    weights : float or (k,) array-like
        Positive weights ``w_s`` of the soft constraints (ignored when ``interpolate``).
    interpolate : bool
        Hit the control vertices exactly (bases paper II.B).
    laplacian, backend, ordering : str
        ``"uniform"``/``"cotangent"``; the direct backend and CHOLMOD ordering (:class:`~o3d_lsmesh.SPDSolver`).
    solver, tol
        ``"auto"`` factors unless the factor exceeds the memory budget (then conjugate gradients to ``tol``).
    progress : bool

    Raises
    ------
    SingularSystemError
        A connected component (or unreferenced vertex) without a control vertex.

    Examples
    --------
    >>> import open3d as o3d
    >>> sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=10)
    >>> LSMeshSolver(sphere, [0, 5, 40, 90]).solve().shape == (len(sphere.vertices), 3)
    True
    """

    def __init__(
        self,
        mesh: AnyMesh,
        constraint_vertex_indices: Any,
        *,
        weights: Any = 1.0,
        interpolate: bool = False,
        laplacian: str = "uniform",
        backend: str = "auto",
        ordering: str = "default",
        solver: str = "auto",
        tol: float | None = None,
        progress: bool = False,
    ) -> None:
        data = read_mesh(mesh, weld=True)
        self._data = data
        indices = data.welded_indices(constraint_vertex_indices, name="constraint_vertex_indices")
        options: dict[str, Any] = dict(weights=weights, interpolate=interpolate, laplacian=laplacian, tol=tol)
        options.update(backend=backend, ordering=ordering, solver=solver, progress=progress)
        super().__init__(data.vertices, data.triangles, indices, **options)

    @property
    def constraint_vertex_indices(self) -> np.ndarray:
        """All control vertices in order, the initial ones then every added anchor (input's layout)."""
        return self._data.source_indices(super().constraint_vertex_indices)

    def solve(self, constraint_vertex_positions: Any = None, *, refine: bool | None = None) -> np.ndarray:
        """Vertex positions ``(n, 3)`` in the input's layout; see :meth:`LSMeshSystem.solve`."""
        return self._data.source_positions(super().solve(constraint_vertex_positions, refine=refine))

    def mesh(self, constraint_vertex_positions: Any = None, *, refine: bool | None = None) -> AnyMesh:
        """The least-squares mesh as a new mesh of the input's kind (see :meth:`solve`); also after unpickling."""
        return new_mesh(self._data, super().solve(constraint_vertex_positions, refine=refine))

    def add_anchors(self, indices: Any, positions: Any = None, *, weights: Any = 1.0) -> None:
        """Add relaxed anchors (indices in the input's layout); see :meth:`LSMeshSystem.add_anchors`."""
        super().add_anchors(self._data.welded_indices(indices, name="indices"), positions, weights=weights)

    def __getstate__(self) -> dict:
        state = super().__getstate__()
        state["_data"] = mesh_state(self._data)  # Open3D meshes do not pickle
        return state

    def __setstate__(self, state: dict) -> None:
        state["_data"] = mesh_from_state(state["_data"])
        super().__setstate__(state)


def ls_mesh(
    mesh: MeshT,
    constraint_vertex_indices: Any,
    constraint_vertex_positions: Any = None,
    *,
    weights: Any = 1.0,
    interpolate: bool = False,
    laplacian: str = "uniform",
    solver: str = "auto",
    tol: float | None = None,
    progress: bool = False,
) -> MeshT:
    """Least-squares mesh: the fairest geometry for ``mesh``'s connectivity near the control points.

    Minimizes ``||L X||^2 + sum_s w_s^2 |X_s - C_s|^2`` (eq. 3, weights of section 6), or with
    ``interpolate=True`` ``||L X||^2`` with the control vertices fixed (bases paper II.B). Returns a new
    mesh of the input's kind (same triangles and colors).

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
    constraint_vertex_indices : (k,) int array-like
    constraint_vertex_positions : (k, 3) array-like, optional
        Default the mesh's own positions at those indices.
    weights, interpolate, laplacian, solver, tol, progress
        See :class:`LSMeshSolver`.

    Raises
    ------
    InputError
        Invalid mesh, indices, positions or weights (a ``ValueError``).
    SingularSystemError
        A connected component without a control vertex.

    Examples
    --------
    >>> import open3d as o3d
    >>> sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=10)
    >>> len(ls_mesh(sphere, [0, 5, 40, 90], weights=10.0).vertices) == len(sphere.vertices)
    True
    """
    data = read_mesh(mesh, weld=True)
    indices = data.welded_indices(constraint_vertex_indices, name="constraint_vertex_indices")
    options: dict[str, Any] = dict(weights=weights, interpolate=interpolate, laplacian=laplacian, tol=tol)
    options.update(solver=solver, progress=progress)
    vertices = solve_once("ls_mesh", progress, data, indices, constraint_vertex_positions, **options)
    return new_mesh(data, vertices)


def solve_once(
    desc: str, bar: bool, data: MeshData, indices: Any, positions: Any = None, **options: Any
) -> np.ndarray:
    """One :class:`LSMeshSystem` of ``data`` factored and solved under a two-stage bar, ``(n, 3)``."""
    with Progress(bar, desc).stages(("factor", "solve")) as begin:
        begin("factor")
        system = LSMeshSystem(data.vertices, data.triangles, indices, **options)
        begin("solve")
        return system.solve(positions)


def reconstruct_geometry(
    mesh: MeshT,
    unknown_vertex_indices: Any,
    *,
    interpolate: bool = True,
    weights: Any = 1.0,
    laplacian: str = "uniform",
    progress: bool = False,
    solver: str = "auto",
    tol: float | None = None,
) -> MeshT:
    """Rebuild the positions of vertices whose geometry is missing (figures 5 and 8 of LS meshes).

    ``interpolate=True``: the interpolatory LS mesh with every known vertex as an anchor, on the rows of
    ``L`` that touch an unknown vertex only (known vertices stay bit-identical); ``False``: every known
    vertex a soft control point of weight ``weights``. Other options: see :class:`LSMeshSolver`.

    Raises
    ------
    SingularSystemError
        A connected component in which every vertex is unknown.

    Examples
    --------
    >>> import open3d as o3d, numpy as np
    >>> sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=10)
    >>> np.asarray(reconstruct_geometry(sphere, np.arange(20)).vertices).shape == (len(sphere.vertices), 3)
    True
    """
    data = read_mesh(mesh)
    unknown = as_indices(unknown_vertex_indices, len(data.vertices), name="unknown_vertex_indices")
    # the unknown vertices' positions may be placeholders (all equal): welded only as copies matched
    # across a cut (a seam's; weld_map's guarded vertices)
    data = read_mesh(data, weld=True, guarded=unknown)
    n = len(data.vertices)
    unknown = data.welded_indices(unknown, name="unknown_vertex_indices", merge=True)
    known = np.setdiff1d(np.arange(n), unknown, assume_unique=True)  # in increasing order
    interpolate = as_bool(interpolate, name="interpolate")
    as_choice(laplacian, operators.LAPLACIAN_KINDS, name="laplacian")
    # checked with either scheme (the interpolatory one does not use them): a bad value is a mistake either way
    as_weights(weights, len(known), name="weights")
    as_bool(progress, name="progress")
    L = operators.laplacian_of_kind(data.vertices, Connectivity(data.triangles, n), laplacian).tocsc()
    # checked here for both schemes, so that the message names the known vertices the caller left
    check_components_constrained(
        L, known, what="known vertex (outside unknown_vertex_indices)", param="unknown_vertex_indices"
    )
    if not interpolate:
        options: dict[str, Any] = dict(weights=weights, laplacian=laplacian, solver=solver, tol=tol)
        return new_mesh(data, solve_once("reconstruct_geometry", progress, data, known, **options))
    with Progress(progress, "reconstruct_geometry").stages(("factor", "solve")) as begin:
        begin("factor")
        L_unknown = L[:, unknown].tocsr()
        rows = np.flatnonzero(np.diff(L_unknown.indptr) > 0)  # rows touching an unknown vertex
        A = L_unknown[rows]
        B = L[rows][:, known]
        normal = (A.T @ A).tocsc()
        # about the known vertices' centroid, as in LSMeshSystem.solve (the relative residual of CG)
        centre = data.vertices[known].mean(axis=0) if len(known) else np.zeros(3)
        rhs = -(A.T @ (B @ (data.vertices[known] - centre)))
        factor = SPDSolver(
            normal, backend=solver_backend(solver), tol=DEFAULT_TOLERANCE if tol is None else tol
        )
        begin("solve")
        vertices = data.vertices.copy()
        vertices[unknown] = factor.solve(rhs) + centre
    return new_mesh(data, vertices)

"""The mesh hierarchy of Liu et al. 2001 (section 4): levels, fine-to-coarse maps, vertex splits.

A :class:`MeshHierarchy` holds plain numpy arrays only (it pickles, and its
arrays are read-only, so concurrent reads are safe). Level ``0`` is the input;
level ``i`` is level ``i - 1`` after one batch of half-edge collapses, so every
vertex of level ``i`` is a vertex of the input and sits at its input position.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp

from .._o3d import MeshData, new_mesh, read_mesh, template, warn_dropped_attributes
from .._progress import check_progress, progress_bar
from .._solvers import solve_spd
from .._validate import as_count, as_positions, as_positive_float, mesh_arrays
from ..topology import VertexRings, vertex_rings

if TYPE_CHECKING:
    from .._types import AnyMesh

__all__ = ["MeshHierarchy", "build_hierarchy", "build_hierarchy_arrays"]

# Tuned constants of the volume-cost collapses (section 4.1), passed to the compiled loop; the levels'
# topology, volume, distances and time they give: benchmarks/results/hierarchy.md.
ALPHA = 1.0  # cost weight of the shortest incident edge (the paper's): hierarchy.md, per-level cross-check
BETA = 0.01  # cost weight of the longest incident edge: hierarchy.md, per-level cross-check
MAX_NORMAL_ANGLE = 60.0  # degrees a surviving triangle's normal may turn: hierarchy.md, per-level cross-check
MIN_QUALITY = (
    1e-3  # least 2 area / sum of squared edges of a moved triangle: hierarchy.md, per-level cross-check
)
MAX_TRIES = 3  # targets tried per vertex, least cone volume first: hierarchy.md, whole-hierarchy speed table
FILL_TIE = (
    1e-9  # split vertices' weak tie to their placeholders: a regularization far below round-off, not tuned
)


def _frozen(array: np.ndarray) -> np.ndarray:
    # a read-only view: the caller's own array (the input of build_hierarchy_arrays) stays writeable
    view = np.ascontiguousarray(array).view()
    view.flags.writeable = False
    return view


@dataclass(frozen=True, eq=False)
class MeshHierarchy:
    """Levels ``M_0, M_1, ..., M_L`` of decreasing size with the collapses between them.

    Build it with :func:`build_hierarchy` (volume-cost collapses) or
    :func:`~o3d_lsmesh.hierarchy.from_fast_simplification` (QEM collapses).

    Attributes
    ----------
    vertices : (n_0, 3) float64
        Input positions.
    triangles : tuple of (m_i, 3) int64
        Triangles of each level, in that level's vertex indices.
    representatives : tuple of (n_i,) int64
        Input index of every vertex of each level (level 0: ``arange(n_0)``).
    parents : tuple of (n_{i-1},) int64
        ``parents[i]`` maps level ``i - 1`` vertices to level ``i`` (``parents[0]`` is empty).
    removed, targets : tuple of (r_i,) int64
        Level-``i - 1`` indices of the vertices removed at level ``i`` and of the
        vertex each was merged into (empty for level 0).
    ring_offsets, rings : tuple of int64 arrays
        CSR 1-ring (level ``i - 1`` indices) of each removed vertex.
    independent : bool
        Whether every level's removed vertices are pairwise non-adjacent (true for
        :func:`build_hierarchy`); :meth:`refine` then splits them in closed form.
    method : str
        ``"volume"`` or ``"fast_simplification"``.
    mesh_kind : str
        Kind of mesh :meth:`level` returns: ``"legacy"``, ``"tensor"`` or ``"arrays"``.
    tensor_format : tuple of str
        ``(device, position dtype, index dtype)`` of a tensor input, else empty.
    """

    vertices: np.ndarray
    triangles: tuple
    representatives: tuple
    parents: tuple
    removed: tuple
    targets: tuple
    ring_offsets: tuple
    rings: tuple
    independent: bool
    method: str
    mesh_kind: str
    tensor_format: tuple = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "vertices", _frozen(self.vertices))
        for name in (
            "triangles",
            "representatives",
            "parents",
            "removed",
            "targets",
            "ring_offsets",
            "rings",
        ):
            object.__setattr__(self, name, tuple(_frozen(a) for a in getattr(self, name)))

    def __setstate__(self, state: dict) -> None:
        # pickle restores the arrays writeable: freeze them again, as construction does
        self.__dict__.update(state)
        self.__post_init__()

    # ------------------------------------------------------------------ queries
    def __len__(self) -> int:
        return len(self.triangles)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, MeshHierarchy):
            return NotImplemented
        for f in fields(self):
            a, b = getattr(self, f.name), getattr(other, f.name)
            if isinstance(a, np.ndarray):
                if not np.array_equal(a, b):
                    return False
            elif isinstance(a, tuple) and a and isinstance(a[0], np.ndarray):
                if len(a) != len(b) or not all(np.array_equal(x, y) for x, y in zip(a, b)):
                    return False
            elif a != b:
                return False
        return True

    __hash__ = None  # type: ignore[assignment]

    def _check_level(self, i: Any, *, minimum: int = 0, name: str = "i") -> int:
        return as_count(i, name=name, minimum=minimum, maximum=len(self) - 1)

    def vertex_count(self, i: int) -> int:
        """Number of vertices of level ``i``."""
        return len(self.representatives[self._check_level(i)])

    def level_arrays(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """``(vertices (n_i, 3) float64, triangles (m_i, 3) int64)`` of level ``i`` (copies)."""
        i = self._check_level(i)
        return self.vertices[self.representatives[i]], self.triangles[i].copy()

    def level(self, i: int) -> AnyMesh:
        """Level ``i`` as a mesh of the input's kind; positions are the input positions of its vertices.

        Examples
        --------
        >>> import open3d as o3d
        >>> h = build_hierarchy(o3d.geometry.TriangleMesh.create_sphere(resolution=10), min_vertices=20)
        >>> len(h.level(1).vertices) == h.vertex_count(1)
        True
        """
        vertices, triangles = self.level_arrays(i)
        return new_mesh(self._template(), vertices, triangles)

    def vertex_map(self, i: int) -> np.ndarray:
        """``(n_0,) int64``: the level-``i`` vertex that represents each input vertex."""
        i = self._check_level(i)
        mapping = np.arange(len(self.vertices), dtype=np.int64)
        for j in range(1, i + 1):
            mapping = self.parents[j][mapping]
        return mapping

    def collapses(self, i: int) -> dict[str, np.ndarray]:
        """Collapse records of level ``i >= 1`` in level ``i - 1`` indices.

        Returns a dict with ``removed (r,)``, ``targets (r,)``, ``ring_offsets (r + 1,)``
        and ``ring`` (the 1-ring of ``removed[j]`` is ``ring[ring_offsets[j]:ring_offsets[j + 1]]``).
        """
        i = self._check_level(i, minimum=1)
        return {
            "removed": self.removed[i],
            "targets": self.targets[i],
            "ring_offsets": self.ring_offsets[i],
            "ring": self.rings[i],
        }

    # --------------------------------------------------------------- refinement
    def refine(self, i: int, positions: Any) -> np.ndarray:
        """Split the vertices removed at level ``i`` back in: positions of level ``i - 1``.

        Vertices kept from level ``i`` keep their positions exactly. Each split
        vertex is first put at the average of its 1-ring at level ``i - 1``
        (for an independent set the 1-ring holds kept vertices only; otherwise
        the split vertices solve these averages together, a discrete harmonic
        fill), then moved once by Kobbelt's step (section 4.2)::

            x <- x - U^2(x) / nu,   nu = 1 + (1/n_i) sum_j 1/n_ij,

        with the uniform umbrella ``U(x) = mean of neighbours - x`` of level
        ``i - 1``. ``U^2`` is evaluated with all level ``i - 1`` positions after
        the averaging and every split vertex moves at once (a Jacobi step, so
        the result does not depend on an order). Split vertices on the
        boundary use the boundary curve instead: their two boundary
        neighbours, for both the average and ``U`` (so ``nu = 3/2``), which keeps
        an open boundary from being pulled inwards.

        Parameters
        ----------
        i : int
            Level to refine from, ``1 <= i < len(self)``.
        positions : (n_i, 3) array-like of float
            Positions of level ``i``'s vertices.

        Returns
        -------
        (n_{i-1}, 3) float64 ndarray
        """
        i = self._check_level(i, minimum=1)
        positions = as_positions(positions, len(self.representatives[i]), name="positions")
        return self.refine_with_rings(i, positions, vertex_rings(self.triangles[i - 1], len(self.parents[i])))

    def refine_with_rings(self, i: int, positions: np.ndarray, rings: VertexRings) -> np.ndarray:
        """:meth:`refine` of checked ``(n_i, 3) float64`` positions (not validated again), with the
        :class:`~o3d_lsmesh.topology.VertexRings` of level ``i - 1``, which a caller fairing that level
        reuses (multiresolution fairing: one ring pass per level)."""
        out = positions[self.parents[i]]
        removed = self.removed[i]
        if len(removed) == 0:
            return out
        weights, scale, on_boundary = _umbrella_weights(rings)
        rows = weights[removed]  # the split vertices' rows
        if self.independent:  # their neighbours are all kept
            out[removed] = rows @ out
        else:
            out[removed] = _harmonic_fill(weights, out, removed, on_boundary)
        umbrella = weights @ out
        umbrella -= out
        second = rows @ umbrella
        second -= umbrella[removed]
        # nu - 1 = sum_j w_ij w_ji with w_ji = scale_j where it is not zero: inside, the 1-ring's interior
        # vertices (a boundary vertex reads the curve only); on a boundary, the curve's two vertices
        if on_boundary is None:
            nu = rows @ scale
        else:
            nu = np.where(on_boundary[removed], rows @ scale, rows @ np.where(on_boundary, 0.0, scale))
        nu += 1.0
        out[removed] -= second / nu[:, None]
        return out

    # ---------------------------------------------------------------- internals
    def _template(self) -> MeshData:
        """A stand-in for the input mesh so that :func:`new_mesh` builds the input's kind."""
        return template(self.mesh_kind, self.tensor_format)


def boundary_degree(rings: VertexRings) -> np.ndarray:
    """``(n,) int64``: the edges of one triangle at every vertex (0 inside, 2 on a simple boundary)."""
    if not rings.boundary.any():  # no edge of one triangle (nor of more)
        return np.zeros(rings.n, dtype=np.int64)
    return np.add.reduceat(_single_slots(rings), rings.indptr[:-1], dtype=np.int64)


def _single_slots(rings: VertexRings) -> np.ndarray:
    # an edge of one triangle holds its one entry twice (so does the diagonal's marker)
    single = rings.pairs[0] == rings.pairs[1]
    single[rings.diagonal] = False
    return single


def _umbrella_weights(rings: VertexRings) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray | None]:
    """Row-stochastic ``W`` of the umbrella operator on the rings' pattern (zero diagonal): the 1-ring
    inside, the boundary neighbours (edges of one triangle) on a boundary; with each row's weight
    ``(n,)`` and the boundary vertices ``(n,) bool`` (None on a mesh without edges of one triangle).
    """
    n, indptr = rings.n, rings.indptr
    degree = rings.valence.astype(np.float64)
    counts = np.diff(indptr)
    on_boundary = None
    if rings.boundary.any():
        single = _single_slots(rings)
        boundary_count = np.add.reduceat(single, indptr[:-1], dtype=np.int64)
        if boundary_count.any():
            on_boundary = boundary_count > 0
            degree[on_boundary] = boundary_count[on_boundary]
    scale = np.divide(1.0, degree, out=np.zeros(n), where=degree > 0)
    data = np.repeat(scale, counts)
    data[rings.diagonal] = 0.0
    if on_boundary is not None:  # a boundary vertex's row reads its curve neighbours only
        np.copyto(data, 0.0, where=np.repeat(on_boundary, counts) & ~single)
    weights = sp.csr_matrix((n, n), dtype=np.float64)
    weights.data, weights.indices, weights.indptr = data, rings.indices, indptr
    weights.has_canonical_format = True  # the rings' pattern: sorted columns, no duplicates
    return weights, scale, on_boundary


def _harmonic_fill(
    weights: sp.csr_matrix, out: np.ndarray, removed: np.ndarray, on_boundary: np.ndarray | None
) -> np.ndarray:
    """Positions of ``removed`` equal to the ``weights`` average of their neighbours, the others fixed.

    Row ``i`` times its degree ``d_i`` is ``(1 + FILL_TIE) d_i x_i - sum_j a_ij x_j = FILL_TIE d_i x0_i``
    (``a`` the rows' 0/1 pattern, ``x0`` the placeholders), symmetric positive definite within the
    boundary rows (which read their curve only) and within the inner ones: boundary first, two SPD solves.
    """
    x = out.copy()
    groups = (
        [removed] if on_boundary is None else [removed[on_boundary[removed]], removed[~on_boundary[removed]]]
    )
    for rows in groups:
        if len(rows) == 0:
            continue
        pattern = weights[rows]
        pattern.data = (pattern.data != 0).astype(np.float64)
        pattern.eliminate_zeros()
        degree = np.diff(pattern.indptr).astype(np.float64)
        degree[degree == 0] = 1.0  # (a vertex without neighbours keeps its placeholder, scaled as before)
        inside = np.zeros(len(x), dtype=bool)
        inside[rows] = True
        system = sp.diags(degree * (1.0 + FILL_TIE)) - pattern[:, rows]
        rhs = pattern[:, np.flatnonzero(~inside)] @ x[~inside] + (FILL_TIE * degree)[:, None] * x[rows]
        x[rows] = solve_spd(system.tocsc(), rhs)
    return x[removed]


def tensor_format_of(data: MeshData) -> tuple:
    if data.kind != "tensor":
        return ()
    src = data.source
    index_dtype = str(src.triangle.indices.dtype) if "indices" in src.triangle else "Int64"
    return (str(src.vertex.positions.device), str(src.vertex.positions.dtype), index_dtype)


def _warn_workers(workers: Any) -> None:
    if workers is not None:
        warnings.warn(
            "workers is deprecated and ignored: the hierarchy is built by one compiled sequential loop, "
            "which threads did not speed up; drop the argument",
            FutureWarning,
            stacklevel=3,
        )


def build_hierarchy_arrays(
    vertices: np.ndarray,
    triangles: np.ndarray,
    *,
    alpha: float = ALPHA,
    beta: float = BETA,
    min_vertices: int = 100,
    max_levels: int | None = None,
    progress: bool = False,
    workers: int | None = None,
    mesh_kind: str = "arrays",
    tensor_format: tuple = (),
) -> MeshHierarchy:
    """Array core of :func:`build_hierarchy`: ``(n, 3) float64`` vertices, ``(m, 3) int64`` triangles.

    The arrays are checked and copied (:func:`~o3d_lsmesh._validate.mesh_arrays`): changing them
    afterwards does not change the hierarchy.
    """
    _warn_workers(workers)
    alpha = as_positive_float(alpha, name="alpha", allow_zero=True)
    beta = as_positive_float(beta, name="beta", allow_zero=True)
    min_vertices = as_count(min_vertices, name="min_vertices")
    if max_levels is not None:
        max_levels = as_count(max_levels, name="max_levels")
    progress = check_progress(progress)
    vertices, triangles = mesh_arrays(vertices, triangles)
    return collapse_hierarchy(
        vertices,
        triangles,
        alpha=alpha,
        beta=beta,
        min_vertices=min_vertices,
        max_levels=max_levels,
        progress=bool(progress),
        mesh_kind=mesh_kind,
        tensor_format=tensor_format,
    )


def collapse_hierarchy(
    vertices: np.ndarray,
    triangles: np.ndarray,
    *,
    alpha: float,
    beta: float,
    min_vertices: int,
    max_levels: int | None,
    progress: bool,
    mesh_kind: str = "arrays",
    tensor_format: tuple = (),
) -> MeshHierarchy:
    """:func:`build_hierarchy_arrays` of checked arrays and options (:func:`read_mesh`'s, kept)."""
    n0 = len(vertices)
    total = max(n0 - min_vertices, 0)  # at most: a level may find no valid collapse before
    with progress_bar(progress, total=total, desc="mesh hierarchy", unit="vertex") as bar:
        from .collapse import collapse_levels

        _, levels = collapse_levels(
            vertices,
            triangles,
            alpha=alpha,
            beta=beta,
            max_normal_angle=MAX_NORMAL_ANGLE,
            min_quality=MIN_QUALITY,
            max_tries=MAX_TRIES,
            min_vertices=min_vertices,
            max_levels=max_levels,
            report=bar.update,
        )
        bar.update(total - bar.n)  # done: the bar ends at its total
    empty, no_ring = np.zeros(0, dtype=np.int64), np.zeros(1, dtype=np.int64)
    first = (empty, empty, no_ring, empty, empty, triangles, np.arange(n0, dtype=np.int64))  # level 0
    removed, targets, offsets, rings, parents, tris, reps = zip(first, *levels)
    return MeshHierarchy(
        vertices,
        tris,
        reps,
        parents,
        removed,
        targets,
        offsets,
        rings,
        True,
        "volume",
        mesh_kind,
        tensor_format,
    )


def build_hierarchy(
    mesh: AnyMesh,
    *,
    alpha: float = ALPHA,
    beta: float = BETA,
    min_vertices: int = 100,
    max_levels: int | None = None,
    progress: bool = False,
    workers: int | None = None,
) -> MeshHierarchy:
    """Build the multiresolution hierarchy of Liu et al. 2001, section 4.1, by volume-cost half-edge collapses.

    Each level removes an independent set of vertices, taken in increasing
    ``cost(x) = alpha * min_edge(x) + beta * max_edge(x)``; each is merged into
    the 1-ring neighbour ``x_k`` of least cone volume
    ``|sum_j (x_j - x_k) x (x_{j+1} - x_k) . (x - x_k)|``. Only collapses that
    pass the link condition, keep boundary vertices on the boundary, and
    neither flip nor degenerate a triangle are made, so every level keeps the
    input's Euler characteristic, components and boundary loops. One compiled
    sequential loop per level (``o3d_lsmesh/hierarchy/collapse.pyx`` states
    its rules).

    Any mesh is accepted, as scanners produce them: a vertex whose triangles
    form several fans, or that lies on an edge of more than two triangles, is
    locked (never removed, never a collapse target), and so is every
    unreferenced vertex (kept at every level, mapped to itself); everything
    else simplifies as on a manifold mesh, so every level has the input's set
    of non-manifold vertices and edges.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
        Any triangle mesh; not modified.
    alpha, beta : float, keyword-only
        Non-negative weights of the shortest and longest incident edge in the cost.
    min_vertices : int, keyword-only
        Stop when a level has this many vertices (or fewer cannot be reached).
    max_levels : int, optional, keyword-only
        Stop after this many levels below the input.
    progress : bool, keyword-only
        Show a tqdm bar.
    workers : int, optional, keyword-only
        Deprecated and ignored (a ``FutureWarning``): the levels are one
        sequential compiled loop, which releases the GIL, so several
        hierarchies can be built on threads at once.

    Returns
    -------
    MeshHierarchy
        Level 0 is the input; it stops when no valid collapse remains. Levels
        hold positions and triangles only: the input's vertex colors, UVs,
        material ids and other attributes cannot follow the new connectivity
        and are dropped, with one ``O3DLSMeshWarning`` naming them.

    Raises
    ------
    TypeError
        ``mesh`` is not a mesh, or an option has the wrong type.
    ValueError
        Invalid mesh arrays (non-finite, out-of-range or repeated indices), negative options.

    Examples
    --------
    >>> import open3d as o3d
    >>> sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=20)
    >>> h = build_hierarchy(sphere, min_vertices=50)
    >>> h.vertex_count(0), h.vertex_count(len(h) - 1) >= 50
    (762, True)
    >>> coarse = h.level(len(h) - 1)
    >>> fine = h.refine(1, h.level_arrays(1)[0])
    >>> fine.shape
    (762, 3)
    """
    _warn_workers(workers)
    data = read_mesh(mesh)  # any mesh: non-manifold, unreferenced vertices
    warn_dropped_attributes(data, "hierarchy levels have new connectivity", normals=True)
    return build_hierarchy_arrays(
        data.vertices,
        data.triangles,
        alpha=alpha,
        beta=beta,
        min_vertices=min_vertices,
        max_levels=max_levels,
        progress=progress,
        mesh_kind=data.kind,
        tensor_format=tensor_format_of(data),
    )

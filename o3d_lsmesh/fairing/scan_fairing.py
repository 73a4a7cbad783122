"""The scan default of ``constrained_fairing``: Liu et al.'s eq. 5 in penalty form, boundary freed.

``E(X) = |K X|^2 + mu sum_t w_t |h_t (X - X0)|^2 + lambda sum_(i,j) |x_i - x_j|^2`` (``K`` the
uniform Laplacian of every referenced vertex, ``h_t`` triangle ``t``'s row of the incidence ``H``,
``w_t`` lower at the rim), minimized by one linear system, then twiced (Tukey):
``X = X1 + S (X0 - X1)``; :func:`relax_rim` then evens out the rim's triangles and
:func:`restore_volume` gives each closed component back its enclosed volume. The weights are
measured on the mesh (:mod:`.scan_measure`). Docs page: ``docs/algorithms/scan_denoiser.rst``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..core.arrays import area_weighted_normals
from ..core.connectivity import Connectivity, halfedges
from ..core.operators import lower_csc, rim_neighbours, scan_normal_matrix
from ..core.progress import Progress
from ..core.solve import Plan, SPDSolver, check_constant_modes, solver_backend
from ..core.validate import collapsed_triangles
from .scan_measure import scan_parameters
from .tuning import RIM_RINGS, SCAN_ITERATIVE_VERTICES, SCAN_REDUCTION, SLIVER_QUALITY

__all__ = ["ScanFairingSolver", "relax_rim", "restore_volume", "scan_denoise", "triangle_quality"]


def _surface(triangles: np.ndarray, n: int, conn: Connectivity | None) -> tuple[np.ndarray, Connectivity]:
    """The triangles of three distinct vertices and their connectivity: a collapsed one has no surface."""
    collapsed = collapsed_triangles(triangles)
    if collapsed.any():  # the given connectivity is the whole mesh's
        triangles, conn = triangles[~collapsed], None
    return triangles, Connectivity(triangles, n) if conn is None else conn


class ScanFairingSolver:
    """The scan energy assembled once; :meth:`solve` faires positions with it.

    Parameters
    ----------
    triangles : (m, 3) int64
    n : int
        Vertex count (unreferenced vertices stay where they are).
    mu, membrane, boundary_weight : float
        ``mu``, ``lambda`` and the rim triangles' ``w_t`` of the energy.
    solver : {"auto", "cholmod", "iterative"}
        ``"iterative"``: IC(0)-preconditioned block CG from the scan, to ``SCAN_REDUCTION`` of each
        solve's starting residual; ``"auto"``: that from ``SCAN_ITERATIVE_VERTICES`` vertices, CHOLMOD below.
    progress : bool
        Show the iterative solves' residual.

    Positive definite (``1^T H^T W H 1 = 9 sum_t w_t > 0`` on each component); pickles. Why CG from
    ``SCAN_ITERATIVE_VERTICES``: ``docs/algorithms/scan_denoiser.rst``.
    """

    def __init__(
        self,
        triangles: np.ndarray,
        n: int,
        *,
        mu: float,
        membrane: float,
        boundary_weight: float,
        conn: Connectivity | None = None,
        rim_curve: float = 0.0,
        solver: str = "auto",
        progress: bool = False,
    ) -> None:
        self.mu = float(mu)
        self.membrane = float(membrane)
        backend = solver_backend(solver)
        triangles, conn = _surface(np.asarray(triangles), n, conn)
        normal, ring, weight = scan_normal_matrix(conn, self.mu, self.membrane, boundary_weight, rim_curve)
        # only mu H^T W H holds a component in place (K 1 = G 1 = 0): a mu too small against the rest let it
        # drift (CHOLMOD failed at a pivot naming nothing, CG collapsed the mesh to a point)
        ones, scale = normal @ np.ones(n), float(normal.diagonal().max(initial=0.0))
        check_constant_modes(
            ones, conn.components[1], scale=scale, name="mu", value=self.mu, what="mu H^T W H"
        )
        # sqrt(mu W) H, (m, n) CSR: the rows that carry the targets
        root, corners = np.sqrt(self.mu * weight), np.arange(0, 3 * len(triangles) + 1, 3)
        self.penalty = sp.csr_matrix(
            (np.repeat(root, 3), triangles.ravel(), corners), shape=(len(triangles), n)
        )
        self.referenced = conn.rim[1] > 0
        if backend == "auto" and n >= SCAN_ITERATIVE_VERTICES:
            backend = "iterative"
        if backend == "iterative":
            # symmetric and canonical: its CSR arrays are its CSC form (no copy); CG runs on the whole
            # matrix, numbered by the 1-ring's reverse Cuthill-McKee order (a scan's is scattered)
            whole = sp.csc_matrix((normal.data, normal.indices, normal.indptr), shape=normal.shape)
            whole.has_canonical_format = True  # as assembled: the gateway need not check it again
            del normal
            plan = Plan(preconditioner="ic0", reduction=SCAN_REDUCTION, locality_of=ring)
            self._solver = SPDSolver(whole, backend=backend, progress=progress, _plan=plan)
            return
        # COLAMD on K's 1-ring pattern; the assembled lower triangle, not product rows (whose memory
        # estimate sent backend="auto" to the slower iterative path)
        self._solver = SPDSolver(
            lower_csc(normal),
            lower=True,
            backend=backend,
            ordering="colamd",
            progress=progress,
            _plan=Plan(pattern_of=ring),
        )

    def normal_rhs(self, positions0: np.ndarray) -> np.ndarray:
        """``mu H^T W H X0``, ``(n, 3)``."""
        return self.penalty.T @ (self.penalty @ positions0)

    @property
    def backend(self) -> str:
        """The solver that runs: ``"cholmod"``, ``"scipy"`` or ``"iterative"``."""
        return self._solver.backend

    def filter(self, positions0: np.ndarray) -> np.ndarray:
        """``S X0``: the minimizer of the energy for targets ``X0``, ``(n, 3)`` (unreferenced rows kept)."""
        return self.solve(positions0, twice=False)

    def solve(
        self, positions0: np.ndarray, *, number_of_iterations: int = 1, twice: bool | float = True
    ) -> np.ndarray:
        """``number_of_iterations`` filter passes (targets re-taken each time), then the twicing step.

        ``twice`` is the twicing weight ``t`` of ``X = X1 + t S (X0 - X1)``
        (``True`` is 1, ``False`` 0: no second back-substitution).
        """
        given = np.asarray(positions0, dtype=np.float64)
        # solved about the centroid (``K 1 = 0``, the other terms are differences: ``S`` commutes with
        # translations), so the iterative path's relative residual measures the shape, not the distance
        # to the origin (a scan far from the origin in world coordinates)
        used = np.ascontiguousarray(given) if self.referenced.all() else given[self.referenced]
        centre = used.mean(axis=0) if len(used) else np.zeros(3)
        targets = given - centre
        # the iterative path starts from the targets (the scan, close to its faired self) and solves the
        # displacement from them to SCAN_REDUCTION (the gateway drops a start worse than zero); direct
        # solvers ignore x0
        positions = targets
        for _ in range(number_of_iterations):
            positions = self._solver.solve(self.normal_rhs(positions), x0=positions)
        weight = float(twice)
        if weight and number_of_iterations:
            rest = targets - positions
            positions = positions + weight * self._solver.solve(self.normal_rhs(rest), x0=rest)
        out = positions + centre
        if not self.referenced.all():
            out[~self.referenced] = given[~self.referenced]  # exactly where they were
        return out


def scan_denoise(
    vertices: np.ndarray,
    triangles: np.ndarray,
    *,
    number_of_iterations: int = 1,
    mu: float | None = None,
    membrane: float | None = None,
    boundary_weight: float | None = None,
    solver: str = "auto",
    progress: bool = False,
    conn: Connectivity | None = None,
) -> np.ndarray:
    """The default denoiser on arrays: :func:`scan_parameters`, one system, the twiced filter, :func:`relax_rim`,
    :func:`restore_volume`.

    Given ``mu``, ``membrane``, ``boundary_weight`` replace the measured values; ``conn``: the mesh's
    connectivity if known. Triangles repeating a vertex are left out. Returns new ``(n, 3)`` positions.

    >>> import open3d as o3d
    >>> box = o3d.geometry.TriangleMesh.create_box()
    >>> scan_denoise(np.asarray(box.vertices), np.asarray(box.triangles).astype(np.int64)).shape
    (8, 3)
    """
    n = len(vertices)
    # at 10M vertices the measures and the assembly take tens of seconds before CG shows its residual
    with Progress(progress, "constrained fairing (scan)").stages(("measure", "assemble", "solve")) as begin:
        begin("measure")
        triangles, conn = _surface(np.asarray(triangles), n, conn)
        measured = scan_parameters(vertices, triangles, conn=conn)
        begin("assemble")
        system = ScanFairingSolver(
            triangles,
            n,
            mu=measured.mu if mu is None else mu,
            membrane=measured.membrane if membrane is None else membrane,
            boundary_weight=measured.boundary_weight if boundary_weight is None else boundary_weight,
            conn=conn,
            rim_curve=measured.rim_curve,
            solver=solver,
            progress=progress,
        )
        begin("solve")
        out = system.solve(vertices, number_of_iterations=number_of_iterations, twice=measured.twicing)
        # a rim as noisy as the interior (s = 0) is not pulled in: its sweeps are off
        out = relax_rim(vertices, out, triangles, conn=conn, strength=measured.scan_likeness)
        return restore_volume(vertices, out, conn)


def restore_volume(given: np.ndarray, positions: np.ndarray, conn: Connectivity) -> np.ndarray:
    """Offset each closed component of ``positions`` along its vertex normals to ``given``'s enclosed volume.

    Desbrun et al. (1999)'s volume preservation as one offset ``x_i + t n_i`` per closed, consistently
    oriented component (``n_i`` the unit area-weighted normals of ``positions``), ``t`` the root of the
    cubic ``V(t) = V(given)`` by Newton from 0; open components and unreferenced vertices are returned as
    they are. ``given``, ``positions``: ``(n, 3)``; returns new ``(n, 3)``. Why and how:
    ``docs/algorithms/scan_denoiser.rst``.

    >>> import open3d as o3d
    >>> box = o3d.geometry.TriangleMesh.create_box()
    >>> V, F = np.asarray(box.vertices), np.asarray(box.triangles).astype(np.int64)
    >>> out = restore_volume(V, 0.9 * V, Connectivity(F, 8))
    >>> float(np.einsum("ij,ij->i", out[F[:, 0]], np.cross(out[F[:, 1]], out[F[:, 2]])).sum() / 6).__round__(12)
    1.0
    """
    triangles, (count, label) = conn.triangles, conn.components
    closed = np.zeros(count, dtype=bool)
    closed[label[triangles[:, 0]]] = True
    closed[label[conn.edges[conn.edge_triangles != 2, 0]]] = False
    if closed.any():  # a closed edge runs once from its lower vertex, once from its higher
        tail, head = halfedges(triangles).T
        balance = np.bincount(conn.halfedge_edge, np.where(tail < head, 1.0, -1.0), minlength=len(conn.edges))
        closed[label[conn.edges[balance != 0, 0]]] = False
    faces = triangles[closed[label[triangles[:, 0]]]]
    if not len(faces):
        return positions  # as it is: nothing closed
    # about each component's centroid: a closed surface's volume does not depend on the origin, its
    # round-off does
    size = np.bincount(label, minlength=count).astype(np.float64)
    centre = np.stack([np.bincount(label, positions[:, k], minlength=count) for k in range(3)], axis=1)
    centre = (centre / size[:, None])[label]
    normal = area_weighted_normals(positions, faces)
    length = np.linalg.norm(normal, axis=1)
    direction = np.divide(normal, length[:, None], out=np.zeros_like(normal), where=length[:, None] > 0)
    owner, corner = label[faces[:, 0]], faces.T

    def rows(x: np.ndarray) -> list[np.ndarray]:  # each corner's coordinates, (3, faces) with contiguous rows
        x = np.ascontiguousarray(x.T)
        return [x[:, k] for k in corner]

    def per_component(u: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:  # sums of u . (v x w) / 6
        triple = u[0] * (v[1] * w[2] - v[2] * w[1]) + u[1] * (v[2] * w[0] - v[0] * w[2])
        return np.bincount(owner, triple + u[2] * (v[0] * w[1] - v[1] * w[0]), minlength=count) / 6.0

    (a, b, c), (p, q, r) = rows(positions - centre), rows(direction)
    target = per_component(*rows(given - centre))
    cubic = (
        per_component(a, b, c) - target,
        per_component(p, b, c) + per_component(a, q, c) + per_component(a, b, r),
        per_component(p, q, c) + per_component(p, b, r) + per_component(a, q, r),
        per_component(p, q, r),
    )
    closed &= cubic[1] > 0.0  # a component whose normals all vanish has no offset
    t, residual = np.zeros(count), np.where(closed, cubic[0], 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):  # a zero slope gives no better trial
        while True:  # Newton on the cubic until the volume's residual stops falling
            trial = t - residual / (cubic[1] + t * (2.0 * cubic[2] + 3.0 * t * cubic[3]))
            value = cubic[0] + trial * (cubic[1] + trial * (cubic[2] + trial * cubic[3]))
            better = closed & (np.abs(value) < np.abs(residual))
            if not better.any():
                break
            t, residual = np.where(better, trial, t), np.where(better, value, residual)
    out, moved = np.array(positions, dtype=np.float64), closed[label]
    out[moved] += t[label[moved], None] * direction[moved]
    return out


def triangle_quality(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """``4 sqrt(3) area / (sum of squared edges)`` of each triangle, ``(m,)``: 1 equilateral, 0 degenerate.

    >>> triangle_quality(np.array([[0.0, 0, 0], [1, 0, 0], [0.5, 0.75**0.5, 0]]), np.array([[0, 1, 2]])).round(12)
    array([1.])
    """
    a = vertices[triangles[:, 0]]
    ab, ac = vertices[triangles[:, 1]] - a, vertices[triangles[:, 2]] - a
    twice_area = np.linalg.norm(np.cross(ab, ac), axis=1)
    bc = ac - ab
    squares = np.einsum("ij,ij->i", ab, ab) + np.einsum("ij,ij->i", ac, ac) + np.einsum("ij,ij->i", bc, bc)
    return 2.0 * np.sqrt(3.0) * twice_area / np.maximum(squares, np.finfo(float).tiny)


def relax_rim(
    scan: np.ndarray,
    positions: np.ndarray,
    triangles: np.ndarray,
    *,
    strength: float = 1.0,
    conn: Connectivity | None = None,
) -> np.ndarray:
    """Even out the triangles near the rim of a faired scan, each vertex moving in its tangent plane.

    ``RIM_RINGS`` damped tangential Jacobi sweeps near the rim, then slivers give back their drift
    (``docs/algorithms/scan_denoiser.rst``). ``scan``, ``positions``: ``(n, 3)``; returns new ``(n, 3)``.
    """
    n = len(positions)
    conn = Connectivity(triangles, n) if conn is None else conn
    boundary = conn.rim[0]
    out = np.array(positions, dtype=np.float64)
    if not boundary.any():
        return out

    # the band: vertices within RIM_RINGS edges of the rim; only its vertices move, so only the triangles
    # at them (their whole fans) are read
    def at(mask: np.ndarray, faces: np.ndarray) -> np.ndarray:  # faces with a vertex in the mask
        return mask[faces[:, 0]] | mask[faces[:, 1]] | mask[faces[:, 2]]

    # grown ring by ring from the last ring's rows of the 1-ring (a triangle's corners are edge neighbours)
    band, front = boundary, np.flatnonzero(boundary)
    for _ in range(RIM_RINGS):
        grown = band.copy()
        grown[conn.adjacency[front].indices] = True
        front, band = np.flatnonzero(grown & ~band), grown
    near = triangles[at(band, triangles)]
    # only the band's rows are read: their lengths alone
    rows = np.flatnonzero(band)
    normal, scan_normal = area_weighted_normals(out, near), area_weighted_normals(scan, near)
    length, scan_length = np.linalg.norm(normal[rows], axis=1), np.linalg.norm(scan_normal[rows], axis=1)
    # a fan the fairing shrank to a point (a lone triangle of the scan), its area under sqrt(eps) of the
    # scan's (then its normal is round-off), takes the scan's tangent plane
    flat = length <= np.sqrt(np.finfo(float).eps) * scan_length
    normal[rows[flat]], length[flat] = scan_normal[rows[flat]], scan_length[flat]
    del scan_normal, scan_length
    rows = rows[length > 0.0]  # a vertex without a tangent plane stays
    movable = np.zeros(n, dtype=bool)
    movable[rows] = True
    normal[rows] /= length[length > 0.0, None]

    def tangential(move: np.ndarray, rows: np.ndarray) -> np.ndarray:  # rows (k,), or their normals (k, 3)
        planes = normal[rows] if rows.ndim == 1 else rows
        return move - np.einsum("ij,ij->i", move, planes)[:, None] * planes

    # a rim vertex averages its neighbours along the rim, any other vertex its 1-ring
    neighbours = rim_neighbours(conn, movable)
    count = np.diff(neighbours.indptr)
    moved = np.flatnonzero(count)
    neighbours = neighbours[moved]
    share, planes = 0.5 * strength / count[moved, None], normal[moved]
    for _ in range(RIM_RINGS):
        out[moved] += tangential(share * (neighbours @ out) - 0.5 * strength * out[moved], planes)
    # where a triangle still degenerates, its vertices give back their tangential drift from the scan, a
    # quarter at a time (all of it at once was measured worse)
    given_back = np.where(movable, 0, 4)
    candidates = near
    while True:
        # only the triangles at a vertex moved in the last round can have changed
        quality = triangle_quality(out, candidates)
        low = candidates[quality < SLIVER_QUALITY]
        corners = np.unique(low[quality[quality < SLIVER_QUALITY] < triangle_quality(scan, low)])
        corners = corners[given_back[corners] < 4]
        if not len(corners):
            return out
        given_back[corners] += 1
        drift = tangential(positions[corners] - scan[corners], corners)
        out[corners] = positions[corners] - 0.25 * given_back[corners, None] * drift
        touched = np.zeros(n, dtype=bool)
        touched[corners] = True
        candidates = near[at(touched, near)]

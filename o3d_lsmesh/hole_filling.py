"""Faired hole filling: Liepa's triangulate-refine-fair pipeline with least-squares-mesh fairing.

Each chosen hole (a closed loop of boundary half-edges) is

1. triangulated by Liepa's minimum-weight dynamic programme (*Filling Holes in Meshes*, SGP 2003,
   section 3: smallest largest dihedral angle, then area) over the triangles of the 3D Delaunay
   tetrahedralization of the loop's points where a triangulation lies within them (Zou et al. 2013, as
   CGAL), O(k^3) in the loop length k: longer loops
   than :data:`DP_MAX_EDGES` are first cut, recursively, along their shortest chord between far-apart
   vertices, so it cannot hang;
2. refined to the density of the surrounding edges (section 4): centroid splits, then edge flips;
3. faired as a least-squares mesh (Sorkine and Cohen-Or 2004, section 6): the new vertices are the only
   unknowns, enough rings of the mesh fixed around them; then a tangential (centroidal) relaxation;
4. checked: a patch that meets the mesh beyond the loop (crossing it, or folded flat onto a neighbour)
   is faired again with a lower continuity, then left unfaired, then replaced by the bare programme's
   triangulation; what still crosses is left open and reported (:class:`FillReport`).

:class:`HoleFiller` holds the whole-mesh analysis, so that :meth:`HoleFiller.fill` does only work local
to the holes (as CGAL's calls on a prebuilt half-edge structure), all holes batched in each step. The
sequential loops of each step (the programme, the splits and flips, the rings, the Laplacian weights and
small normal equations, the relaxation, the crossing test) are compiled in ``_fill_kernel.pyx``; this
module holds the pipeline, the choices between candidates and the sparse path of large patches.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from . import _solvers
from ._errors import O3DLSMeshWarning, SingularSystemError
from ._o3d import new_mesh, read_mesh
from ._progress import check_progress, progress_bar
from ._ranges import concatenated_ranges
from ._validate import as_bool, as_choice, as_count, as_positive_float, mesh_arrays
from .topology import boundary_loops, unique_edges_and_runs

if TYPE_CHECKING:
    from ._types import MeshT

__all__ = [
    "BORDER_FACING_AWAY",
    "DENSITY_MAX",
    "DP_MAX_EDGES",
    "FillReport",
    "FilledHoles",
    "Hole",
    "HoleFiller",
    "HoleOutcome",
    "fill_holes",
    "fill_holes_arrays",
    "find_holes",
]


_KERNEL: Any = None


def _kernel() -> Any:
    """The compiled loops (``_fill_kernel.pyx``), imported at first use like the hierarchy's kernel, so
    that the package imports from a source tree whose extensions are not built."""
    global _KERNEL
    if _KERNEL is None:
        from . import _fill_kernel

        _KERNEL = _fill_kernel
    return _KERNEL


#: Loops with more edges are split by chords before the O(k^3) dynamic programme. The compiled
#: programme on a noisy closed curve, this 2-core machine: k = 100 takes 11 ms, 150 38 ms, 200 91 ms,
#: 300 0.31 s, 400 0.76 s, 600 2.4 s. A hole of radius r on a mesh of spacing h has about 6 r / h edges,
#: so holes up to ~33 h across are triangulated in one piece. A split cuts along a straight chord that
#: the surface does not follow: at 100 (the earlier switch) ten seeded 15h holes in the horse were 1.56x
#: CGAL's mean distance, whole-loop programmes 1.03x (benchmarks/results/fill_holes.md).
DP_MAX_EDGES = 200

#: A component's longest loop is its outer border (left open by default) when less than this fraction of
#: the component's area faces away from, or sideways to, the loop's mean normal (its vector area
#: ``1/2 sum p_i x p_(i+1)``; sideways: within 78 degrees of perpendicular, cosine below 0.2): a range
#: scan sees only surfaces facing the scanner, so its silhouette has almost none, whereas a closed
#: surface with a hole wraps around it (a box with a hole in its top: 83%). Not fitted; measured
#: (benchmarks/results/border.md): at most 9.3% on the silhouettes of 26 raw scans, 46% or more on
#: holes cut in the closed shared meshes.
BORDER_FACING_AWAY = 0.25
_SIDEWAYS = 0.2

#: The largest ``density`` :func:`fill_holes` takes: new edges a quarter of the surrounding ones. The
#: refinement adds at most about what density 2 adds to a patch of even scale
#: (:func:`o3d_lsmesh._fill_kernel.refine_budget`), so more buys nothing but work.
DENSITY_MAX = 4.0

_Edges = tuple[np.ndarray, np.ndarray, np.ndarray]  # edges i < j of a local mesh, each half-edge's edge
_ALPHA = np.sqrt(2.0)  # Liepa's density factor (section 4)


def _loop_rows(triangles: np.ndarray, n: int, edge_info: Any) -> list[tuple[np.ndarray, np.ndarray]]:
    """The loops of :func:`o3d_lsmesh.topology.boundary_loops`, each with the row (of
    :func:`o3d_lsmesh.topology.halfedges`) of the one half-edge on each loop edge ``(loop[i], loop[i + 1])``;
    ``edge_info`` is :func:`o3d_lsmesh.topology.unique_edges_and_runs` of the mesh."""
    (edges, counts, inverse), runs = edge_info
    loops = boundary_loops(triangles, n, _runs=runs)
    if not loops:
        return []
    single = np.flatnonzero(counts[inverse] == 1)
    row_of_edge = np.full(len(edges), -1, dtype=np.int64)
    row_of_edge[inverse[single]] = single
    tail = np.concatenate(loops)
    head = np.concatenate([np.roll(loop, -1) for loop in loops])
    keys = np.minimum(tail, head) * n + np.maximum(tail, head)
    rows = row_of_edge[np.searchsorted(edges[:, 0] * n + edges[:, 1], keys)]
    return list(zip(loops, np.split(rows, np.cumsum([len(loop) for loop in loops])[:-1])))


@dataclass(frozen=True)
class Hole:
    """One boundary loop: vertices along the orientation of the triangles around it.

    Attributes
    ----------
    vertices : (k,) int64
    edges : int
        ``k``, the number of boundary edges.
    perimeter, diameter : float
        Sum of the edge lengths; largest distance between two of its vertices.
    component : int
        Connected component of the mesh (by shared vertices) the loop lies on.
    border : bool
        Whether it is its component's outer border (see :data:`BORDER_FACING_AWAY`).
    rows : (k,) int64
        The half-edge of each loop edge, row of :func:`o3d_lsmesh.topology.halfedges`.
    """

    vertices: np.ndarray
    edges: int
    perimeter: float
    diameter: float
    component: int
    border: bool
    rows: np.ndarray = field(repr=False)


def _diameter(points: np.ndarray) -> float:
    chunks = range(0, len(points), 512)  # bound memory at 512 * k distances
    return float(
        np.sqrt(max(float(((points[s : s + 512, None] - points[None]) ** 2).sum(-1).max()) for s in chunks))
    )


def find_holes(vertices: np.ndarray, triangles: np.ndarray, *, _edge_info=None) -> list[Hole]:
    """Every boundary loop of the mesh with its size and whether it is an outer border.

    A component's outer border is its longest loop when less than :data:`BORDER_FACING_AWAY` of the
    component's area faces away from or sideways to the loop (a scan's silhouette, a small island's
    rim); on a closed surface with holes, none is.

    Parameters
    ----------
    vertices : (n, 3) float64
    triangles : (m, 3) int64

    Returns
    -------
    list of Hole
        In the order of :func:`o3d_lsmesh.topology.boundary_loops` (by smallest vertex index).

    Examples
    --------
    >>> import numpy as np
    >>> holes = find_holes(np.eye(3), np.array([[0, 1, 2]]))
    >>> holes[0].edges, holes[0].border  # a lone triangle: its loop is its border
    (3, True)
    """
    n = len(vertices)
    _edge_info = unique_edges_and_runs(triangles, n) if _edge_info is None else _edge_info
    loops = _loop_rows(triangles, n, _edge_info)
    if not loops:
        return []
    edges = _edge_info[0][0]
    # components over the sorted edges: the upper triangle of the adjacency in CSR order (no second sort)
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(edges[:, 0], minlength=n), out=indptr[1:])
    _, label = csgraph.connected_components(
        sp.csr_matrix((np.ones(len(edges)), edges[:, 1], indptr), shape=(n, n)), directed=False
    )
    perimeters = np.array(
        [np.linalg.norm(np.roll(vertices[lp], -1, axis=0) - vertices[lp], axis=1).sum() for lp, _ in loops]
    )
    components = np.array([label[loop[0]] for loop, _ in loops], dtype=np.int64)
    by_length = np.lexsort((-perimeters, components))  # the longest loop of each component first
    first = np.ones(len(loops), dtype=bool)
    first[1:] = components[by_length][1:] != components[by_length][:-1]
    longest = by_length[first]
    # each judged component's triangles against its longest loop's vector area: the area facing away
    judged = np.full(label.max() + 1, -1)
    judged[components[longest]] = longest
    tri_loop = judged[label[triangles[:, 0]]]
    mine = np.flatnonzero(tri_loop >= 0)
    loop_vector = np.zeros((len(loops), 3))
    for i in longest:
        p = vertices[loops[i][0]] - vertices[loops[i][0][0]]
        loop_vector[i] = _cross(p, np.roll(p, -1, axis=0)).sum(axis=0)
        loop_vector[i] /= max(float(np.sqrt((loop_vector[i] ** 2).sum())), 1e-300)
    facing_away = np.zeros(len(loops))
    total = np.zeros(len(loops))
    for start in range(0, len(mine), 65536):  # bounded memory on large meshes
        rows = mine[start : start + 65536]
        p = vertices[triangles[rows]]
        vector = 0.5 * _cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        size = np.sqrt((vector**2).sum(axis=1))
        away = (vector * loop_vector[tri_loop[rows]]).sum(axis=1) < _SIDEWAYS * size
        total += np.bincount(tri_loop[rows], weights=size, minlength=len(loops))
        facing_away += np.bincount(tri_loop[rows], weights=np.where(away, size, 0.0), minlength=len(loops))
    border = np.zeros(len(loops), dtype=bool)
    border[longest] = facing_away[longest] < BORDER_FACING_AWAY * total[longest]
    diameters = [_diameter(vertices[loop]) for loop, _ in loops]  # loops come sorted by first vertex
    return [
        Hole(loop, len(loop), float(perimeters[i]), diameters[i], int(components[i]), bool(border[i]), rows)
        for i, (loop, rows) in enumerate(loops)
    ]


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``np.cross`` over the last axis of 3-vectors, without its axis juggling (it dominates small calls)."""
    shape = u.shape if u.shape == v.shape else np.broadcast_shapes(u.shape, v.shape)
    out = np.empty(shape)
    u0, u1, u2 = u[..., 0], u[..., 1], u[..., 2]
    v0, v1, v2 = v[..., 0], v[..., 1], v[..., 2]
    np.subtract(u1 * v2, u2 * v1, out=out[..., 0])
    np.subtract(u2 * v0, u0 * v2, out=out[..., 1])
    np.subtract(u0 * v1, u1 * v0, out=out[..., 2])
    return out


def _triangulate(
    points: np.ndarray, outer_normals: np.ndarray, forbidden: np.ndarray | None, spacing: float
) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate a loop, splitting it by chords while it is longer than :data:`DP_MAX_EDGES`.

    Returns the extra points (on the chords) and triangles over the loop's indices ``[0, k)`` followed
    by the extra points'.
    """
    k = len(points)
    if k <= DP_MAX_EDGES:
        return np.zeros((0, 3)), _kernel().minimum_weight_triangulation(
            points,
            outer_normals,
            None if forbidden is None or not forbidden.any() else forbidden.view(np.uint8),
            _kernel().delaunay_triangles(points),
        )
    # the shortest chord between vertices 1/3 to 2/3 of the loop apart, in chunks of rows
    best = (np.inf, 0, k // 2)
    gap = np.arange(k // 3, k - k // 3 + 1)[None, :]
    for start in range(0, k, 256):
        i = np.arange(start, min(k, start + 256))[:, None]
        j = (i + gap) % k
        dist = np.linalg.norm(points[i] - points[j], axis=-1)
        if forbidden is not None:
            dist = np.where(forbidden[i, j], np.inf, dist)
        r, c = divmod(int(np.argmin(dist)), dist.shape[1])
        if dist[r, c] < best[0]:
            best = (float(dist[r, c]), int(i[r, 0]), int(j[r, c]))
    a, b = min(best[1:]), max(best[1:])
    # points along the chord at the spacing, at most k / 6 of them: each piece has at most 5 k / 6
    # points, so the splits end after O(log k) levels and O(k) programmes of at most DP_MAX_EDGES
    count = min(max(0, round(best[0] / spacing) - 1), k // 6) if spacing > 0 else 0
    chord = points[a] + np.linspace(0.0, 1.0, count + 2)[1:-1, None] * (points[b] - points[a])  # a -> b
    # piece one: a .. b along the loop, then back along the chord; piece two: b .. a, then the chord a -> b
    e = k + np.arange(count)
    all_points = np.concatenate([points, chord])
    triangles, extra, offset = [], [chord], k + count
    for piece in (
        np.concatenate([np.arange(a, b + 1), e[::-1]]),
        np.concatenate([np.arange(b, k), np.arange(0, a + 1), e]),
    ):
        # outer normals on the piece's edges that are edges of the original loop
        nxt = np.roll(piece, -1)
        on_loop = (piece < k) & (nxt < k) & (nxt == (piece + 1) % k)
        loop_normals = np.zeros((len(piece), 3))
        loop_normals[on_loop] = outer_normals[piece[on_loop]]
        sub_forbidden = None
        if forbidden is not None:
            sub_forbidden = np.zeros((len(piece), len(piece)), dtype=bool)
            idx = np.flatnonzero(piece < k)
            sub_forbidden[np.ix_(idx, idx)] = forbidden[np.ix_(piece[idx], piece[idx])]
        sub_extra, sub_tris = _triangulate(all_points[piece], loop_normals, sub_forbidden, spacing)
        # the piece's local indices back: [0, len(piece)) -> piece, beyond -> its new extra points
        triangles.append(np.concatenate([piece, offset + np.arange(len(sub_extra))])[sub_tris])
        offset += len(sub_extra)
        extra.append(sub_extra)
    return np.concatenate(extra), np.concatenate(triangles)


def _operators(
    i: np.ndarray, j: np.ndarray, w: np.ndarray, degree: np.ndarray, scale: np.ndarray, dense: bool
):
    """Stiffness ``K = D - W`` and Laplacian ``L = S K`` (CSR, or arrays if ``dense``) of a local mesh
    with edges ``(i, j)`` of weight ``w``, ``D`` the ``degree`` and ``S`` the row ``scale`` of
    :func:`o3d_lsmesh._fill_kernel.laplacian_weights`."""
    nv = len(degree)
    diagonal = np.arange(nv)
    rows, cols = np.concatenate([i, j, diagonal]), np.concatenate([j, i, diagonal])
    values = np.concatenate([-w, -w, degree])
    if dense:
        K = np.zeros((nv, nv))
        K[rows, cols] = values
        return K, scale[:, None] * K
    K = sp.csr_matrix((values, (rows, cols)), shape=(nv, nv))
    L = K.copy()  # L = S K: K's pattern with its rows scaled
    L.data = L.data * np.repeat(scale, np.diff(L.indptr))
    return K, L


def _fair(
    x: np.ndarray, tris: np.ndarray, unknown: np.ndarray, rings: list, level: int, edges: _Edges, cot: bool
):
    """Positions of the ``unknown`` local vertices minimizing continuity ``level``'s energy, the others
    fixed at ``x``:

    * ``0``: ``x^T K x`` (membrane, harmonic: ``L x = 0`` at the unknowns);
    * ``1``: ``sum_r |(L x)_r|^2`` over the rows touching an unknown: the LS-mesh energy ``||L x||^2``
      with interpolated anchors (eq. 3, section 6);
    * ``2``: ``sum |(L x)_r - (L x)_s|^2`` over edges ``(r, s)`` touching such a row:
      ``(L x)^T K (L x)``, the tri-Laplacian energy,

    with ``K = D - W`` and ``L = S K``: uniform, ``W`` the adjacency and ``S = D^-1`` (eq. 1 of LS
    meshes); or, if ``cot``, ``W`` the cotangent weights of ``x`` clamped below at 5% of their mean
    (obtuse pairs would make ``K`` indefinite) and ``S`` the inverse vertex areas, normalized to mean 1
    (:func:`o3d_lsmesh._fill_kernel.laplacian_weights`).

    ``rings[0]`` are the loop vertices, ``rings[i]`` the i-th ring around them: the rows used involve
    only vertices whose one-rings are complete in ``tris``. ``edges`` is
    :func:`o3d_lsmesh._fill_kernel.unique_edges` of ``tris``. Small systems (at most
    :data:`o3d_lsmesh._solvers.DENSE_UNKNOWNS` unknowns) are assembled by the compiled
    :func:`o3d_lsmesh._fill_kernel.normal_equations` and solved by LAPACK's dense Cholesky, at
    continuity 1 and 2 in one call (:func:`o3d_lsmesh._fill_kernel.fair_dense`: on a hole of a few
    vertices the NumPy glue between the steps cost more than the steps); larger ones sparse.
    """
    nv = len(x)
    i, j, inverse = edges
    dense = len(unknown) <= _solvers.DENSE_UNKNOWNS
    if dense and level > 0:  # the small patch's solve in one compiled call
        solution = _kernel().fair_dense(
            x, tris, i, j, inverse, unknown, rings[0], rings[1] if level > 1 else rings[0], level, cot
        )
        if solution is None:
            raise SingularSystemError("the fairing system is not positive definite")
        return solution
    w, degree, scale = _kernel().laplacian_weights(tris, nv, i, j, inverse, x if cot else None)
    if level == 0:
        K, _ = _operators(i, j, w, degree, scale, dense)
        known = np.ones(nv, dtype=bool)
        known[unknown] = False
        return _solve_blocks(K[unknown][:, unknown], -(K[unknown][:, np.flatnonzero(known)] @ x[known]))
    rows = np.zeros(nv, dtype=bool)
    rows[unknown] = True
    rows[rings[0]] = True  # rows whose Laplacian involves an unknown
    if level == 1:
        plus, minus = np.flatnonzero(rows), np.zeros(0, dtype=np.int64)
    else:
        valid = rows.copy()
        valid[rings[1]] = True
        keep = (rows[i] | rows[j]) & valid[i] & valid[j]
        plus, minus = i[keep], j[keep]
    if dense:
        normal, rhs = _kernel().normal_equations(x, i, j, w, degree, scale, plus, minus, unknown)
        solution = _kernel().cholesky_solve(normal, rhs)  # solve_spd's dense path, without its wrapping
        if solution is None:
            raise SingularSystemError("the fairing system is not positive definite")
        return solution
    _, L = _operators(i, j, w, degree, scale, False)
    if level == 1:
        A_full = L[plus]
    else:  # the edge difference operator: row e is +1 at plus[e] and -1 at minus[e]
        G = sp.csr_matrix(
            (
                np.tile([1.0, -1.0], len(plus)),
                np.stack([plus, minus], axis=1).ravel(),
                np.arange(0, 2 * len(plus) + 1, 2),
            ),
            shape=(len(plus), nv),
        )
        A_full = G @ L
    A_full = A_full.tocsc()
    if len(unknown) and unknown[0] == nv - len(unknown) and (np.diff(unknown) == 1).all():
        A_u = A_full[:, nv - len(unknown) :]  # the usual layout: the unknowns are the last columns
    else:
        A_u = A_full[:, unknown]
    fixed = x.copy()
    fixed[unknown] = 0.0  # A_known x_known, without slicing the known columns out
    return _solve_blocks(A_u.T @ A_u, -(A_u.T @ (A_full @ fixed)))


def _solve_blocks(matrix: Any, rhs: np.ndarray) -> np.ndarray:
    """:func:`o3d_lsmesh._solvers.solve_spd` of a fairing system, whose blocks are the patches (and
    patches sharing rings): a block with a non-finite entry (cotangent weights of a degenerate
    triangle) is left NaN, for the caller to fall back on that patch alone, and the others solved."""
    matrix = sp.csr_matrix(matrix)
    bad = ~np.isfinite(rhs).all(axis=1)
    bad[np.repeat(np.arange(matrix.shape[0]), np.diff(matrix.indptr))[~np.isfinite(matrix.data)]] = True
    if not bad.any():
        return _solvers.solve_spd(matrix, rhs)
    _, label = csgraph.connected_components(matrix, directed=False)
    ok = ~np.isin(label, label[bad])
    x = np.full(rhs.shape, np.nan)
    if ok.any():
        x[ok] = _solvers.solve_spd(matrix[ok][:, ok], rhs[ok])
    return x


@dataclass(frozen=True)
class HoleOutcome:
    """What :func:`fill_holes` did with one boundary loop.

    Attributes
    ----------
    id : int
        The loop's index in :func:`find_holes` (and :attr:`HoleFiller.holes`) of the input.
    edges : int
        Its number of boundary edges.
    diameter : float
        Largest distance between two of its vertices.
    filled : bool
        Whether it was closed.
    how : str
        How it was filled (``"continuity 2"`` ... ``"continuity 0"``, ``"refined, unfaired"``,
        ``"minimum-weight triangulation"``: each a simpler retry where the one before crossed the
        surface), or why it was left open.
    """

    id: int
    edges: int
    diameter: float
    filled: bool
    how: str


@dataclass(frozen=True)
class FillReport:
    """Every boundary loop :func:`fill_holes` filled or left open, and how or why
    (``fill_holes(..., return_report=True)``; :attr:`FilledHoles.report`).

    Attributes
    ----------
    holes : tuple of HoleOutcome
        One per loop, by id.

    Examples
    --------
    >>> import numpy as np
    >>> from o3d_lsmesh import FillReport, fill_holes
    >>> square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]], float)
    >>> pyramid = (square, np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]))
    >>> (V, T), report = fill_holes(pyramid, fill_border=True, return_report=True)
    >>> [(hole.id, hole.edges, hole.filled, hole.how) for hole in report.holes]
    [(0, 4, True, 'minimum-weight triangulation')]
    """

    holes: tuple[HoleOutcome, ...]

    @property
    def filled(self) -> list[HoleOutcome]:
        return [hole for hole in self.holes if hole.filled]

    @property
    def skipped(self) -> list[HoleOutcome]:
        return [hole for hole in self.holes if not hole.filled]

    def describe(self, limit: int | None = None) -> str:
        """The loops left open, one clause each (the first ``limit`` of them)."""
        left = self.skipped
        shown = "; ".join(
            f"loop {h.id} ({h.edges} edges, diameter {h.diameter:.4g}): {h.how}" for h in left[:limit]
        )
        return shown + (f"; and {len(left) - limit} more" if limit is not None and len(left) > limit else "")


def _how(level: int) -> str:
    """:attr:`HoleOutcome.how` of a hole filled at ``level`` (:attr:`FilledHoles.continuity`)."""
    return {-1: "refined, unfaired", -2: "minimum-weight triangulation"}.get(level, f"continuity {level}")


@dataclass(frozen=True)
class FilledHoles:
    """The result of :func:`fill_holes_arrays`.

    Attributes
    ----------
    vertices : (n + p, 3) float64
        The input vertices, unchanged, then the ``p`` new ones.
    triangles : (m + q, 3) int64
        The input triangles, unchanged and in order, then the ``q`` new ones.
    holes : list of Hole
        The holes that were filled.
    skipped : list of Hole
        Loops left open (outer borders, beyond the size limits, or every fill crossing the mesh).
    interpolation : (p, n) scipy.sparse.csr_matrix
        Harmonic weights of the new vertices over the input's (rows sum to 1):
        ``interpolation @ colors`` gives the new vertices' colours (empty unless asked for).
    continuity : (len(holes),) int64
        The continuity each hole was faired with: the asked one, or a lower one where the asked one
        made the patch cross the mesh (-1: left as refined, unfaired; -2: the minimum-weight
        triangulation alone, no new vertex).
    report : FillReport
        Every loop, filled or left open, and how or why.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    holes: list
    skipped: list
    # the matrix, or the (p, n) shape of an all-zero one, built when first read: SciPy's constructor
    # costs about a third of a small hole's fill when the caches are cold
    _interpolation: Any = field(repr=False)
    continuity: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    report: FillReport = field(default_factory=lambda: FillReport(()))

    @property
    def interpolation(self) -> sp.csr_matrix:
        if isinstance(self._interpolation, tuple):
            object.__setattr__(self, "_interpolation", _empty_csr(*self._interpolation))
        return self._interpolation


def fill_holes_arrays(
    vertices: np.ndarray,
    triangles: np.ndarray,
    *,
    max_hole_edges: int | None = None,
    max_hole_diameter: float | None = None,
    continuity: int = 2,
    density: float = 1.0,
    weights: str = "cotangent",
    fill_border: bool = False,
    interpolation: bool = False,
    progress: bool = False,
) -> FilledHoles:
    """Fill the holes of ``(vertices, triangles)``: the array core of :func:`fill_holes`.

    Parameters
    ----------
    vertices : (n, 3) float64
    triangles : (m, 3) int64
    max_hole_edges, max_hole_diameter, continuity, density, weights, fill_border, progress
        As in :func:`fill_holes`.
    interpolation : bool
        Also compute :attr:`FilledHoles.interpolation` (else an empty matrix).

    Returns
    -------
    FilledHoles

    See Also
    --------
    HoleFiller : the whole-mesh analysis done once, for several fills.

    Examples
    --------
    >>> import numpy as np
    >>> square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]], float)
    >>> tris = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])  # a pyramid without its base
    >>> out = fill_holes_arrays(square, tris, fill_border=True)
    >>> len(out.triangles) - len(tris), len(out.holes)
    (2, 1)
    """
    return HoleFiller(vertices, triangles, index_triangles=False).fill(
        max_hole_edges=max_hole_edges,
        max_hole_diameter=max_hole_diameter,
        continuity=continuity,
        density=density,
        weights=weights,
        fill_border=fill_border,
        interpolation=interpolation,
        progress=progress,
    )


class HoleFiller:
    """The whole-mesh analysis of a mesh's holes, done once; :meth:`fill` then does only per-hole work.

    Like CGAL's prebuilt half-edge structure: the loops (:func:`find_holes`), each vertex's mean edge
    length (Liepa's scale) and triangles, and grids of the triangles' bounding spheres (for the
    crossing check). The state is read-only: it pickles, and :meth:`fill` may run from several threads.

    Parameters
    ----------
    vertices : (n, 3) float64
    triangles : (m, 3) int64
    index_triangles : bool, keyword-only
        Build the grids (they pay off over several fills); ``False`` makes each fill query only
        the triangles in the box of its new triangles, faster for a single fill.

    Attributes
    ----------
    holes : list of Hole
        Every boundary loop, as :func:`find_holes` gives them.

    Examples
    --------
    >>> import numpy as np
    >>> square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]], float)
    >>> filler = HoleFiller(square, np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]))
    >>> [hole.edges for hole in filler.holes]
    [4]
    >>> len(filler.fill(fill_border=True).triangles)
    6
    """

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, *, index_triangles: bool = True) -> None:
        index_triangles = bool(as_bool(index_triangles, name="index_triangles"))
        vertices, triangles = mesh_arrays(vertices, triangles)  # copies: the state must not change under it
        for array in (vertices, triangles):
            array.setflags(write=False)
        n, m = len(vertices), len(triangles)
        self.vertices, self.triangles = vertices, triangles
        edge_info = unique_edges_and_runs(triangles, n)  # the one whole-mesh sort
        edges = edge_info[0][0]
        self.holes = find_holes(vertices, triangles, _edge_info=edge_info)
        length = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
        degree = np.maximum(np.bincount(edges.ravel(), minlength=n), 1)
        self.sigma = np.bincount(edges.ravel(), weights=np.repeat(length, 2), minlength=n) / degree
        # the triangles of each vertex (CSR), by a transpose (linear, no sort)
        by_vertex = sp.csr_matrix(
            (np.repeat(np.arange(m, dtype=np.int64), 3), triangles.ravel(), np.arange(0, 3 * m + 1, 3)),
            shape=(m, n),
        ).tocsc()
        self.vertex_triangles = (by_vertex.indptr.astype(np.int64), by_vertex.data.astype(np.int64))
        self.index = _TriangleIndex(vertices, triangles) if index_triangles else None

    def fill(
        self,
        *,
        max_hole_edges: int | None = None,
        max_hole_diameter: float | None = None,
        continuity: int = 2,
        density: float = 1.0,
        weights: str = "cotangent",
        fill_border: bool = False,
        interpolation: bool = False,
        progress: bool = False,
    ) -> FilledHoles:
        """Fill the chosen holes: the options and result of :func:`fill_holes_arrays`."""
        if max_hole_edges is not None:
            max_hole_edges = as_count(max_hole_edges, name="max_hole_edges", minimum=3)
        if max_hole_diameter is not None:
            max_hole_diameter = as_positive_float(max_hole_diameter, name="max_hole_diameter")
        continuity = as_count(continuity, name="continuity", minimum=0, maximum=2)
        density = as_positive_float(density, name="density", allow_zero=True)
        if density > DENSITY_MAX:
            raise ValueError(f"density must be at most {DENSITY_MAX:g} (DENSITY_MAX), got {density:g}")
        weights = as_choice(weights, ("uniform", "cotangent"), name="weights")
        fill_border = bool(as_bool(fill_border, name="fill_border"))
        check_progress(progress)
        m = len(self.triangles)
        holes: list[Hole] = []
        why: dict[int, str] = {}  # id(hole) -> why it is left open
        for hole in self.holes:
            # the three edges of one triangle are the rim of a flap (a triangle hanging by a vertex,
            # common in raw scans), not a hole: "filling" it would add that triangle's reverse
            if hole.edges == 3 and len(np.unique(np.asarray(hole.rows) % m)) == 1:
                why[id(hole)] = "the rim of one triangle hanging by a vertex (a flap, not a hole)"
            elif max_hole_edges is not None and hole.edges > max_hole_edges:
                why[id(hole)] = f"more than max_hole_edges={max_hole_edges} edges"
            elif max_hole_diameter is not None and hole.diameter > max_hole_diameter:
                why[id(hole)] = f"wider than max_hole_diameter={max_hole_diameter:g}"
            elif hole.border and not fill_border:
                why[id(hole)] = "taken as the outer border of an open surface (fill_border=False)"
            else:
                holes.append(hole)
        # the crossing checks' grids: prebuilt, or built once here for several holes (a single one queries
        # the triangles in the box of its patch)
        index = self.index
        if index is None and len(holes) > 1:
            index = _TriangleIndex(self.vertices, self.triangles)
        cot = weights == "cotangent"
        out = self._fill_pass(holes, continuity, density, cot, interpolation, progress, index)
        vertices, triangles, filled, stuck, used, weights_matrix, own = out
        if stuck and density > 0:
            # simpler forms: the bare minimum-weight triangulation (no new vertex), checked against the
            # fills kept so far too; what still crosses is given up
            retry = self._fill_pass(stuck, continuity, 0.0, False, False, False, index)
            again = np.concatenate([triangles, retry[1][m:]])
            crossing = _crossings(vertices, again, m, index, np.concatenate([own, len(filled) + retry[6]]))
            crossing = crossing[len(triangles) - m :]
            bad = np.bincount(retry[6], weights=crossing, minlength=len(retry[2])) > 0
            keep = ~bad[retry[6]]
            triangles = np.concatenate([triangles, retry[1][m:][keep]])
            filled = filled + [hole for hole, b in zip(retry[2], bad) if not b]
            used = np.concatenate([used, np.full(int((~bad).sum()), -2, dtype=np.int64)])
            stuck = retry[3] + [hole for hole, b in zip(retry[2], bad) if b]
        for hole in stuck:
            why[id(hole)] = "every fill crosses the surface (folded or overlapping triangles next to it)"
        number = {id(hole): i for i, hole in enumerate(self.holes)}
        level = {id(hole): int(c) for hole, c in zip(filled, used)}
        report = FillReport(
            tuple(
                HoleOutcome(
                    i,
                    hole.edges,
                    hole.diameter,
                    id(hole) in level,
                    _how(level[id(hole)]) if id(hole) in level else why[id(hole)],
                )
                for i, hole in enumerate(self.holes)
                if id(hole) in level or id(hole) in why
            )
        )
        # said: every loop left open but those the size limits exclude and flaps (no holes)
        said = FillReport(tuple(h for h in report.skipped if h.how.startswith(("every", "taken"))))
        if said.holes:
            warnings.warn(
                f"fill_holes: {len(said.holes)} of {len(self.holes)} loops left open: {said.describe(10)}"
                " (every loop, filled or not: fill_holes(..., return_report=True), a FillReport)",
                O3DLSMeshWarning,
                stacklevel=3,
            )
        order = np.argsort([number[id(hole)] for hole in filled], kind="stable").astype(np.int64)
        skipped = [hole for hole in self.holes if id(hole) in why]
        return FilledHoles(
            vertices, triangles, [filled[i] for i in order], skipped, weights_matrix, used[order], report
        )

    def _fill_pass(
        self,
        holes: list,
        continuity: int,
        density: float,
        cot: bool,
        interpolation: bool,
        progress: bool,
        index: Any,
    ) -> tuple:
        """Fill ``holes``: the vertices and triangles (the input's, then the new ones), the holes filled,
        those whose every fill crosses (left open), the continuity of each filled one, the
        interpolation (or its shape) and the filled hole (index in the list) of each new triangle.
        ``index``: the crossing checks' (:func:`_crossings`)."""
        vertices, triangles = self.vertices, self.triangles
        n = len(vertices)
        empty = np.zeros(0, dtype=np.int64)
        if not holes:
            return vertices.copy(), triangles.copy(), [], [], empty, (0, n), empty
        # each piece (a loop; one through a vertex twice is cut in pieces) is triangulated on its own,
        # long ones cut by chords sampled at the refinement's spacing (none without) first
        pieces = [
            (h, *p)
            for h, hole in enumerate(holes)
            for p in _simple_pieces(hole.vertices, hole.rows, vertices[hole.vertices])
        ]
        piece_hole, piece_loop, piece_rows = zip(*pieces)
        count = len(piece_loop)
        if count == 1 and len(piece_loop[0]) <= DP_MAX_EDGES:
            # one simple loop short enough for the programme (the usual fill): one compiled call
            with progress_bar(progress, total=1, desc="filling holes", unit="loop") as bar:
                fresh_points, new_tris = _kernel().fill_loop(
                    piece_loop[0],
                    piece_rows[0],
                    vertices,
                    triangles,
                    *self.vertex_triangles,
                    self.sigma,
                    density,
                    _ALPHA,
                )
                bar.update(1)
            owner = tri_piece = np.zeros(len(new_tris), dtype=np.int64)
        else:
            # each piece's points, the normals across its edges, its chords that are mesh edges, its spacing
            piece_points, piece_outer, piece_forbidden, piece_spacing, piece_pairs = zip(
                *(
                    _kernel().loop_geometry(loop, rows, vertices, triangles, *self.vertex_triangles)
                    for loop, rows in zip(piece_loop, piece_rows)
                )
            )
            piece_extra, piece_tris = [], []
            with progress_bar(progress, total=count, desc="filling holes", unit="loop") as bar:
                for points, outer, forbidden, spacing in zip(
                    piece_points, piece_outer, piece_forbidden, piece_spacing
                ):
                    extra, tris = _triangulate(
                        points, outer, forbidden, spacing / density if density > 0 else 0.0
                    )
                    piece_extra.append(extra)
                    piece_tris.append(tris)
                    bar.update(1)
            # every piece refined at once, in disjoint local index ranges (a single short loop took the
            # compiled path above)
            lengths = np.array([len(loop) for loop in piece_loop])
            sizes = np.array([len(p) + len(e) for p, e in zip(piece_points, piece_extra)])
            starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
            all_points = np.concatenate([np.concatenate([p, e]) for p, e in zip(piece_points, piece_extra)])
            all_tris = np.concatenate([t + start for t, start in zip(piece_tris, starts)])
            point_piece = np.repeat(np.arange(count), sizes)
            if density > 0:
                # Liepa's scale: each loop vertex's mean edge length, the chords' spacing on their points
                sigma = [
                    np.concatenate(
                        [self.sigma[loop] / max(density, 1e-300), np.full(len(extra), spacing / density)]
                    )
                    if len(extra)
                    else self.sigma[loop] / max(density, 1e-300)
                    for loop, extra, spacing in zip(piece_loop, piece_extra, piece_spacing)
                ]
                # mesh edges between loop vertices: no flip may make them twice
                all_points, all_tris, point_piece = _kernel().refine(
                    all_points,
                    np.concatenate(sigma),
                    all_tris,
                    np.concatenate([f + s for f, s in zip(piece_pairs, starts)]),
                    point_piece,
                    _ALPHA,
                    len(all_points)
                    + _kernel().refine_budget(all_points, all_tris, self.sigma[np.concatenate(piece_loop)]),
                )
            # global numbering: loop points (first in each piece, in order) are mesh vertices; the others
            # are new, numbered piece by piece
            is_loop = np.zeros(len(all_points), dtype=bool)
            is_loop[concatenated_ranges(starts, lengths)] = True
            global_index = np.empty(len(all_points), dtype=np.int64)
            global_index[is_loop] = np.concatenate(piece_loop)
            fresh = np.flatnonzero(~is_loop)
            fresh = fresh[np.argsort(point_piece[fresh], kind="stable")]
            global_index[fresh] = n + np.arange(len(fresh))
            fresh_points = all_points[fresh]
            tri_piece = point_piece[all_tris[:, 0]]
            tri_order = np.argsort(tri_piece, kind="stable")
            tri_piece = tri_piece[tri_order]
            new_tris = global_index[all_tris[tri_order]]
            owner = np.asarray(piece_hole, dtype=np.int64)[tri_piece]  # the hole of each new triangle
        p = len(fresh_points)
        weights_matrix: Any
        if interpolation and p:
            bounds = np.searchsorted(tri_piece, np.arange(count + 1))
            weights_matrix = _interpolation(new_tris, bounds, piece_loop, n, p)
        else:
            weights_matrix = (p, n)
        out_vertices = np.concatenate([vertices, fresh_points])
        out_triangles = np.concatenate([triangles, new_tris])
        used, stuck = self._fair_all(out_vertices, out_triangles, holes, continuity, cot, owner, index)
        vertex_owner = _vertex_owner(new_tris, owner, n, p)
        used[np.bincount(vertex_owner, minlength=len(holes)) == 0] = -2  # no new vertex: the bare programme
        if len(stuck):
            keep_vertex = ~np.isin(vertex_owner, stuck)
            remap = np.concatenate([np.arange(n), n + np.cumsum(keep_vertex) - 1])
            out_vertices = np.concatenate([vertices, out_vertices[n:][keep_vertex]])
            out_triangles = np.concatenate([triangles, remap[new_tris[~np.isin(owner, stuck)]]])
            weights_matrix = (
                (int(keep_vertex.sum()), n)
                if isinstance(weights_matrix, tuple)
                else weights_matrix[np.flatnonzero(keep_vertex)]
            )
            left = np.isin(np.arange(len(holes)), stuck)
            owner = (np.cumsum(~left) - 1)[owner[~np.isin(owner, stuck)]]
            return (
                out_vertices,
                out_triangles,
                [hole for hole, out in zip(holes, left) if not out],
                [hole for hole, out in zip(holes, left) if out],
                used[~left],
                weights_matrix,
                owner,
            )
        return out_vertices, out_triangles, list(holes), [], used, weights_matrix, owner

    def _fair_all(
        self,
        vertices: np.ndarray,
        triangles: np.ndarray,
        holes: list,
        continuity: int,
        cot: bool,
        owner: np.ndarray,
        index: Any,
    ):
        """Fair every new vertex at once: one local system over the patches and the rings around them.

        ``vertices`` (the input's, then the refined patches' new ones) take the result in place.
        Candidates, best first: the asked continuity (after its cotangent pass if ``cot``, then
        without), then each lower continuity, then the refined patch unfaired. Each hole (``owner`` of
        each new triangle) keeps the first candidate whose new triangles cross no triangle of the mesh
        (a tri-Laplacian patch can overshoot into a thin part next to the hole); returns the continuity
        each hole got and the holes where none is (the caller leaves them open).
        """
        total, m, n = len(vertices), len(self.triangles), len(self.vertices)
        unknown = np.arange(n, total)
        loops = holes[0].vertices if len(holes) == 1 else np.concatenate([hole.vertices for hole in holes])
        # triangles within `continuity` rings of the loops in the input, plus every new triangle; a local
        # numbering (nothing as long as the mesh): the new vertices, every one on a new triangle and
        # numbered last, stay last; one connectivity for every solve below
        new_tris = triangles[m:]
        local_vertices, local, local_rings, local_edges = _kernel().ring_mesh(
            self.triangles, *self.vertex_triangles, loops, continuity, triangles, total
        )
        local_unknown = np.arange(len(local_vertices) - len(unknown), len(local_vertices))
        refined = vertices[n:].copy()
        work = vertices  # its new rows hold the candidate being solved from or checked

        def solve(level: int, weighted: bool) -> np.ndarray | None:
            try:
                x = _fair(
                    work[local_vertices], local, local_unknown, local_rings, level, local_edges, weighted
                )
            except SingularSystemError:
                return None
            return x if np.isfinite(x).any() else None  # a patch whose system is not finite: NaN rows

        def solve_twice(level: int) -> tuple[np.ndarray | None, np.ndarray | None]:
            """The uniform solve, then the cotangent one from it, in one compiled call (a small patch)."""
            ring = local_rings[1] if level > 1 else local_rings[0]
            return _kernel().fair_dense_twice(
                work[local_vertices], local, *local_edges, local_unknown, local_rings[0], ring, level
            )

        def candidates():  # lazily: most calls stop at the first
            dense = len(unknown) <= _solvers.DENSE_UNKNOWNS
            for level in (
                range(continuity, -1, -1) if len(unknown) else []
            ):  # nothing to fair without new vertices
                twice = cot and level > 0 and dense
                solution, again = solve_twice(level) if twice else (solve(level, False), None)
                if solution is None:
                    continue
                work[n:] = solution
                if cot and level > 0:
                    # cotangent weights (clamped, area-normalized) read off the uniform solution: a fair
                    # embedding, where weights from the flat refined patch diverged (camel 15h: 87 h off)
                    again = again if twice else solve(level, True)
                    if again is not None:  # a patch whose cotangent system is not finite keeps uniform
                        again = np.where(np.isfinite(again).all(axis=1)[:, None], again, solution)
                    if again is not None and _kernel().keeps_facing(work, again, new_tris):
                        work[n:] = again
                        yield level, _kernel().tangential_relax(work, new_tris, n)
                        work[n:] = solution
                yield level, _kernel().tangential_relax(work, new_tris, n)
                work[n:] = refined
            yield -1, refined  # the refined patch as triangulated

        tried = []
        if len(holes) == 1:  # the first candidate free of crossings, without the per-hole bookkeeping
            for level, candidate in candidates():
                tried.append(level)
                work[n:] = candidate
                if np.isfinite(candidate).all() and not _crossings(work, triangles, m, index, owner).any():
                    return np.array([level], dtype=np.int64), np.zeros(0, dtype=np.int64)
            work[n:] = refined
            return np.array([tried[0]], dtype=np.int64), np.zeros(1, dtype=np.int64)
        vertex_owner = _vertex_owner(new_tris, owner, n, total - n)
        chosen = np.full(len(holes), -1)
        out = refined.copy()
        for rank, (level, candidate) in enumerate(candidates()):
            tried.append(level)
            # a patch left NaN (its system not finite) is checked as refined and fails this candidate
            broken = ~np.isfinite(candidate).all(axis=1)
            work[n:] = np.where(broken[:, None], refined, candidate)
            crossing = _crossings(work, triangles, m, index, owner)  # (q,) nonzero on crossing holes
            per_hole = np.bincount(owner, weights=crossing, minlength=len(holes))
            per_hole += np.bincount(vertex_owner, weights=broken, minlength=len(holes))
            for hole_index in np.flatnonzero((chosen < 0) & (per_hole == 0)):
                mine = vertex_owner == hole_index
                out[mine] = candidate[mine]
                chosen[hole_index] = rank
            if (chosen >= 0).all():
                break
        work[n:] = out
        return np.array([tried[c] if c >= 0 else tried[0] for c in chosen], dtype=np.int64), np.flatnonzero(
            chosen < 0
        )


def _simple_pieces(loop: np.ndarray, rows: np.ndarray, points: np.ndarray):
    """Split a loop that passes a vertex (or a position: duplicated vertices, ``points`` of the loop)
    more than once into loops that do not, each filled on its own: a patch across the pinch would cross
    the surface there."""
    key = loop
    if len(set(map(tuple, points.tolist()))) < len(loop):
        key = np.unique(points, axis=0, return_inverse=True)[1].ravel()
    elif len(set(loop.tolist())) == len(
        loop
    ):  # the usual loop: simple (a set is quicker than np.unique here)
        if len(loop) >= 3:
            yield loop, rows
        return
    stack = [(loop, rows, key)]
    while stack:
        loop, rows, key = stack.pop()
        first = np.zeros(len(loop), dtype=bool)
        first[np.unique(key, return_index=True)[1]] = True
        if first.all():
            if len(loop) >= 3:
                yield loop, rows
            continue
        q = int(np.argmin(first))  # the first second visit, and the first visit of that vertex
        p = int(np.argmax(key == key[q]))
        stack.append((loop[p:q], rows[p:q], key[p:q]))
        rest = np.r_[0:p, q : len(loop)]
        stack.append((loop[rest], rows[rest], key[rest]))


def _empty_csr(rows: int, cols: int) -> sp.csr_matrix:
    """An all-zero ``(rows, cols)`` CSR matrix, from its arrays (SciPy's shape-only form costs more)."""
    return sp.csr_matrix(
        (np.zeros(0), np.zeros(0, dtype=np.int32), np.zeros(rows + 1, dtype=np.int32)),
        shape=(rows, cols),
        copy=False,
    )


def _vertex_owner(new_tris: np.ndarray, owner: np.ndarray, n: int, p: int) -> np.ndarray:
    """The hole of each of the ``p`` new vertices (numbered from ``n``), from that of each new triangle."""
    vertex_owner = np.zeros(p, dtype=np.int64)
    inside = new_tris >= n
    vertex_owner[new_tris[inside] - n] = np.broadcast_to(owner[:, None], new_tris.shape)[inside]
    return vertex_owner


def _interpolation(
    new_tris: np.ndarray, bounds: np.ndarray, piece_loop: Any, n: int, p: int
) -> sp.csr_matrix:
    """Harmonic weights ``(p, n)`` of the new vertices over their loop's (for colours and other attributes):
    one small solve per piece, whose new triangles are ``new_tris[bounds[i]:bounds[i + 1]]``."""
    rows, cols, vals = [], [], []
    for piece, loop in enumerate(piece_loop):
        local = new_tris[bounds[piece] : bounds[piece + 1]]
        inner = np.unique(local[local >= n])
        if len(inner) == 0:
            continue
        numbering = np.concatenate([loop, inner])
        by_index = np.argsort(numbering)
        tris_local = by_index[np.searchsorted(numbering[by_index], local)]
        k, nl = len(loop), len(numbering)
        # the membrane (continuity 0) with the loop's unit vectors as the fixed "positions"
        unit = np.eye(nl, k)
        harmonic = _fair(
            unit, tris_local, np.arange(k, nl), [], 0, _kernel().unique_edges(tris_local, nl), False
        )
        r, c = np.nonzero(np.abs(harmonic) > 1e-12)
        rows.append(inner[r] - n)
        cols.append(loop[c])
        vals.append(harmonic[r, c])
    if not rows:
        return sp.csr_matrix((p, n))
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(p, n))


class _TriangleIndex:
    """Bounding spheres (about the centroids) of a mesh's triangles in uniform grids, for crossing queries.

    Two grids, the spheres of radius at most 4 times the median and the rest, each queried with its own
    largest radius, so that a few long slivers do not make every query reach far. Each grid (cells of
    about that radius, at most ``4 m`` of them) lists its triangles cell by cell (one stable sort):
    a patch's query reads a few cells in the compiled :func:`o3d_lsmesh._fill_kernel.patch_crossings`,
    where a k-d tree's ball query cost SciPy's per-call overhead (queries are thread-safe; the grids
    pickle).
    """

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray) -> None:
        p = vertices[triangles]
        self.centre = p.mean(axis=1)
        self.radius = np.linalg.norm(p - self.centre[:, None, :], axis=2).max(axis=1)
        small = self.radius <= (4.0 * float(np.median(self.radius)) if len(self.radius) else 0.0)
        self.grids = [self._grid(g) for g in (np.flatnonzero(small), np.flatnonzero(~small)) if len(g)]

    def _grid(self, members: np.ndarray) -> tuple:
        centre = self.centre[members]
        reach = float(self.radius[members].max())
        origin = centre.min(axis=0)
        extent = centre.max(axis=0) - origin
        cell = reach if reach > 0 else max(float(extent.max()), 1.0)
        budget = 4 * len(members) + 64
        while np.prod(np.floor(extent / cell) + 1) > budget:  # the grid stays linear in the triangles
            cell *= 1.5
        dims = (np.floor(extent / cell) + 1).astype(np.int64)
        xyz = np.minimum(np.floor((centre - origin) / cell).astype(np.int64), dims - 1)
        key = (xyz[:, 0] * dims[1] + xyz[:, 1]) * dims[2] + xyz[:, 2]
        order = np.argsort(key, kind="stable")
        indptr = np.zeros(int(np.prod(dims)) + 1, dtype=np.int64)
        np.cumsum(np.bincount(key, minlength=len(indptr) - 1), out=indptr[1:])
        return origin, cell, dims, indptr, members[order], reach


def _crossings(
    vertices: np.ndarray, triangles: np.ndarray, first_new: int, index: Any, owner: Any = None
) -> np.ndarray:
    """For each new triangle (from ``first_new`` on), the number of triangles it meets beyond the corners
    and edge they share: crossings, and folds flat onto a neighbour. With ``owner`` (each new triangle's
    hole), a hole's triangles are not tested once one crosses: nonzero counts then only mark the holes.

    One compiled test (:func:`o3d_lsmesh._fill_kernel.patch_crossings`): each new triangle against the
    input triangles of ``index`` (a :class:`_TriangleIndex` of ``triangles[:first_new]``; if None, one
    is built of the input triangles in the new triangles' box) and the new ones, near it.
    """
    if len(triangles) == first_new:
        return np.zeros(0)
    new = _TriangleIndex(vertices, triangles[first_new:])
    if index is None:
        # the input triangles with a vertex in the new triangles' box grown by twice the largest of them
        p_new = vertices[triangles[first_new:]].reshape(-1, 3)
        low, high = p_new.min(0) - 2.0 * new.radius.max(), p_new.max(0) + 2.0 * new.radius.max()
        in_box = ((vertices >= low) & (vertices <= high)).all(axis=1)
        boxed = np.flatnonzero(in_box[triangles[:first_new]].any(axis=1))
        index = _TriangleIndex(vertices, triangles[boxed])
        triangles, first_new = np.concatenate([triangles[boxed], triangles[first_new:]]), len(boxed)
    return _kernel().patch_crossings(
        vertices,
        triangles,
        first_new,
        index.grids,
        index.centre,
        index.radius,
        new.grids,
        new.centre,
        new.radius,
        owner,
    )


def fill_holes(
    mesh: MeshT,
    *,
    max_hole_edges: int | None = None,
    max_hole_diameter: float | None = None,
    continuity: int = 2,
    density: float = 1.0,
    weights: str = "cotangent",
    fill_border: bool = False,
    progress: bool = False,
    return_report: bool = False,
) -> Any:
    """Close the mesh's holes with patches faired as least-squares meshes; a new mesh.

    Each chosen hole (a closed loop of boundary edges) is triangulated by Liepa's minimum-weight
    dynamic programme (largest dihedral angle, then area), refined to the density of the edges around
    it with Delaunay flips, and its new vertices are placed by minimizing, with the surrounding mesh
    fixed (Sorkine and Cohen-Or 2004, section 6, interpolated anchors):

    * ``continuity=0``: ``sum |x_i - x_j|^2`` over edges (harmonic, a membrane);
    * ``continuity=1``: ``||L x||^2``, the LS-mesh energy (eq. 3), bi-Laplacian;
    * ``continuity=2``: ``(L x)^T K (L x)``, tri-Laplacian: the Laplacian itself varies smoothly, so
      curvature continues across the loop,

    with ``L = I - D^-1 A`` the uniform Laplacian of eq. 1 and ``K = D - A``; only the new vertices are
    unknowns, ``continuity + 1`` rings of the input fixed around each loop. ``weights="cotangent"``
    then solves again with cotangent weights read off that fair solution (``K = D - W``, ``L = M^-1 K``,
    ``M`` the vertex areas), closer to the true surface on irregular meshes.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
        Any triangle mesh: non-manifold edges and vertices, several components, pinched boundaries and
        holes touching at a vertex are handled (a loop through a vertex twice is filled in pieces).
    max_hole_edges : int >= 3, optional
        Fill only holes with at most this many boundary edges.
    max_hole_diameter : float > 0, optional
        Fill only holes whose diameter (largest distance between two loop vertices) is at most this.
    continuity : {0, 1, 2}
        Smoothness across the loop, see above. Default 2.
    density : float in [0, DENSITY_MAX]
        New vertices are spaced like the surrounding edges divided by ``density``; ``0`` adds none
        (the minimum-weight triangulation alone). The work is bounded: at most about what density 2
        adds to a patch of even scale, and no split at a corner of 64 triangles.
    weights : {"cotangent", "uniform"}
        ``"uniform"``: the uniform solve alone; ``"cotangent"``: then one re-weighted solve (see above).
    fill_border : bool
        Also fill each open component's outer border (see :data:`BORDER_FACING_AWAY`): a scan's silhouette,
        a lone island's rim. Default ``False``: left open.
    progress : bool
        Show a tqdm bar over the holes.
    return_report : bool
        Also return the :class:`FillReport`: every loop filled or left open, how or why.

    Returns
    -------
    Mesh of the kind given, or ``(mesh, FillReport)`` if ``return_report``
        The input's vertices and triangles unchanged and in order, then the new ones, wound like their
        neighbours. Holes are those of the welded surface (vertices at equal coordinates merged), so a
        UV seam is not a hole; a new triangle uses the copy of a seam vertex on its hole's side. Every
        attribute stays on the input's elements (UVs, material ids, textures, material, tensor
        attributes) and is extended to the new ones: per-vertex values and UVs harmonically (cotangent
        weights) where the UV chart is continuous around the hole, else the UV of a loop corner of a
        neighbouring triangle; material ids and other per-triangle values of that triangle. Normals
        are recomputed if the input had them.

    Raises
    ------
    TypeError
        ``mesh`` not a mesh; an option of the wrong type.
    ValueError
        An empty or invalid mesh; ``max_hole_edges < 3``; ``max_hole_diameter <= 0``;
        ``continuity`` not 0, 1 or 2; ``density`` outside ``[0, DENSITY_MAX]``; ``weights`` not a choice.

    See Also
    --------
    fill_holes_arrays : the array core, which also reports the holes found.
    HoleFiller : the whole-mesh analysis done once, for several fills of one mesh.
    reconstruct_geometry : re-solve known connectivity instead of building it.

    Notes
    -----
    Loops of more than :data:`DP_MAX_EDGES` edges are cut by chords before the O(k^3) dynamic
    programme. Every result is checked for new triangles that meet the mesh anywhere but at the corners
    and edges they share (crossings, and folds flat onto a neighbour; separating-axis tests against the
    triangles near them): a hole whose patch does is faired again, per hole, with uniform weights, then
    each lower continuity, then left as refined, then filled by the bare minimum-weight triangulation
    (:attr:`HoleOutcome.how` says which). A patch whose fairing system is not finite falls back the same
    way, alone. What still crosses (the surface next to the hole is itself folded) is left open.

    No loop is left open silently: an :class:`O3DLSMeshWarning` names each one left open by a crossing
    or taken as an outer border, and ``return_report=True`` gives every loop, filled or not, how or why.
    A component's outer border is not filled by default (a scan's silhouette; see
    :data:`BORDER_FACING_AWAY`). A loop through a vertex (or a position) twice is filled as its simple
    pieces. Non-manifold edges and vertices elsewhere are left as they are; a chord that already is a
    mesh edge is never used.

    References
    ----------
    P. Liepa, Filling Holes in Meshes, SGP 2003. O. Sorkine and D. Cohen-Or, Least-squares Meshes,
    SMI 2004.

    Examples
    --------
    >>> import open3d as o3d, numpy as np
    >>> sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=20)
    >>> holed = o3d.geometry.TriangleMesh(sphere)
    >>> holed.remove_triangles_by_index(list(range(30)))
    >>> out = fill_holes(holed)
    >>> out.is_watertight(), len(out.triangles) >= len(holed.triangles)
    (True, True)
    """
    data = read_mesh(mesh, weld=True)  # the welded surface's holes: a UV seam is not one
    result = fill_holes_arrays(
        data.vertices,
        data.triangles,
        max_hole_edges=max_hole_edges,
        max_hole_diameter=max_hole_diameter,
        continuity=continuity,
        density=density,
        weights=weights,
        fill_border=fill_border,
        progress=progress,
    )
    out = new_mesh(data, result.vertices, result.triangles if result.holes else None, appended=True)
    return (out, result.report) if as_bool(return_report, name="return_report") else out

"""Triangulating holes: Liepa's minimum-weight programme (chords first on long loops), then refinement.

P. Liepa, Filling Holes in Meshes, SGP 2003, sections 3-4; see docs/algorithms/hole_filling.rst.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..core.arrays import concatenated_ranges, in_sorted
from ..core.progress import Progress
from .find import _cross
from .tuning import ALPHA, COSPHERICAL, DP_MAX_EDGES


def delaunay_triangles(points: np.ndarray) -> np.ndarray | None:
    """The triangles of the 3D Delaunay tetrahedralization of a loop's ``k`` points, as the ``allowed`` of
    the minimum-weight programme (``(k^3,)`` uint8), or None where it restricts nothing (``k < 5``,
    coplanar or cospherical points; Zou et al. 2013, see the docs page)."""
    from scipy.spatial import Delaunay, QhullError

    from .._triangulation_kernel import delaunay_allowed  # compiled: imported where used

    k = len(points)
    if k < 5:
        return None
    points = np.asarray(points, dtype=np.float64)
    # about the centroid: Qhull's and the circumsphere test's round-off follow the coordinates' size
    points = np.ascontiguousarray(points - points.mean(axis=0))
    try:
        tets = Delaunay(points).simplices.astype(np.int64)
    except (QhullError, ValueError):
        return None
    # a point on (within rounding of) a tetrahedron's circumsphere makes the tetrahedralization one of
    # several (a loop on a sphere or a cylinder), chosen by rounding: not the same after a rigid motion
    p = points[tets]
    with np.errstate(all="ignore"):
        try:
            edges = p[:, 1:] - p[:, :1]
            centre = p[:, 0] + np.linalg.solve(2.0 * edges, (edges**2).sum(axis=2)[..., None])[..., 0]
        except np.linalg.LinAlgError:  # a flat tetrahedron (Qhull's triangulated output): not unique
            return None
    return delaunay_allowed(points, tets, centre, COSPHERICAL)


def refine_budget(points: np.ndarray, triangles: np.ndarray, sigma: np.ndarray) -> int:
    """The most new points the refinement may add to a patch: ``4 A / mean(sigma)^2``, ``A`` its area."""
    p = np.asarray(points)[np.asarray(triangles)]
    area = 0.5 * np.sqrt((_cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]) ** 2).sum(axis=1)).sum()
    sigma = np.asarray(sigma, dtype=np.float64)
    mean = float(sigma.sum() / len(sigma)) if len(sigma) else float("nan")  # np.mean's bits
    return int(min(4.0 * area / mean**2, 2.0**62)) if mean > 0 else 0


def _triangulate(
    points: np.ndarray, outer_normals: np.ndarray, forbidden: np.ndarray, spacing: float
) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate a loop, splitting it by chords while it is longer than :data:`DP_MAX_EDGES`.

    ``forbidden``: the chords that are mesh edges, ``(c, 2)`` loop indices ``p < q``. Returns the extra
    points (on the chords) and triangles over the loop's indices ``[0, k)`` followed by the extra points'.
    """
    from .._triangulation_kernel import minimum_weight_triangulation  # compiled: imported where used

    k = len(points)
    if k <= DP_MAX_EDGES:
        matrix = None
        if len(forbidden):  # the programme reads a (k, k) matrix: at most DP_MAX_EDGES squared
            matrix = np.zeros((k, k), dtype=np.uint8)
            matrix[forbidden[:, 0], forbidden[:, 1]] = matrix[forbidden[:, 1], forbidden[:, 0]] = 1
        return np.zeros((0, 3)), minimum_weight_triangulation(
            points, outer_normals, matrix, delaunay_triangles(points)
        )
    keys = np.sort(forbidden[:, 0] * k + forbidden[:, 1])
    # the shortest chord between vertices 1/3 to 2/3 of the loop apart, in chunks of rows
    best = (np.inf, 0, k // 2)
    gap = np.arange(k // 3, k - k // 3 + 1)[None, :]
    for start in range(0, k, 256):
        i = np.arange(start, min(k, start + 256))[:, None]
        j = (i + gap) % k
        dist = np.linalg.norm(points[i] - points[j], axis=-1)
        if len(keys):
            dist = np.where(in_sorted(keys, np.minimum(i, j) * k + np.maximum(i, j)), np.inf, dist)
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
    local = np.full(k + count, -1)  # each point's index in the piece being cut out
    for piece in (
        np.concatenate([np.arange(a, b + 1), e[::-1]]),
        np.concatenate([np.arange(b, k), np.arange(0, a + 1), e]),
    ):
        # outer normals on the piece's edges that are edges of the original loop
        nxt = np.roll(piece, -1)
        on_loop = (piece < k) & (nxt < k) & (nxt == (piece + 1) % k)
        loop_normals = np.zeros((len(piece), 3))
        loop_normals[on_loop] = outer_normals[piece[on_loop]]
        # the forbidden chords with both ends in the piece, renumbered, each p < q again
        local[:] = -1
        local[piece] = np.arange(len(piece))
        ends = local[forbidden]
        ends = np.sort(ends[(ends >= 0).all(axis=1)], axis=1)
        sub_extra, sub_tris = _triangulate(all_points[piece], loop_normals, ends, spacing)
        # the piece's local indices back: [0, len(piece)) -> piece, beyond -> its new extra points
        triangles.append(np.concatenate([piece, offset + np.arange(len(sub_extra))])[sub_tris])
        offset += len(sub_extra)
        extra.append(sub_extra)
    return np.concatenate(extra), np.concatenate(triangles)


def _simple_pieces(loop: np.ndarray, rows: np.ndarray, points: np.ndarray):
    """Split a loop that passes a vertex (or a position: duplicated vertices, ``points`` of the loop)
    more than once into loops that do not, each filled on its own: a patch across the pinch would cross
    the surface there."""
    if len(set(map(tuple, points.tolist()))) == len(loop):  # the usual loop (a set is quicker than np.unique)
        if len(loop) >= 3:
            yield loop, rows
        return
    key = np.unique(points, axis=0, return_inverse=True)[1].ravel()
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


def closable(loop: np.ndarray, points: np.ndarray) -> bool:
    """Whether triangles can close a loop (``points`` its vertices' positions): each of its edges lies in
    a piece of :func:`_simple_pieces`. A piece of two vertices between two visits of one position is a
    zero-width crack (the loop runs out and back along coincident vertices), which no triangle closes."""
    return sum(len(piece) for piece, _ in _simple_pieces(loop, loop, points)) == len(loop)


def triangulate_holes(filler: Any, holes: list, density: float, progress: bool) -> tuple:
    """Triangulate and refine every piece of ``holes`` (loops of ``filler``, a :class:`HoleFiller`): the new
    points ``(p, 3)`` (numbered from ``n`` piece by piece), the new triangles ``(q, 3)`` in the mesh's
    numbering and the hole of each new triangle."""
    from .._triangulation_kernel import loop_geometry, refine  # compiled: imported where used

    vertices, triangles = filler.vertices, filler.triangles
    n = len(vertices)
    # each piece (a loop; one through a vertex twice is cut in pieces) is triangulated on its own,
    # long ones cut by chords sampled at the refinement's spacing (none without) first
    pieces = [
        (h, *p)
        for h, hole in enumerate(holes)
        for p in _simple_pieces(hole.vertices, hole.rows, vertices[hole.vertices])
    ]
    piece_hole, piece_loop, piece_rows = zip(*pieces)
    count = len(piece_loop)
    # each piece's points, the normals across its edges, its spacing and its chords that are mesh edges
    piece_points, piece_outer, piece_spacing, piece_pairs = zip(
        *(
            loop_geometry(loop, rows, vertices, triangles, *filler.vertex_triangles)
            for loop, rows in zip(piece_loop, piece_rows)
        )
    )
    piece_extra, piece_tris = [], []
    with Progress(progress, "filling holes").bar(count, unit="loop") as bar:
        for points, outer, pairs, spacing in zip(piece_points, piece_outer, piece_pairs, piece_spacing):
            extra, tris = _triangulate(points, outer, pairs, spacing / density if density > 0 else 0.0)
            piece_extra.append(extra)
            piece_tris.append(tris)
            bar.update(1)
    # every piece refined at once, in disjoint local index ranges
    lengths = np.array([len(loop) for loop in piece_loop])
    sizes = np.array([len(p) + len(e) for p, e in zip(piece_points, piece_extra)])
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    all_points = np.concatenate([np.concatenate([p, e]) for p, e in zip(piece_points, piece_extra)])
    all_tris = np.concatenate([t + start for t, start in zip(piece_tris, starts)])
    point_piece = np.repeat(np.arange(count), sizes)
    if density > 0:
        # Liepa's scale: each loop vertex's mean edge length, the chords' spacing on their points
        sigma = [
            np.concatenate([filler.sigma[loop] / density, np.full(len(extra), spacing / density)])
            for loop, extra, spacing in zip(piece_loop, piece_extra, piece_spacing)
        ]
        # mesh edges between loop vertices: no flip may make them twice
        all_points, all_tris, point_piece = refine(
            all_points,
            np.concatenate(sigma),
            all_tris,
            np.concatenate([f + s for f, s in zip(piece_pairs, starts)]),
            point_piece,
            ALPHA,
            len(all_points) + refine_budget(all_points, all_tris, filler.sigma[np.concatenate(piece_loop)]),
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
    owner = np.asarray(piece_hole, dtype=np.int64)[tri_piece[tri_order]]  # the hole of each new triangle
    return fresh_points, global_index[all_tris[tri_order]], owner

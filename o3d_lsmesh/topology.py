"""Connectivity of triangle meshes as arrays: edges, adjacency, components, boundary loops, manifoldness.

Everything here works on ``triangles (m, 3) int64`` and a vertex count ``n``
and is vectorized; duplicates are removed by sort-and-mask on integer keys,
which is much faster than ``np.unique`` on large keys.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

__all__ = [
    "halfedges",
    "unique_edges",
    "directed_edges",
    "adjacency_matrix",
    "vertex_valences",
    "connected_components",
    "boundary_halfedges",
    "boundary_loops",
    "nonmanifold_edges",
    "nonmanifold_vertices",
    "check_manifold",
    "euler_characteristic",
]


def halfedges(triangles: np.ndarray) -> np.ndarray:
    """Directed edges ``(3m, 2)`` in triangle order: rows ``t``, ``m + t``, ``2m + t`` are
    ``(a, b)``, ``(b, c)``, ``(c, a)`` of triangle ``t = (a, b, c)``."""
    return np.concatenate(
        [triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]], axis=0
    )


def _group(keys: np.ndarray, bound: int, *, inverse: bool = True):
    """Sort-and-mask grouping of integer ``keys`` in ``[0, bound)``: (order, starts, counts, inverse).

    ``inverse=False`` returns ``None`` in its place (it costs a third of the grouping).

    When key and position fit in 64 bits together they are packed and sorted as
    one ``uint64`` array (numpy sorts plain integers several times faster than
    it argsorts them); ties keep their input order either way. Work arrays are
    reused in place: on large meshes fresh memory costs as much as the sort.
    """
    count = len(keys)
    index_bits = max(1, int(count - 1).bit_length())
    if max(1, int(bound - 1).bit_length()) + index_bits <= 64:
        packed = keys.astype(np.uint64)
        packed <<= np.uint64(index_bits)
        packed |= np.arange(count, dtype=np.uint64)
        packed.sort()
        order = np.bitwise_and(packed, np.uint64((1 << index_bits) - 1)).view(np.int64)
        packed >>= np.uint64(index_bits)
        sorted_keys = packed.view(np.int64)
    else:
        order = np.argsort(keys, kind="stable")
        sorted_keys = keys[order]
    first, starts, counts = _runs(sorted_keys)
    if not inverse:
        return order, starts, counts, None
    rank = np.cumsum(first, dtype=np.int64)
    rank -= 1
    inverse_ = np.empty(count, dtype=np.int64)
    inverse_[order] = rank
    return order, starts, counts, inverse_


def _runs(sorted_keys: np.ndarray):
    """Runs of equal values in sorted ``keys``: (first-of-run mask, run starts, run lengths)."""
    count = len(sorted_keys)
    first = np.empty(count, dtype=bool)
    first[:1] = True
    np.not_equal(sorted_keys[1:], sorted_keys[:-1], out=first[1:])
    starts = np.flatnonzero(first)
    # lengths written in place (np.diff with append copies ``starts`` first)
    lengths = np.empty(len(starts), dtype=np.int64)
    np.subtract(starts[1:], starts[:-1], out=lengths[:-1])
    lengths[-1:] = count - starts[-1:]
    return first, starts, lengths


def _edge_keys(triangles: np.ndarray, n: int) -> np.ndarray:
    # undirected key lo * n + hi of every half-edge, in the row order of halfedges()
    m = len(triangles)
    tail = triangles.T
    head = triangles[:, [1, 2, 0]].T
    keys = np.minimum(tail, head, out=np.empty((3, m), dtype=np.int64))
    keys *= np.int64(n)
    keys += np.maximum(tail, head)
    return keys.reshape(-1)


def _edge_runs(triangles: np.ndarray, n: int):
    # half-edge rows of halfedges() grouped by undirected edge: (order, starts, counts)
    return _group(_edge_keys(triangles, n), n * n, inverse=False)[:3]


def unique_edges(triangles: np.ndarray, n: int | None = None):
    """Undirected edges with the number of triangles on each.

    Returns
    -------
    edges : (k, 2) int64
        ``edges[:, 0] < edges[:, 1]``, sorted lexicographically.
    counts : (k,) int64
        Triangles sharing each edge (1 on a boundary, 2 inside, >2 non-manifold).
    inverse : (3m,) int64
        Edge index of each half-edge of :func:`halfedges`.
    """
    if n is None:
        n = int(triangles.max()) + 1 if len(triangles) else 0
    keys = _edge_keys(triangles, n)
    order, starts, counts, inverse = _group(keys, n * n)
    first = keys[order[starts]]
    edges = np.empty((len(first), 2), dtype=np.int64)
    np.floor_divide(first, n, out=edges[:, 0])
    np.remainder(first, n, out=edges[:, 1])
    return edges, counts, inverse


def directed_edges(triangles: np.ndarray, n: int, *, executor=None):
    """Both directions of every edge, sorted by ``(source, target)``, with their triangle counts.

    Returns
    -------
    src, dst : (2e,) int64
        Edge ``src[k] -> dst[k]``; ``src`` is sorted, so these are the CSR
        arrays of the adjacency (``dst`` the column indices).
    triangle_count : (2e,) int64
        Triangles on each edge (1 on a boundary, 2 inside, more when
        non-manifold), whatever the orientation of the triangles.

    Each triangle gives the key ``src << bits | dst`` of each direction of its
    three edges once; one sort of the plain int64 keys (numpy's SIMD sort, far
    faster than argsort, ``np.unique`` or a COO-to-CSR merge) groups them.
    With a thread pool ``executor``, each half of the triangles is sorted in
    its own thread, and the two sorted halves are merged as two pairs of runs
    split at one key, again in two threads (same result).
    """
    bits = max(1, int(n - 1).bit_length())
    if 2 * bits > 62:  # beyond 2^31 vertices: keys by multiplication do not fit either
        raise ValueError(f"n must be below 2**31, got {n}")
    shift = np.int64(bits)
    triangles = np.asarray(triangles, dtype=np.int64)
    m = len(triangles)
    if executor is None or m < 1 << 16:
        return _unique_keys(_sorted_keys(triangles, shift), shift)
    half = m // 2
    low, high = executor.map(lambda rows: _sorted_keys(triangles[rows], shift), (slice(0, half), slice(half, m)))
    pivot = high[len(high) // 2]
    cut_low, cut_high = np.searchsorted(low, pivot), np.searchsorted(high, pivot)
    parts = list(executor.map(
        lambda pair: _unique_keys(_merged(*pair), shift),
        ((low[:cut_low], high[:cut_high]), (low[cut_low:], high[cut_high:])),
    ))
    del low, high
    return tuple(np.concatenate([part[i] for part in parts]) for i in range(3))


def _sorted_keys(triangles: np.ndarray, shift: np.int64) -> np.ndarray:
    m = len(triangles)
    corners = triangles.T  # a view: columns read in place
    # written in place: on large meshes fresh temporaries cost as much as the sort
    keys = np.empty(6 * m, dtype=np.int64)
    rows = keys.reshape(6, m)
    np.left_shift(corners, shift, out=rows[:3])
    rows[3:] = rows[:3]
    for row, head in enumerate((1, 2, 0, 2, 0, 1)):
        rows[row] |= corners[head]
    keys.sort()
    return keys


def _merged(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    keys = np.concatenate([a, b])
    keys.sort(kind="stable")  # two sorted runs: one merge
    return keys


def _unique_keys(keys: np.ndarray, shift: np.int64):
    _, at, triangle_count = _runs(keys)
    keys = keys[at]
    src = keys >> shift
    keys &= np.int64((1 << int(shift)) - 1)
    return src, keys, triangle_count


def adjacency_matrix(triangles: np.ndarray, n: int) -> sp.csr_matrix:
    """Symmetric binary vertex adjacency ``(n, n)`` CSR (1 where an edge joins two vertices), sorted indices."""
    src, dst, _ = directed_edges(triangles, n)
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(src, minlength=n), out=indptr[1:])
    # SciPy keeps 32-bit indices when they fit; giving them so avoids a copy
    index_dtype = np.int32 if len(dst) < np.iinfo(np.int32).max and n < np.iinfo(np.int32).max else np.int64
    adjacency = sp.csr_matrix((np.ones(len(dst)), dst.astype(index_dtype), indptr.astype(index_dtype)), shape=(n, n))
    adjacency.has_canonical_format = True  # sorted, no duplicates
    return adjacency


def vertex_valences(triangles: np.ndarray, n: int) -> np.ndarray:
    """Number of edge neighbours of every vertex, ``(n,) int64`` (0 for isolated vertices)."""
    edges, _, _ = unique_edges(triangles, n)
    return np.bincount(edges.ravel(), minlength=n).astype(np.int64)


def connected_components(triangles: np.ndarray, n: int):
    """Connected components over edges: ``(count, labels (n,) int64)``; isolated vertices are their own."""
    count, labels = csgraph.connected_components(adjacency_matrix(triangles, n), directed=False)
    return int(count), labels.astype(np.int64)


def euler_characteristic(triangles: np.ndarray, n_referenced: int | None = None) -> int:
    """``V - E + F`` over the referenced vertices."""
    edges, _, _ = unique_edges(triangles)
    if n_referenced is None:
        n_referenced = len(np.unique(triangles))
    return int(n_referenced - len(edges) + len(triangles))


def boundary_halfedges(triangles: np.ndarray, n: int | None = None) -> np.ndarray:
    """Half-edges ``(b, 2)`` on edges used by exactly one triangle, oriented as in that triangle."""
    _, counts, inverse = unique_edges(triangles, n)
    return halfedges(triangles)[counts[inverse] == 1]


def nonmanifold_edges(triangles: np.ndarray, n: int | None = None) -> np.ndarray:
    """Edges ``(k, 2)`` shared by more than two triangles."""
    edges, counts, _ = unique_edges(triangles, n)
    return edges[counts > 2]


def nonmanifold_vertices(triangles: np.ndarray, n: int, *, _runs=None) -> np.ndarray:
    """Vertices whose triangles do not form a single fan (bow-ties and the like), sorted.

    The corners ``(t, v)`` of the triangles around a vertex are linked when two
    triangles share a manifold edge through ``v``; a vertex is non-manifold when
    its corners fall into more than one linked group.
    """
    m = len(triangles)
    corners = 3 * m
    order, starts, counts = _edge_runs(triangles, n) if _runs is None else _runs
    # corner p*m + t holds triangles[t, p]; half-edge row q*m + t runs from corner q*m + t
    # to corner ((q + 1) % 3)*m + t, so every corner starts one half-edge and ends one
    tail = triangles.T.reshape(-1)
    interior = starts[counts == 2]
    a, b = order[interior], order[interior + 1]
    del interior
    same_direction = tail[a] == tail[b]
    end_a = a + m
    end_a[end_a >= corners] -= corners
    end_b = b + m
    end_b[end_b >= corners] -= corners
    # every corner has at most two links, one through the half-edge it starts and one through the
    # one it ends, so the graph is written as CSR directly (a self-link where there is none)
    index = np.int32 if 2 * corners < np.iinfo(np.int32).max else np.int64
    link = np.empty((corners, 2), dtype=index)
    link[:, 0] = np.arange(corners, dtype=index)
    link[:, 1] = link[:, 0]
    link[a, 0] = np.where(same_direction, b, end_b)
    link[b, 0] = np.where(same_direction, a, end_a)
    link[end_a, 1] = np.where(same_direction, end_b, b)
    link[end_b, 1] = np.where(same_direction, end_a, a)
    del a, b, end_a, end_b, same_direction
    first = np.minimum(link[:, 0], link[:, 1])
    np.maximum(link[:, 0], link[:, 1], out=link[:, 1])
    link[:, 0] = first
    del first
    graph = sp.csr_matrix(
        (np.ones(2 * corners, dtype=np.int8), link.reshape(-1), np.arange(0, 2 * corners + 1, 2, dtype=index)),
        shape=(corners, corners),
    )
    graph.has_sorted_indices = True  # each row's two links were just ordered
    # the links are symmetric, so strong components are the components, and finding them
    # reads the graph alone (weak or undirected ones transpose it first)
    fan_count, fan = csgraph.connected_components(graph, directed=True, connection="strong")
    # links only join corners of one vertex, so every fan belongs to exactly one vertex
    vertex_of_fan = np.zeros(fan_count, dtype=np.int64)
    vertex_of_fan[fan] = tail
    return np.flatnonzero(np.bincount(vertex_of_fan, minlength=n) > 1)


def check_manifold(triangles: np.ndarray, n: int, *, name: str = "mesh") -> None:
    """Raise ``ValueError`` naming the first non-manifold edge or vertex of the mesh."""
    runs = _edge_runs(triangles, n)
    order, starts, counts = runs
    bad = np.flatnonzero(counts > 2)
    if len(bad):
        row = order[starts[bad[0]]]
        e = np.sort(halfedges(triangles)[row])
        raise ValueError(
            f"{name} must be edge-manifold, got edge ({int(e[0])}, {int(e[1])}) shared by more than two "
            f"triangles ({len(bad)} such edges)"
        )
    bad_vertices = nonmanifold_vertices(triangles, n, _runs=runs)
    if len(bad_vertices):
        raise ValueError(
            f"{name} must be vertex-manifold, got vertex {int(bad_vertices[0])} joining separate fans of "
            f"triangles ({len(bad_vertices)} such vertices)"
        )


def boundary_loops(triangles: np.ndarray, n: int) -> list[np.ndarray]:
    """Every boundary loop as an ordered ``(l,) int64`` array of vertex indices.

    A loop follows the orientation of its triangles and starts at its smallest
    vertex index; loops are sorted by that start. Needs a manifold boundary
    (exactly two boundary edges at every boundary vertex).

    Raises
    ------
    ValueError
        A boundary vertex with other than two boundary edges.
    """
    bhe = boundary_halfedges(triangles, n)
    if len(bhe) == 0:
        return []
    degree = np.bincount(bhe.ravel(), minlength=n)
    on_boundary = degree > 0
    if np.any(degree[on_boundary] != 2):
        v = int(np.flatnonzero(on_boundary & (degree != 2))[0])
        raise ValueError(
            f"mesh boundary must be manifold, got vertex {v} on {int(degree[v])} boundary edges"
        )
    nxt = np.full(n, -1, dtype=np.int64)
    nxt[bhe[:, 0]] = bhe[:, 1]
    if np.any(nxt[bhe[:, 0]] != bhe[:, 1]) or np.count_nonzero(nxt >= 0) != len(bhe):
        # inconsistent orientation along the boundary: orient each loop by walking the undirected graph
        return _loops_by_walk(bhe, n)
    verts = np.flatnonzero(on_boundary)
    graph = sp.coo_matrix((np.ones(len(bhe)), (bhe[:, 0], bhe[:, 1])), shape=(n, n))
    _, label = csgraph.connected_components(graph, directed=False)
    label = label[verts]
    start = np.full(label.max() + 1, np.iinfo(np.int64).max)
    np.minimum.at(start, label, verts)
    starts = np.sort(start[np.unique(label)])
    # list ranking by pointer jumping: cut each cycle just before its start, then double
    succ = nxt.copy()
    prev_of_start = np.full(n, -1, dtype=np.int64)
    prev_of_start[nxt[verts]] = verts
    succ[prev_of_start[starts]] = -1
    rank = np.where(succ >= 0, 1, 0)[verts]
    rank_full = np.zeros(n, dtype=np.int64)
    rank_full[verts] = rank
    jump = succ.copy()
    active = verts[jump[verts] >= 0]
    while len(active):
        target = jump[active]
        rank_full[active] += rank_full[target]
        jump[active] = jump[target]
        active = active[jump[active] >= 0]
    # rank_full = steps to the end of the cut cycle; position from start = length - 1 - rank
    loop_of = np.zeros(n, dtype=np.int64)
    loop_index = np.searchsorted(starts, start[label])
    loop_of[verts] = loop_index
    length = rank_full[starts] + 1
    position = length[loop_of[verts]] - 1 - rank_full[verts]
    order = np.lexsort((position, loop_of[verts]))
    ordered = verts[order]
    bounds = np.cumsum(length)[:-1]
    return [np.ascontiguousarray(loop) for loop in np.split(ordered, bounds)]


def _loops_by_walk(bhe: np.ndarray, n: int) -> list[np.ndarray]:
    # Rare path (boundary with inconsistent orientation): a plain walk over boundary vertices.
    neighbours: dict[int, list[int]] = {}
    for a, b in bhe.tolist():
        neighbours.setdefault(a, []).append(b)
        neighbours.setdefault(b, []).append(a)
    seen: set[int] = set()
    loops = []
    for start in sorted(neighbours):
        if start in seen:
            continue
        loop = [start]
        seen.add(start)
        prev, cur = start, neighbours[start][0]
        directed = {tuple(e) for e in bhe.tolist()}
        if (start, cur) not in directed:
            cur = neighbours[start][1]
        while cur != start:
            loop.append(cur)
            seen.add(cur)
            a, b = neighbours[cur]
            prev, cur = cur, (b if a == prev else a)
        loops.append(np.asarray(loop, dtype=np.int64))
    return loops

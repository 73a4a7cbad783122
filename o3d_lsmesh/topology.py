"""Connectivity of triangle meshes as arrays: edges, adjacency, components, boundary loops, manifoldness.

Everything here works on ``triangles (m, 3) int64`` and a vertex count ``n``
and is vectorized; duplicates are removed by sort-and-mask on integer keys,
which is much faster than ``np.unique`` on large keys.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

try:  # SciPy's sparse kernels (private, the same signatures since SciPy 1.0): sorts without a copy
    from scipy.sparse._sparsetools import csr_sort_indices as _csr_sort_indices
    from scipy.sparse._sparsetools import csr_tocsc as _csr_tocsc
except ImportError:  # pragma: no cover - a SciPy without them sorts with numpy
    _csr_tocsc = _csr_sort_indices = None

__all__ = [
    "BoundaryCurves",
    "EdgeStructure",
    "VertexRings",
    "adjacency_matrix",
    "boundary_chains",
    "boundary_curves",
    "boundary_halfedges",
    "boundary_loops",
    "connected_components",
    "directed_edges",
    "edge_structure",
    "halfedges",
    "nonmanifold_edges",
    "nonmanifold_vertices",
    "ring_pattern",
    "unique_edges",
    "vertex_rings",
]


def halfedges(triangles: np.ndarray) -> np.ndarray:
    """Directed edges ``(3m, 2)`` in triangle order: rows ``t``, ``m + t``, ``2m + t`` are
    ``(a, b)``, ``(b, c)``, ``(c, a)`` of triangle ``t = (a, b, c)``."""
    return np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]], axis=0)


def group_keys(keys: np.ndarray, bound: int):
    """Sort-and-mask grouping of integer ``keys`` in ``[0, bound)``: (order, starts, counts, inverse).

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
    rank = np.cumsum(first, dtype=np.int64)
    rank -= 1
    inverse = np.empty(count, dtype=np.int64)
    inverse[order] = rank
    return order, starts, counts, inverse


def _runs(sorted_keys: np.ndarray):
    """Runs of equal values in sorted ``keys``: (first-of-run mask, run starts, run lengths)."""
    first = run_heads(sorted_keys)
    starts = np.flatnonzero(first)
    return first, starts, _run_lengths(starts, len(sorted_keys))


def run_heads(values: np.ndarray) -> np.ndarray:
    """``(k,) bool``: True where ``values`` differs from the value before it (and at the first)."""
    first = np.empty(len(values), dtype=bool)
    first[:1] = True
    np.not_equal(values[1:], values[:-1], out=first[1:])
    return first


def _run_lengths(starts: np.ndarray, count: int) -> np.ndarray:
    """Lengths of the runs starting at ``starts`` in ``count`` items, in ``starts``' dtype."""
    # written in place (np.diff with append copies ``starts`` first)
    lengths = np.empty(len(starts), dtype=starts.dtype)
    np.subtract(starts[1:], starts[:-1], out=lengths[:-1])
    lengths[-1:] = count - starts[-1:]
    return lengths


def edge_runs(triangles: np.ndarray, n: int):
    # half-edge rows of halfedges() grouped by undirected edge: (order, starts, counts)
    return edge_structure(triangles, n).runs


@dataclass(frozen=True)
class EdgeStructure:
    """The undirected edges of a mesh and the grouping of its half-edges, from one sort.

    Computed once per operation by :func:`edge_structure` and passed down to
    whatever needs edges (valences, boundary, boundary curves, ring patterns,
    Laplacians), so that a mesh's edge sort runs once.

    Attributes
    ----------
    edges : (e, 2) int32 (int64 beyond 2**31 half-edges)
        ``edges[:, 0] < edges[:, 1]``, sorted lexicographically.
    counts : (e,) int32
        Triangles sharing each edge (1 on a boundary, 2 inside, >2 non-manifold).
    inverse : (3m,) int32
        Edge index of each half-edge row of :func:`halfedges`.
    order : (3m,) int32
        Half-edge rows grouped by edge (edge ``k``'s rows are
        ``order[starts[k]:starts[k] + counts[k]]``, in row order).
    starts : (e,) int32
        First position of each edge in ``order``.
    """

    edges: np.ndarray
    counts: np.ndarray
    order: np.ndarray
    starts: np.ndarray
    _inverse: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def inverse(self) -> np.ndarray:
        """Edge index of each half-edge row, ``(3m,)``: formed on first use (local fairing never needs it)."""
        if self._inverse is None:
            inverse = np.empty(len(self.order), dtype=self.order.dtype)
            inverse[self.order] = np.repeat(np.arange(len(self.edges), dtype=self.order.dtype), self.counts)
            # a race recomputes the same array: harmless
            object.__setattr__(self, "_inverse", inverse)
        return self._inverse  # type: ignore[return-value]

    @property
    def runs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(order, starts, counts)``: the half-edge grouping that boundary walks take."""
        return self.order, self.starts, self.counts


def edge_structure(triangles: np.ndarray, n: int | None = None) -> EdgeStructure:
    """The :class:`EdgeStructure` of a mesh: its ``3m`` half-edges grouped by undirected edge, without a sort.

    The half-edges are ordered by ``(lo, hi)`` with two stable counting sorts
    (least significant key first), each a CSR-to-CSC transpose in SciPy's C
    code: linear, and about half the time of one comparison sort of packed
    64-bit keys. Index arrays are int32 when the mesh fits (``3m < 2**31``),
    which halves the memory traffic that dominates at scan sizes. The result
    equals a stable sort of the keys ``lo * n + hi``.

    Examples
    --------
    >>> import numpy as np
    >>> es = edge_structure(np.array([[0, 1, 2], [0, 2, 3]]), 4)
    >>> es.edges.tolist(), es.counts.tolist()
    ([[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]], [1, 2, 1, 1, 1])
    """
    triangles = np.asarray(triangles)
    if n is None:
        n = int(triangles.max()) + 1 if len(triangles) else 0
    m = len(triangles)
    count = 3 * m
    index = np.int32 if max(count, n) < np.iinfo(np.int32).max else np.int64
    if count == 0:
        empty = np.zeros(0, dtype=index)
        return EdgeStructure(np.zeros((0, 2), dtype=index), empty, empty, empty, _inverse=empty)
    tail = triangles.T
    head = triangles[:, [1, 2, 0]].T
    lo = np.minimum(tail, head).astype(index).reshape(-1)  # rows of halfedges() order
    hi = np.maximum(tail, head).astype(index).reshape(-1)
    del tail, head
    rows = np.arange(count + 1, dtype=np.int64)
    # pass 1: half-edges by hi; pass 2: that order, stably by lo
    by_hi = sp.csr_matrix((rows[:-1].astype(index), hi, rows), shape=(count, n)).tocsc().data
    by_lo = sp.csr_matrix((by_hi, lo[by_hi], rows), shape=(count, n)).tocsc()
    del by_hi, rows
    order = by_lo.data
    lo_start = by_lo.indptr
    del by_lo
    sorted_hi = hi[order]
    first = run_heads(sorted_hi)
    first[lo_start[:-1][lo_start[:-1] < lo_start[1:]]] = True  # a new lo starts a new edge
    starts = np.flatnonzero(first).astype(index)
    counts = _run_lengths(starts, count)
    edges = np.empty((len(starts), 2), dtype=index)
    edges[:, 0] = lo[order[starts]]
    edges[:, 1] = sorted_hi[starts]
    del sorted_hi, lo, hi, first
    return EdgeStructure(edges, counts, order, starts)


#: Indices per call of :func:`gather` (numpy converts an index to intp first: a temporary this size).
_GATHER_BLOCK = 1 << 16


def gather(values: np.ndarray, index: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``values[index]`` for a 1-D ``index`` known to be in range, of any integer dtype (into ``out`` if given).

    ``np.take`` with ``mode="wrap"`` into a buffer (the default mode buffers its output, costing
    more than the gather), in blocks when the index is not intp: numpy converts it to intp first,
    and a mesh-sized converted copy is fresh memory, whose page faults cost more than the gather.
    """
    if out is None:
        out = np.empty(np.shape(index), dtype=values.dtype)
    if index.dtype == np.intp or len(index) <= _GATHER_BLOCK:
        return np.take(values, index, out=out, mode="wrap")
    for i in range(0, len(index), _GATHER_BLOCK):
        np.take(values, index[i : i + _GATHER_BLOCK], out=out[i : i + _GATHER_BLOCK], mode="wrap")
    return out


#: Corner slots of the six directed entries of a triangle in :func:`vertex_rings`: entry ``d * m + t``
#: runs from corner ``RING_ROW_SLOT[d]`` of triangle ``t`` (its row) to corner ``RING_COLUMN_SLOT[d]``
#: (its column); entries 0-2 are the half-edges of :func:`halfedges`, 3-5 the same edges reversed.
RING_ROW_SLOT = (0, 1, 2, 1, 2, 0)
RING_COLUMN_SLOT = (1, 2, 0, 0, 1, 2)

#: Vertices per block of :func:`vertex_rings` (about 12 entries each): block temporaries of a few
#: megabytes, which the allocator reuses instead of mapping (and faulting in) fresh pages.
_RING_BLOCK = 1 << 14


@dataclass(frozen=True)
class VertexRings:
    """The 1-ring CSR pattern of a mesh, with the triangles behind every slot.

    Built by :func:`vertex_rings`. Row ``v`` of ``(indptr, indices)`` holds ``v`` itself and its
    distinct edge neighbours, in column order (canonical CSR). Every triangle ``t`` gives six
    *entries*: entry ``d * m + t`` (``d < 6``) sits in row ``triangles[t, RING_ROW_SLOT[d]]`` and
    column ``triangles[t, RING_COLUMN_SLOT[d]]``, so slot ``(v, w)`` collects one entry per triangle
    on the edge ``{v, w}``.

    Attributes
    ----------
    indptr : (n + 1,) int32 (int64 beyond ``2**31`` entries)
    indices : (nnz,) int32
        The pattern: diagonal plus both directions of every edge, ``nnz = n + 2 e``.
    diagonal : (n,) int64
        Position of each row's diagonal in ``indices``.
    pairs : (2, nnz) int32
        Two entries of each slot: the two triangles of an edge of two; on an edge of one triangle
        its entry twice, on an edge of more two of them; ``6 m`` on the diagonal.
    valence : (n,) int64
        Distinct edge neighbours of every vertex (0 for isolated vertices).
    boundary : (n,) bool
        Vertices on an edge of one triangle or of more than two.
    """

    indptr: np.ndarray
    indices: np.ndarray
    diagonal: np.ndarray
    pairs: np.ndarray
    valence: np.ndarray
    boundary: np.ndarray

    @property
    def n(self) -> int:
        return len(self.indptr) - 1


def vertex_rings(triangles: np.ndarray, n: int) -> VertexRings:
    """The :class:`VertexRings` of a mesh: its 1-ring CSR pattern, valences and boundary, in one pass.

    The ``3 m`` triangle corners are grouped by vertex with one stable counting sort (SciPy's
    CSR-to-CSC transpose); then, block by block of vertices, every corner gives its two entries
    (to the next and the previous corner of its triangle), each row's few columns are sorted in
    place (about 12 per row), and equal columns of a row are the triangles of one edge. Only the
    results are mesh-sized (int32 when the mesh fits): the per-block temporaries stay a few
    megabytes, so that at scan sizes no memory is mapped and faulted in for the sort's sake.
    Arrays sized by the bound ``6 m + n`` on the slots are allocated but only their used prefix
    is touched. What local fairing needs (pattern, valences, boundary) comes from this pass, with
    no undirected edge list.

    Examples
    --------
    >>> import numpy as np
    >>> rings = vertex_rings(np.array([[0, 1, 2], [0, 2, 3]]), 4)
    >>> rings.indptr.tolist(), rings.indices.tolist()
    ([0, 4, 7, 11, 14], [0, 1, 2, 3, 0, 1, 2, 0, 1, 2, 3, 0, 2, 3])
    >>> rings.valence.tolist(), rings.boundary.tolist()
    ([3, 2, 3, 2], [True, True, True, True])
    >>> np.sort(rings.pairs[:, rings.indptr[2] : rings.indptr[3]], axis=0).tolist()  # row 2's slots
    [[4, 8, 12, 3], [7, 8, 12, 3]]
    """
    triangles = np.asarray(triangles)
    m = len(triangles)
    corners = 3 * m
    bound = 6 * m + n
    index = np.int32 if bound + 1 < np.iinfo(np.int32).max else np.int64
    flat = np.ascontiguousarray(triangles, dtype=index).reshape(-1)  # corner (t, a) at 3 t + a
    # corners grouped by vertex, stably: a counting sort, the transpose of the (m, n) CSR whose row
    # t holds triangle t's corners (data: the corner's place a in its triangle)
    start = np.zeros(n + 1, dtype=index)
    by_vertex = np.empty(corners, dtype=index)  # the triangle of each corner
    place = np.empty(corners, dtype=np.int8)  # its place in the triangle
    if _csr_tocsc is not None:
        _csr_tocsc(
            m,
            n,
            np.arange(0, corners + 1, 3, dtype=index),
            flat,
            np.tile(np.arange(3, dtype=np.int8), m),
            start,
            by_vertex,
            place,
        )
    else:  # pragma: no cover
        order = np.argsort(flat, kind="stable")
        by_vertex[:], place[:] = order // 3, order % 3
        np.cumsum(np.bincount(flat, minlength=n), out=start[1:])
    indices = np.empty(bound, dtype=index)  # only the used prefix (n + 2e) is ever touched
    pairs = np.empty((2, bound), dtype=index)
    diagonal = np.empty(n, dtype=np.int64)
    valence = np.zeros(n, dtype=np.int64)
    boundary = np.zeros(n, dtype=bool)
    offset = 0
    for v0 in range(0, n, _RING_BLOCK):
        v1 = min(n, v0 + _RING_BLOCK)
        rows = v1 - v0
        triangle = by_vertex[start[v0] : start[v1]]
        slot = place[start[v0] : start[v1]].astype(index)
        at_corner = 3 * triangle
        # the corner's two entries: forward (id a * m + t, to the next corner) and reverse (id
        # d * m + t with d = 3 + (a - 1) % 3, to the previous corner)
        columns = np.empty(2 * len(triangle), dtype=index)
        entries = np.empty(2 * len(triangle), dtype=index)
        columns[0::2] = gather(flat, at_corner + (slot + 1) % 3)
        columns[1::2] = gather(flat, at_corner + (slot + 2) % 3)
        forward = entries[0::2]
        np.multiply(slot, m, out=forward)
        forward += triangle
        reverse = entries[1::2]
        np.add(forward, 2 * m, out=reverse)
        reverse[slot == 0] += 3 * m
        del triangle, slot, at_corner
        degree = np.diff(start[v0 : v1 + 1])
        local = (2 * (start[v0 : v1 + 1] - start[v0])).astype(index)
        if _csr_sort_indices is not None:
            _csr_sort_indices(rows, local, columns, entries)  # each row's columns in order
        else:  # pragma: no cover
            row_of = np.repeat(np.arange(rows), 2 * degree)
            order = np.lexsort((columns, row_of))
            columns, entries = columns[order], entries[order]
        # a slot starts at every new column and at every non-empty row
        first = run_heads(columns)
        first[local[:-1][degree > 0]] = True
        at = np.flatnonzero(first)
        multiplicity = np.diff(at, append=len(columns))
        row = np.repeat(np.arange(rows), 2 * degree)[at]
        column = columns[at]
        per_row = np.bincount(row, minlength=rows)
        valence[v0:v1] = per_row
        boundary[v0 + row[multiplicity != 2]] = True
        # global positions: each row's slots below its vertex, its diagonal, the slots above
        row_start = np.cumsum(per_row + 1) - (per_row + 1) + offset
        rank = np.arange(len(at)) - (np.cumsum(per_row) - per_row)[row]
        vertex = np.arange(v0, v1)
        above = column > vertex[row]
        position = row_start[row] + rank + above
        diagonal_position = row_start + np.bincount(row[~above], minlength=rows)
        indices[position] = column
        indices[diagonal_position] = vertex
        pairs[0, position] = entries[at]
        pairs[1, position] = entries[at + (multiplicity > 1)]
        pairs[:, diagonal_position] = 6 * m  # a zero row for the operators
        diagonal[v0:v1] = diagonal_position
        offset += int(per_row.sum()) + rows
    indptr = np.zeros(n + 1, dtype=index)
    np.cumsum(valence + 1, out=indptr[1:])
    return VertexRings(indptr, indices[:offset], diagonal, pairs[:, :offset], valence, boundary)


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
    return unique_edges_and_runs(triangles, n)[0]


def unique_edges_and_runs(triangles: np.ndarray, n: int | None = None):
    """:func:`unique_edges` and the half-edge runs of :func:`boundary_loops` (``_runs``) from one edge structure."""
    es = edge_structure(triangles, n)
    return (es.edges.astype(np.int64), es.counts.astype(np.int64), es.inverse.astype(np.int64)), es.runs


def ring_pattern(edges: np.ndarray, n: int):
    """CSR layout of the 1-ring pattern (diagonal plus both directions of every edge), without a sort.

    ``edges (e, 2)`` as in :class:`EdgeStructure` (``lo < hi``, sorted). Row
    ``v`` holds, in column order, the edges where ``v`` is the larger end
    (backward, columns ``< v``), its diagonal, and the edges where ``v`` is the
    smaller end (forward, columns ``> v``): canonical CSR. Returns ``indptr
    (n+1,)``, ``indices (nnz,)`` and the CSR positions (all int32 when they fit) of
    the diagonal ``(n,)``, of each edge forward ``(e,)`` and backward ``(e,)``,
    so that data can be scattered straight into CSR order.

    Examples
    --------
    >>> import numpy as np
    >>> indptr, indices, diagonal, forward, backward = ring_pattern(np.array([[0, 1], [0, 2], [1, 2]]), 3)
    >>> indptr.tolist(), indices.tolist(), forward.tolist(), backward.tolist()
    ([0, 3, 6, 9], [0, 1, 2, 0, 1, 2, 0, 1, 2], [1, 2, 5], [3, 6, 7])
    """
    lo, hi = edges[:, 0], edges[:, 1]
    e = len(edges)
    index = np.int32 if 2 * e + n < np.iinfo(np.int32).max else np.int64
    n_forward = np.bincount(lo, minlength=n)
    n_backward = np.bincount(hi, minlength=n)
    indptr = np.zeros(n + 1, dtype=index)
    np.cumsum(n_forward, out=indptr[1:])
    indptr[1:] += n_backward.cumsum()
    indptr[1:] += np.arange(1, n + 1, dtype=index)
    diagonal = indptr[:-1] + n_backward.astype(index)
    # edges are sorted by (lo, hi), so the forward edges of a row are contiguous
    first_forward = np.zeros(n, dtype=index)
    np.cumsum(n_forward[:-1], out=first_forward[1:])
    forward = np.arange(e, dtype=index)
    forward += (diagonal + 1 - first_forward)[lo]
    del first_forward, n_forward
    # backward: edges by (hi, lo), a stable counting sort of the edge list by hi (a CSC transpose)
    by_hi = (
        sp.csr_matrix((np.arange(e, dtype=index), hi, np.arange(e + 1, dtype=np.int64)), shape=(e, max(n, 1)))
        .tocsc()
        .data
    )
    first_backward = np.zeros(n, dtype=index)
    np.cumsum(n_backward[:-1], out=first_backward[1:])
    backward = np.empty(e, dtype=index)
    rank = np.arange(e, dtype=index)
    rank += (indptr[:-1] - first_backward)[hi[by_hi]]
    backward[by_hi] = rank
    del rank, by_hi, first_backward
    indices = np.empty(int(indptr[-1]), dtype=index)
    indices[diagonal] = np.arange(n, dtype=index)
    indices[forward] = hi
    indices[backward] = lo
    return indptr, indices, diagonal, forward, backward


def directed_edges(triangles: np.ndarray, n: int):
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
    """
    bits = max(1, int(n - 1).bit_length())
    if 2 * bits > 62:  # beyond 2^31 vertices: keys by multiplication do not fit either
        raise ValueError(f"n must be below 2**31, got {n}")
    shift = np.int64(bits)
    triangles = np.asarray(triangles, dtype=np.int64)
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
    adjacency = sp.csr_matrix(
        (np.ones(len(dst)), dst.astype(index_dtype), indptr.astype(index_dtype)), shape=(n, n)
    )
    adjacency.has_canonical_format = True  # sorted, no duplicates
    return adjacency


def connected_components(triangles: np.ndarray, n: int):
    """Connected components over edges: ``(count, labels (n,) int64)``; isolated vertices are their own."""
    count, labels = csgraph.connected_components(adjacency_matrix(triangles, n), directed=False)
    return int(count), labels.astype(np.int64)


def boundary_halfedges(triangles: np.ndarray, n: int | None = None) -> np.ndarray:
    """Half-edges ``(b, 2)`` on edges used by exactly one triangle, oriented as in that triangle."""
    _, counts, inverse = unique_edges(triangles, n)
    return halfedges(triangles)[counts[inverse] == 1]


def nonmanifold_edges(triangles: np.ndarray, n: int | None = None) -> np.ndarray:
    """Edges ``(k, 2)`` shared by more than two triangles."""
    edges, counts, _ = unique_edges(triangles, n)
    return edges[counts > 2]


def nonmanifold_vertices(triangles: np.ndarray, n: int) -> np.ndarray:
    """Vertices whose triangles do not form a single fan (bow-ties and the like), sorted.

    The corners ``(t, v)`` of the triangles around a vertex are linked when two
    triangles share a manifold edge through ``v``; a vertex is non-manifold when
    its corners fall into more than one linked group.
    """
    tail = triangles.T.reshape(-1)
    fan_count, fan = corner_fans(triangles, n, edge_runs(triangles, n))
    # links only join corners of one vertex, so every fan belongs to exactly one vertex
    vertex_of_fan = np.zeros(fan_count, dtype=np.int64)
    vertex_of_fan[fan] = tail
    return np.flatnonzero(np.bincount(vertex_of_fan, minlength=n) > 1)


def corner_fans(triangles: np.ndarray, n: int, runs, *, only: np.ndarray | None = None):
    """Fans of triangle corners: ``(count, label)``, corners linked across manifold edges.

    Corner ``p*m + t`` holds ``triangles[t, p]``. Two corners of one vertex are
    linked when their triangles share an edge through it that has exactly two
    triangles; a fan is a linked group (a path or a cycle of triangles around
    the vertex). With a boolean vertex mask ``only``, ``label`` has ``-1`` for
    the corners of other vertices and the graph is built on the selected
    corners alone (links never leave a vertex, so the fans are the same).
    """
    m = len(triangles)
    corners = 3 * m
    order, starts, counts = runs
    # corner p*m + t holds triangles[t, p]; half-edge row q*m + t runs from corner q*m + t
    # to corner ((q + 1) % 3)*m + t, so every corner starts one half-edge and ends one
    tail = triangles.T.reshape(-1)
    interior = starts[counts == 2]
    a, b = order[interior], order[interior + 1]
    del interior
    same_direction = tail[a] == tail[b]
    # (a + m) mod 3m, without passing 4m: int32 runs hold up to 3m < 2**31
    end_a, end_b = a - 2 * m, b - 2 * m
    end_a[end_a < 0] += corners
    end_b[end_b < 0] += corners
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
    selected = None
    if only is not None:
        selected = np.flatnonzero(only[tail])
        renumber = np.full(corners, -1, dtype=index)
        renumber[selected] = np.arange(len(selected), dtype=index)
        link = renumber[link[selected]]  # links stay among the corners of one vertex
        corners = len(selected)
    first = np.minimum(link[:, 0], link[:, 1])
    np.maximum(link[:, 0], link[:, 1], out=link[:, 1])
    link[:, 0] = first
    del first
    graph = sp.csr_matrix(
        (
            np.ones(2 * corners, dtype=np.int8),
            link.reshape(-1),
            np.arange(0, 2 * corners + 1, 2, dtype=index),
        ),
        shape=(corners, corners),
    )
    graph.has_sorted_indices = True  # each row's two links were just ordered
    # a corner without a link (or linked twice to one corner) repeats an entry: merged in one linear
    # pass, since SciPy < 1.15's strong components never return on repeated entries
    graph.sum_duplicates()
    # the links are symmetric, so strong components are the components, and finding them
    # reads the graph alone (weak or undirected ones transpose it first)
    fan_count, fan = csgraph.connected_components(graph, directed=True, connection="strong")
    fan = fan.astype(np.int64)
    if selected is None:
        return int(fan_count), fan
    label = np.full(3 * m, -1, dtype=np.int64)
    label[selected] = fan
    return int(fan_count), label


@dataclass(frozen=True)
class BoundaryCurves:
    """The boundary of a mesh cut into simple curves at its junction vertices.

    Attributes
    ----------
    loops : list of (l,) int64
        Closed simple loops through no junction: ``loop[-1]`` joins ``loop[0]``.
    chains : list of (k + 1,) int64
        Open chains of ``k >= 1`` boundary edges whose two ends (``chain[0]``
        and ``chain[-1]``, possibly the same vertex) are junctions and whose
        inner vertices are not.
    junctions : (j,) int64
        Sorted boundary vertices where the boundary is not a simple curve: on
        other than two boundary edges (a pinch, where two holes or two parts of
        one hole touch, or the end of a fin), or on an edge of more than two
        triangles.

    Every boundary edge lies on exactly one loop or chain; each curve follows
    the orientation of the majority of its edges' triangles and starts at its
    smallest vertex (loops) or at a junction (chains); curves are sorted by
    their first vertex.
    """

    loops: list
    chains: list
    junctions: np.ndarray

    def __len__(self) -> int:
        return len(self.loops) + len(self.chains)


def boundary_loops(triangles: np.ndarray, n: int, *, _runs=None) -> list[np.ndarray]:
    """Every closed boundary loop as an ordered ``(l,) int64`` array of vertex indices, on any mesh.

    A loop is a closed cycle of boundary half-edges (edges of exactly one
    triangle). At a vertex with one incoming and one outgoing boundary edge
    the loop goes straight on. At a pinch (several holes, or two parts of one
    hole, touching at a vertex) each incoming boundary edge continues with the
    outgoing one *of the same fan*: the one reached by walking around the
    vertex through the triangles that share its manifold edges, so a loop
    runs along the rim of one piece of surface and may visit a pinch vertex
    more than once. These are the boundary components of the surface with
    every non-manifold vertex split into its fans, so the Euler
    characteristic holds: ``bunny_scan.ply`` has 131 loops on 54 disk-like
    pieces (``2 * 54 - (chi + 51 split vertices) = 131``), while its 2,898
    boundary edges form 109 *connected* pieces of the boundary graph, loops
    touching at 22 of the 51 pinches counting once. A fan whose triangles
    disagree in orientation still pairs its two boundary edges; the loop then
    follows the majority of its edges' orientation. A boundary edge whose fan
    ends at an edge of more than two triangles (a fin) belongs to no closed
    loop; see :func:`boundary_curves` and :func:`boundary_chains`, which cover
    every boundary edge.

    A loop follows the orientation of its triangles and starts at its
    smallest vertex index (its first visit there); loops are sorted by that
    start. Vectorized: one sort pairs the boundary edges, connected
    components split the pairs into loops and pointer jumping orders them.

    Parameters
    ----------
    triangles : (m, 3) int64
    n : int
        Vertex count.

    Returns
    -------
    list of (l,) int64

    Examples
    --------
    >>> import numpy as np
    >>> bowtie = np.array([[0, 1, 2], [0, 3, 4]])  # two triangles touching at vertex 0
    >>> [loop.tolist() for loop in boundary_loops(bowtie, 5)]
    [[0, 1, 2], [0, 3, 4]]
    """
    closed, _ = _boundary_walk(np.asarray(triangles, dtype=np.int64), n, split_at_junctions=False, runs=_runs)
    return closed


def boundary_chains(triangles: np.ndarray, n: int) -> BoundaryCurves:
    """Cut the boundary into simple closed loops and open chains between junction vertices.

    The boundary graph (edges of exactly one triangle) is split at its
    junctions (vertices on other than two boundary edges, or on an edge of
    more than two triangles; see :class:`BoundaryCurves`). What remains are
    simple curves: closed loops that meet no junction and open chains whose
    ends are junctions. This is the input of the boundary-curve fairing
    (:mod:`o3d_lsmesh.fairing.boundary_curve`), which needs a simple curve
    around every moving vertex.

    Parameters
    ----------
    triangles : (m, 3) int64
    n : int

    Returns
    -------
    BoundaryCurves

    Examples
    --------
    >>> import numpy as np
    >>> bowtie = np.array([[0, 1, 2], [0, 3, 4]])
    >>> curves = boundary_chains(bowtie, 5)
    >>> [c.tolist() for c in curves.chains], curves.loops, curves.junctions.tolist()
    ([[0, 1, 2, 0], [0, 3, 4, 0]], [], [0])
    """
    triangles = np.asarray(triangles, dtype=np.int64)
    closed, open_ = _boundary_walk(triangles, n, split_at_junctions=True)
    return BoundaryCurves(closed, open_, _junctions(triangles, n)[0])


def boundary_curves(triangles: np.ndarray, n: int, *, edges: EdgeStructure | None = None) -> BoundaryCurves:
    """The boundary as the curves that the boundary-curve fairing walks, on any mesh.

    ``loops`` are the closed loops of :func:`boundary_loops` (which pass
    *through* pinch vertices, pairing boundary edges by fan), ``chains`` the
    open boundary paths that end where a fan stops at an edge of more than two
    triangles (fins), and ``junctions`` the boundary vertices on such edges.
    Every boundary edge lies on exactly one loop or chain. ``edges``: the
    mesh's :class:`EdgeStructure` when the caller has it (saves the edge sort).

    Examples
    --------
    >>> import numpy as np
    >>> fin = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])  # three triangles on edge (0, 1)
    >>> curves = boundary_curves(fin, 5)
    >>> curves.loops, [c.tolist() for c in curves.chains], curves.junctions.tolist()
    ([], [[0, 3, 1], [1, 2, 0], [1, 4, 0]], [0, 1])
    """
    triangles = np.asarray(triangles, dtype=np.int64)
    if len(triangles) == 0:
        return BoundaryCurves([], [], np.zeros(0, dtype=np.int64))
    runs = edge_runs(triangles, n) if edges is None else edges.runs
    closed, open_ = _boundary_walk(triangles, n, split_at_junctions=False, runs=runs)
    rows, tail, _, on_crowded = boundary_rows(triangles, n, runs)
    on_boundary = np.zeros(n, dtype=bool)
    on_boundary[tail[rows]] = True
    return BoundaryCurves(closed, open_, np.flatnonzero(on_boundary & on_crowded))


def boundary_rows(triangles: np.ndarray, n: int, runs):
    """Rows of :func:`halfedges` on edges of exactly one triangle (no self-edges), the half-edges'
    tails and heads, and the ``(n,) bool`` mask of the vertices on an edge of more than two triangles."""
    order, starts, counts = runs
    rows = order[starts[counts == 1]]
    tail = triangles.T.reshape(-1)
    head = triangles[:, [1, 2, 0]].T.reshape(-1)
    rows = np.sort(rows[tail[rows] != head[rows]])  # a repeated vertex is not an edge
    crowded = order[starts[counts > 2]]
    on_crowded = np.zeros(n, dtype=bool)
    on_crowded[tail[crowded]] = True
    on_crowded[head[crowded]] = True
    return rows, tail, head, on_crowded


def _junctions(triangles: np.ndarray, n: int, runs=None):
    if runs is None:
        runs = edge_runs(triangles, n)
    rows, tail, head, on_crowded = boundary_rows(triangles, n, runs)
    degree = np.bincount(tail[rows], minlength=n) + np.bincount(head[rows], minlength=n)
    special = (degree > 0) & ((degree != 2) | on_crowded)
    return np.flatnonzero(special), special, rows, tail, head, runs


def _boundary_walk(triangles: np.ndarray, n: int, *, split_at_junctions: bool, runs=None):
    """Closed and open boundary curves: ``(closed, open)``, each a sorted list of vertex arrays.

    Boundary edge ``i`` (half-edge row ``rows[i]``) has two ends: ``2i`` at its
    tail, ``2i + 1`` at its head. Ends are paired at every vertex: the two of a
    plain boundary vertex, and at a junction the two of each fan (or none when
    ``split_at_junctions``). A walk enters an edge at one end and leaves at
    the other: state ``2i`` runs edge ``i`` forward, ``2i + 1`` backward, and
    the next state is the partner of the end it leaves, ``partner[s ^ 1]``.
    Every curve is two chains of states (one per direction); the one with more
    forward states is kept.
    """
    empty: tuple[list, list] = ([], [])
    if len(triangles) == 0:
        return empty
    _, special, rows, tail, head, runs = _junctions(triangles, n, runs)
    b = len(rows)
    if b == 0:
        return empty
    m = len(triangles)
    end_vertex = np.empty(2 * b, dtype=np.int64)
    end_vertex[0::2], end_vertex[1::2] = tail[rows], head[rows]
    # pairing key of every end: its vertex at a plain vertex; at a junction its fan (or itself)
    key = end_vertex.copy()
    at_junction = special[end_vertex]
    if np.any(at_junction):
        ends = np.flatnonzero(at_junction)
        if split_at_junctions:
            key[ends] = n + np.arange(len(ends))  # unique: never paired
        else:
            _, fan = corner_fans(triangles, n, runs, only=special)
            corner = np.empty(2 * b, dtype=np.int64)
            corner[0::2] = rows  # a half-edge's row is the corner it starts from
            q, t = np.divmod(rows, m)
            corner[1::2] = ((q + 1) % 3) * m + t  # ... and it ends at the next corner of its triangle
            key[ends] = n + fan[corner[ends]]
    order = np.argsort(key, kind="stable")
    _, run_start, run_length = _runs(key[order])
    pairs = run_start[run_length == 2]  # a fan or a plain vertex holds at most two boundary ends
    partner = np.full(2 * b, -1, dtype=np.int64)
    partner[order[pairs]] = order[pairs + 1]
    partner[order[pairs + 1]] = order[pairs]
    state = np.arange(2 * b, dtype=np.int64)
    succ = partner[state ^ 1]
    has = succ >= 0
    graph = sp.csr_matrix((np.ones(int(has.sum())), (state[has], succ[has])), shape=(2 * b, 2 * b))
    count, label = csgraph.connected_components(graph, directed=True, connection="weak")
    # keep, of the two directions of every curve, the one with more forward edges (ties: the
    # direction holding its smallest edge forward)
    forward = np.bincount(label[0::2], minlength=count)
    smallest = np.full(count, 2 * b, dtype=np.int64)
    np.minimum.at(smallest, label, state)
    twin = np.empty(count, dtype=np.int64)
    twin[label] = label[state ^ 1]
    keep_curve = (forward > forward[twin]) | ((forward == forward[twin]) & (smallest < smallest[twin]))
    kept = keep_curve[label]
    entry = end_vertex[state]  # state 2i enters at the tail, 2i + 1 at the head
    exit_ = end_vertex[state ^ 1]
    pred = np.where(partner >= 0, partner ^ 1, -1)  # state whose leaving end is paired with my entry
    is_open = np.zeros(count, dtype=bool)
    is_open[label[kept & (pred < 0)]] = True
    # start: the first state of an open curve; the state entering at the smallest vertex of a closed one
    first = np.where(is_open[label], pred < 0, True) & kept
    candidates = np.flatnonzero(first)
    candidates = candidates[np.lexsort((candidates, entry[candidates], label[candidates]))]
    lead = np.ones(len(candidates), dtype=bool)
    lead[1:] = label[candidates[1:]] != label[candidates[:-1]]
    start_state = candidates[lead]  # one per kept curve, in label order
    # cut every closed curve before its start, then rank by pointer jumping on predecessors
    back = np.where(kept, pred, -1)
    back[start_state] = -1
    rank = np.where(back >= 0, 1, 0).astype(np.int64)
    jump = back.copy()
    active = np.flatnonzero(jump >= 0)
    while len(active):
        target = jump[active]
        rank[active] += rank[target]
        jump[active] = jump[target]
        active = active[jump[active] >= 0]
    states = np.flatnonzero(kept)
    curve_of = label[states]
    sequence = states[np.lexsort((rank[states], curve_of))]
    lengths = np.bincount(curve_of, minlength=count)[label[start_state]]
    pieces = np.split(entry[sequence], np.cumsum(lengths)[:-1])
    last = np.split(sequence, np.cumsum(lengths)[:-1])
    closed, open_ = [], []
    for curve, piece, states_of in zip(label[start_state].tolist(), pieces, last):
        if is_open[curve]:
            open_.append(np.append(piece, exit_[states_of[-1]]))
        else:
            closed.append(np.ascontiguousarray(piece))
    return _sorted_curves(closed), _sorted_curves(open_)


def _sorted_curves(curves: list) -> list:
    # by first vertex, then second (two curves from one pinch start at the same vertex, never on the same edge)
    return sorted(curves, key=lambda c: (int(c[0]), int(c[1])))

"""One connectivity object per mesh: edges, half-edges, rings, face adjacency, components, k-rings.

:class:`Connectivity` is built once per operation from ``triangles (m, 3)`` and ``n`` and passed
down; each part is computed on first use. The builders group by counting sorts (CSR transposes),
not ``np.unique``. Boundaries: :mod:`o3d_lsmesh.core.boundary`. Docs: ``docs/algorithms/connectivity.rst``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from .arrays import gather, kernel_index, run_heads
from .errors import InputError

__all__ = ["Connectivity", "EdgeStructure", "FaceAdjacency", "VertexRings", "halfedges", "ring_pattern"]


if TYPE_CHECKING:
    from functools import cached_property as _cached
else:

    class _cached:
        # functools.cached_property without its lock (one per class before Python 3.12): a race
        # computes the same value twice, harmless
        def __init__(self, function: Callable[[Any], Any]):
            self.function, self.name, self.__doc__ = function, function.__name__, function.__doc__

        def __get__(self, instance, owner=None):
            if instance is None:
                return self
            value = instance.__dict__[self.name] = self.function(instance)
            return value


class FaceAdjacency(NamedTuple):
    """Face neighbourhoods (:attr:`Connectivity.face_adjacency`)."""

    incidence: sp.csr_matrix  # (m, n) triangle-vertex incidence, three ones a row
    ring: sp.csr_matrix  # (m, m) faces sharing a vertex with each face (itself included), sorted, data 1
    pairs: np.ndarray  # (p, 2) int64 faces sharing an edge (k - 1 consecutive pairs on an edge of k)
    edges: np.ndarray  # (e, 2) the mesh's edges
    pair_edge: np.ndarray  # (p,) int64 the edge each pair shares


class Connectivity:
    """The connectivity of ``triangles (m, 3)`` on ``n`` vertices, each part computed once on first use.

    Numpy arrays (and SciPy matrices) only; pickles; safe to read from several threads (a race
    computes a part twice, with the same result). Index arrays are int32 when the mesh fits.

    Attributes
    ----------
    edge_structure : EdgeStructure
        Edges ``(e, 2)`` (``lo < hi``, sorted), ``edge_triangles (e,)`` and ``halfedge_edge (3m,)`` (the edge
        of each row of :func:`halfedges`); ``boundary_edges``: ``(e,) bool``.
    rings : VertexRings
        1-ring CSR with diagonal slots and the triangles behind every slot; ``valence (n,) int64``.
    ring_pattern, adjacency
        :func:`ring_pattern`'s ``(indptr, indices, diagonal, forward, backward)``; ``(n, n)`` binary CSR.
    rim : tuple
        ``(on_rim (n,) bool, edge_valence (n,) int64)``, read-only: on an edge of one triangle; edge
        neighbours (from the edges alone, without :attr:`rings`).
    vertex_triangles : tuple
        ``(indptr (n + 1,), triangle (3m,))``: vertex ``v``'s triangles, increasing, once per corner.
    face_adjacency : FaceAdjacency
    components : tuple
        ``(count, labels (n,) int64)`` over edges; an isolated vertex is its own component.

    Examples
    --------
    >>> c = Connectivity(np.array([[0, 1, 2], [0, 2, 3]]), 5)
    >>> c.edge_triangles.tolist(), c.valence.tolist(), c.components[0]
    ([1, 2, 1, 1, 1], [3, 2, 3, 2, 0], 2)
    """

    def __init__(self, triangles: np.ndarray, n: int | None = None):
        triangles = np.asarray(triangles)
        if triangles.ndim != 2 or triangles.shape[1] != 3:
            raise ValueError(f"triangles must have shape (m, 3), got {triangles.shape}")
        self.triangles = triangles.astype(np.int64, copy=False)
        self.n = int(n) if n is not None else (int(triangles.max()) + 1 if len(triangles) else 0)

    def __repr__(self) -> str:
        return f"Connectivity(m={len(self.triangles)}, n={self.n})"

    def release(self, part: str) -> None:
        """Free a computed part (an attribute name); it is computed again where it is used again."""
        self.__dict__.pop(part, None)

    @_cached
    def edge_structure(self) -> EdgeStructure:
        return _edge_structure(self.triangles, self.n)

    edges = property(lambda self: self.edge_structure.edges)
    edge_triangles = property(lambda self: self.edge_structure.counts)
    halfedge_edge = property(lambda self: self.edge_structure.inverse)
    boundary_edges = property(lambda self: self.edge_structure.counts == 1)
    valence = property(lambda self: self.rings.valence)

    @_cached
    def rings(self) -> VertexRings:
        return _vertex_rings(self.triangles, self.n, _RING_BLOCK)

    @_cached
    def ring_pattern(self) -> tuple:
        return ring_pattern(self.edges, self.n)

    @_cached
    def rim(self) -> tuple[np.ndarray, np.ndarray]:
        on_rim = np.zeros(self.n, dtype=bool)
        on_rim[self.edges[self.boundary_edges].ravel()] = True
        valence = np.bincount(self.edges.ravel(), minlength=self.n).astype(np.int64, copy=False)
        on_rim.setflags(write=False)  # shared by every step of a call
        valence.setflags(write=False)
        return on_rim, valence

    @_cached
    def adjacency(self) -> sp.csr_matrix:
        # the 1-ring pattern without its diagonal (every row has one): no second grouping of the edges
        n = self.n
        if n >= 2**31:  # refused before any n-sized array
            raise InputError(f"mesh must have fewer than 2**31 vertices, got {n}", param="mesh")
        indptr, indices, diagonal = self.ring_pattern[:3]
        keep = np.ones(len(indices), dtype=bool)
        keep[diagonal] = False
        adjacency = sp.csr_matrix(
            (np.ones(len(indices) - n), indices[keep], indptr - np.arange(n + 1, dtype=indptr.dtype)),
            shape=(n, n),
        )
        if (self.edges[:, 0] == self.edges[:, 1]).any():  # a triangle repeating a vertex: its self-loop once
            adjacency.sum_duplicates()
            adjacency.data.fill(1.0)
        adjacency.has_canonical_format = True  # sorted, no duplicates
        return adjacency

    @_cached
    def vertex_triangles(self) -> tuple[np.ndarray, np.ndarray]:
        m = len(self.triangles)
        incidence = sp.csr_matrix(
            (np.ones(3 * m, dtype=np.int8), self.triangles.reshape(-1), np.arange(0, 3 * m + 1, 3)),
            shape=(m, self.n),
        ).tocsc()  # a stable counting sort of the corners by vertex
        return incidence.indptr, incidence.indices

    @_cached
    def face_adjacency(self) -> FaceAdjacency:
        from .._block_kernel import gram  # compiled by the package's build

        triangles, n, m = self.triangles, self.n, len(self.triangles)
        incidence = sp.csr_matrix(
            (np.ones(3 * m), triangles.ravel(), np.arange(0, 3 * m + 1, 3)), shape=(m, n)
        )
        # incidence incidence^T in one compiled pass, rows sorted (its columns: vertex_triangles' grouping)
        by_vertex, index = incidence.tocsc(), np.result_type(incidence.indptr, incidence.indices)
        parts = [part.astype(index, copy=False) for part in (incidence.indptr, incidence.indices)]
        parts += [by_vertex.indptr.astype(index, copy=False), by_vertex.indices.astype(index, copy=False)]
        indptr, indices, data = gram(parts[0], parts[1], incidence.data, parts[2], parts[3], by_vertex.data)
        data[:] = 1.0
        ring = sp.csr_matrix((data, indices, indptr), shape=(m, m))
        ring.has_canonical_format = True  # sorted, no duplicates
        # edge-adjacent faces: consecutive half-edges of one edge group (half-edge a * m + t is in triangle t)
        es = self.edge_structure
        follows = np.ones(len(es.order), dtype=bool)
        follows[es.starts] = False  # every half-edge but its edge's first
        follows = np.flatnonzero(follows)
        first, second = es.order[follows - 1].astype(np.int64), es.order[follows].astype(np.int64)
        pairs = np.stack([first % m, second % m], axis=1)
        pair_edge = np.repeat(np.arange(len(es.counts)), es.counts - 1)
        return FaceAdjacency(incidence, ring, pairs, es.edges, pair_edge)

    @_cached
    def components(self) -> tuple[int, np.ndarray]:
        count, labels = csgraph.connected_components(self.adjacency, directed=False)
        return int(count), labels.astype(np.int64)

    def k_rings(self, seeds: np.ndarray, k: int) -> np.ndarray:
        """Sorted vertices within ``k`` edges of any of ``seeds`` (the seeds included), ``(q,) int64``.
        >>> Connectivity(np.array([[0, 1, 2], [2, 3, 4]])).k_rings([0], 1).tolist()
        [0, 1, 2]
        """
        inside = np.zeros(self.n, dtype=bool)
        inside[np.asarray(seeds, dtype=np.int64)] = True
        adjacency = self.adjacency
        for _ in range(int(k)):
            grown = inside | (adjacency @ inside.astype(np.int8) > 0)
            if np.array_equal(grown, inside):
                break
            inside = grown
        return np.flatnonzero(inside)

    def submesh(self, triangle_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``triangles[triangle_ids]`` renumbered: ``(local (s, 3), vertices (q,))`` int64, ``vertices[local]`` equal to it.

        >>> local, vertices = Connectivity(np.array([[0, 1, 2], [2, 3, 4]])).submesh([1])
        >>> local.tolist(), vertices.tolist()
        ([[0, 1, 2]], [2, 3, 4])
        """
        part = self.triangles[np.asarray(triangle_ids, dtype=np.int64)]
        used = np.zeros(self.n, dtype=bool)
        used[part.reshape(-1)] = True
        vertices = np.flatnonzero(used)
        renumber = np.cumsum(used, dtype=np.int64) - 1
        return renumber[part], vertices


def halfedges(triangles: np.ndarray) -> np.ndarray:
    """Directed edges ``(3m, 2)`` in triangle order: rows ``t``, ``m + t``, ``2m + t`` are
    ``(a, b)``, ``(b, c)``, ``(c, a)`` of triangle ``t = (a, b, c)``."""
    return np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]], axis=0)


@dataclass(frozen=True)
class EdgeStructure:
    """The undirected edges of a mesh and the grouping of its half-edges (:attr:`Connectivity.edge_structure`).

    Index arrays int32 (int64 beyond ``2**31`` half-edges); ``inverse`` formed on first use.
    """

    edges: np.ndarray  # (e, 2) lo < hi, sorted lexicographically
    counts: np.ndarray  # (e,) triangles sharing each edge
    order: np.ndarray  # (3m,) half-edge rows by edge: edge k's are order[starts[k]:starts[k] + counts[k]]
    starts: np.ndarray  # (e,)
    _inverse: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def inverse(self) -> np.ndarray:
        """Edge of each half-edge row of :func:`halfedges`, ``(3m,)``."""
        if self._inverse is None:
            inverse = np.empty(len(self.order), dtype=self.order.dtype)
            inverse[self.order] = np.repeat(np.arange(len(self.edges), dtype=self.order.dtype), self.counts)
            object.__setattr__(self, "_inverse", inverse)
        return self._inverse  # type: ignore[return-value]

    @property
    def runs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(order, starts, counts)``: the half-edge grouping that boundary walks take."""
        return self.order, self.starts, self.counts


def _edge_structure(triangles: np.ndarray, n: int) -> EdgeStructure:
    # a stable sort of the half-edges by lo * n + hi made of two counting sorts, by hi then lo
    m = len(triangles)
    count = 3 * m
    index = np.int32 if max(count, n) < np.iinfo(np.int32).max else np.int64
    if count == 0:
        empty = np.zeros(0, dtype=index)
        return EdgeStructure(np.zeros((0, 2), dtype=index), empty, empty, empty, _inverse=empty)
    # mesh-sized, on small pages (constrained_fairing.rst); compiled by the package's build: imported here
    from .._block_kernel import empty_small_pages as fresh
    from .._scan_kernel import edge_groups

    lo, hi = fresh(count, index), fresh(count, index)  # rows of halfedges() order, written in place
    for a in range(3):
        tail, head, part = triangles[:, a], triangles[:, (a + 1) % 3], slice(a * m, (a + 1) * m)
        np.minimum(tail, head, out=lo[part], casting="unsafe")
        np.maximum(tail, head, out=hi[part], casting="unsafe")
    # two counting sorts (by hi, then that order stably by lo) and the runs of one edge, compiled
    order, starts, counts, edges = edge_groups(lo, hi, n)
    del lo, hi
    return EdgeStructure(edges, counts, order, starts)


#: Corners (row, column) of the six entries ``d * m + t`` of a triangle in :attr:`Connectivity.rings`:
#: entries 0-2 are the half-edges of :func:`halfedges`, 3-5 the same edges reversed.
RING_ROW_SLOT = (0, 1, 2, 1, 2, 0)
RING_COLUMN_SLOT = (1, 2, 0, 0, 1, 2)

#: Vertices per block of the rings' builder: temporaries of a few megabytes, reused by the allocator.
_RING_BLOCK = 1 << 14


@dataclass(frozen=True)
class VertexRings:
    """The 1-ring CSR pattern with the triangles behind every slot (:attr:`Connectivity.rings`).

    Triangle ``t`` gives six entries: entry ``d * m + t`` sits in row ``triangles[t, RING_ROW_SLOT[d]]``
    and column ``triangles[t, RING_COLUMN_SLOT[d]]``. Index arrays int32 (int64 beyond ``2**31``).
    """

    indptr: np.ndarray  # (n + 1,)
    indices: np.ndarray  # (n + 2e,) diagonal plus both directions of every edge, canonical
    diagonal: np.ndarray  # (n,) int64 position of each row's diagonal
    pairs: np.ndarray  # (2, n + 2e) two entries of each slot (one triangle: twice); 6 m on the diagonal
    valence: np.ndarray  # (n,) int64
    boundary: np.ndarray  # (n,) bool: on an edge of one triangle or of more than two

    @property
    def n(self) -> int:
        return len(self.indptr) - 1


def _vertex_rings(triangles: np.ndarray, n: int, block: int) -> VertexRings:
    # one pass over the corners grouped by vertex, block vertices at a time; equal columns of a row
    # are the triangles of one edge
    m = len(triangles)
    corners = 3 * m
    bound = 6 * m + n
    index = np.int32 if bound + 1 < np.iinfo(np.int32).max else np.int64
    flat = np.ascontiguousarray(triangles, dtype=index).reshape(-1)  # corner (t, a) at 3 t + a
    # corners grouped by vertex, stably: a counting sort, the transpose of the (m, n) CSR whose row
    # t holds triangle t's corners (data: the corner's place a in its triangle)
    by_corner = sp.csr_matrix(
        (np.tile(np.arange(3, dtype=np.int8), m), flat, np.arange(0, corners + 1, 3, dtype=index)),
        shape=(m, n),
    ).tocsc()
    start, by_vertex, place = by_corner.indptr, by_corner.indices, by_corner.data  # triangle, place in it
    del by_corner
    indices = np.empty(bound, dtype=index)  # only the used prefix (n + 2e) is ever touched
    pairs = np.empty((2, bound), dtype=index)
    diagonal = np.empty(n, dtype=np.int64)
    valence = np.zeros(n, dtype=np.int64)
    boundary = np.zeros(n, dtype=bool)
    offset = 0
    for v0 in range(0, n, block):
        v1 = min(n, v0 + block)
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
        part = sp.csr_matrix((entries, columns, local), shape=(rows, n))
        part.sort_indices()  # each row's columns in order (about 12 a row)
        columns, entries = part.indices, part.data
        del part
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


def ring_pattern(edges: np.ndarray, n: int):
    """The 1-ring CSR of sorted ``edges (e, 2)`` (``lo < hi``): ``indptr (n+1,)``, ``indices`` and the positions
    of the diagonal ``(n,)`` and of each edge forward (row ``lo``) and backward (row ``hi``), int32 if they fit.

    >>> ring_pattern(np.array([[0, 1], [0, 2], [1, 2]]), 3)[3:]  # forward, backward
    (array([1, 2, 5], dtype=int32), array([3, 6, 7], dtype=int32))
    """
    from .._scan_kernel import ring_slots  # compiled by the package's build: imported where used

    e = len(edges)
    index = np.int32 if 2 * e + n < np.iinfo(np.int32).max else np.int64
    indptr, indices = np.empty(n + 1, dtype=index), np.empty(n + 2 * e, dtype=index)
    diagonal, forward, backward = np.empty(n, dtype=index), np.empty(e, dtype=index), np.empty(e, dtype=index)
    ring_slots(kernel_index(edges, 2), indptr, indices, diagonal, forward, backward)
    return indptr, indices, diagonal, forward, backward

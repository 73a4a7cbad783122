# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""The connectivity's grouping of a mesh's half-edges into edges, compiled (the scan default's first step).

Serial: a counting sort's scatter runs in order, and each pass is a few milliseconds at 1M vertices.
Every function checks the shapes and values it indexes with and raises a ``ValueError`` naming the array.
"""

import numpy as np

from libc.stdint cimport int32_t, int64_t

from ._block_kernel import empty_small_pages  # mesh-sized outputs (constrained_fairing.rst)

ctypedef fused index_t:
    int32_t
    int64_t


def edge_groups(const index_t[::1] lo, const index_t[::1] hi, Py_ssize_t n):
    """Half-edge ``i`` runs from ``lo[i]`` to ``hi[i]``: the half-edges sorted stably by ``(lo, hi)`` and
    their runs of one edge, ``(order (k,), starts (e,), counts (e,), edges (e, 2))`` of ``lo``'s type.

    Two counting sorts, by ``hi``, then stably by ``lo``: the order of two CSR-to-CSC transposes of the
    ``(k, n)`` matrices whose row ``i`` holds column ``hi[i]``, then ``lo[i]`` (SciPy's, which
    :class:`~o3d_lsmesh.core.connectivity.Connectivity` used before); then one pass for the runs.
    """
    cdef Py_ssize_t k = lo.shape[0], i, s, e = 0
    if hi.shape[0] != k:
        raise ValueError(f"hi must have as many entries as lo ({k}), got {hi.shape[0]}")
    if n < 0:
        raise ValueError(f"n must be at least 0, got {n}")
    for i in range(k):
        if not (0 <= lo[i] < n and 0 <= hi[i] < n):
            raise ValueError(f"lo and hi must lie in 0..{n - 1}, got ({lo[i]}, {hi[i]}) at {i}")
    dtype = np.int32 if index_t is int32_t else np.int64
    start_array, slot_array = np.zeros(n + 1, dtype), np.empty(n + 1, dtype)
    by_hi_array, order_array = empty_small_pages(k, dtype), empty_small_pages(k, dtype)
    cdef index_t[::1] start = start_array, slot = slot_array, by_hi = by_hi_array, order = order_array
    with nogil:
        for i in range(k):
            start[hi[i] + 1] += 1
        for i in range(n):
            start[i + 1] += start[i]
        slot[:] = start
        for i in range(k):
            by_hi[slot[hi[i]]] = i
            slot[hi[i]] += 1
        start[:] = 0
        for i in range(k):
            start[lo[i] + 1] += 1
        for i in range(n):
            start[i + 1] += start[i]
        slot[:] = start
        for s in range(k):
            i = by_hi[s]
            order[slot[lo[i]]] = i
            slot[lo[i]] += 1
        # a new edge wherever (lo, hi) changes along the order
        for s in range(k):
            if s == 0 or lo[order[s]] != lo[order[s - 1]] or hi[order[s]] != hi[order[s - 1]]:
                e += 1
    del by_hi_array, start_array, slot_array
    starts_array, counts_array = empty_small_pages(e, dtype), empty_small_pages(e, dtype)
    edges_array = np.empty((e, 2), dtype)
    cdef index_t[::1] starts = starts_array, counts = counts_array
    cdef index_t[:, ::1] edges = edges_array
    e = 0
    with nogil:
        for s in range(k):
            i = order[s]
            if s == 0 or lo[i] != lo[order[s - 1]] or hi[i] != hi[order[s - 1]]:
                starts[e], edges[e, 0], edges[e, 1] = s, lo[i], hi[i]
                e += 1
        for s in range(e):
            counts[s] = (starts[s + 1] if s + 1 < e else k) - starts[s]
    return order_array, starts_array, counts_array, edges_array


ctypedef fused slot_t:
    int32_t
    int64_t


def ring_slots(const index_t[:, ::1] edges, slot_t[::1] indptr, slot_t[::1] indices, slot_t[::1] diagonal,
               slot_t[::1] forward, slot_t[::1] backward):
    """The 1-ring CSR of ``edges (e, 2)`` sorted by ``(lo, hi)`` on ``n = len(indptr) - 1`` vertices, written
    into ``indptr (n + 1,)``, ``indices (n + 2e,)`` and the slots of the diagonal ``(n,)``, of each edge
    forward (row ``lo``) and backward (row ``hi``), ``(e,)`` each: a row's backward edges (by ``lo``), its
    diagonal, its forward edges (by ``hi``), in one pass over the edges per part.
    """
    cdef Py_ssize_t n = indptr.shape[0] - 1, e = edges.shape[0], i, t
    cdef index_t lo, hi
    if edges.shape[1] != 2:
        raise ValueError(f"edges must have 2 columns, got {edges.shape[1]}")
    if diagonal.shape[0] != n or indices.shape[0] != n + 2 * e:
        raise ValueError(f"diagonal and indices must have {n} and {n + 2 * e} entries, got {diagonal.shape[0]} "
                         f"and {indices.shape[0]}")
    if forward.shape[0] != e or backward.shape[0] != e:
        raise ValueError(f"forward and backward must have {e} entries, got {forward.shape[0]} and {backward.shape[0]}")
    for t in range(e):
        if not (0 <= edges[t, 0] < n and 0 <= edges[t, 1] < n):
            raise ValueError(f"edges must name vertices in 0..{n - 1}, got ({edges[t, 0]}, {edges[t, 1]}) at {t}")
    cursor_array = np.empty(n, np.int32 if slot_t is int32_t else np.int64)
    cdef slot_t[::1] cursor = cursor_array
    with nogil:
        indptr[:] = 0
        diagonal[:] = 0
        for t in range(e):
            indptr[edges[t, 0] + 1] += 1
            indptr[edges[t, 1] + 1] += 1
            diagonal[edges[t, 1]] += 1  # the backward edges before the diagonal
        for i in range(n):
            indptr[i + 1] += indptr[i] + 1
            diagonal[i] += indptr[i]
            indices[diagonal[i]] = i
            cursor[i] = indptr[i]
        for t in range(e):  # sorted by lo: each row's backward edges arrive by increasing lo
            lo, hi = edges[t, 0], edges[t, 1]
            backward[t] = cursor[hi]
            indices[cursor[hi]] = lo
            cursor[hi] += 1
        for i in range(n):
            cursor[i] = diagonal[i] + 1
        for t in range(e):  # and each row's forward edges by increasing hi
            lo, hi = edges[t, 0], edges[t, 1]
            forward[t] = cursor[lo]
            indices[cursor[lo]] = hi
            cursor[lo] += 1

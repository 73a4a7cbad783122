# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""The feature mode's loops over each face's ring of faces and Sun's vertex steps.

Each loop reads a face's ring (a CSR pattern, about 13 entries per face) once and keeps what it needs of
an entry in registers: no array with one value per stored entry is formed (fresh memory costs page
faults). Rows run on every core (OpenMP; ``OMP_NUM_THREADS`` sets how many), each row's sums in stored
order, so the results never depend on the thread count.
"""

import numpy as np

from cython.parallel cimport prange, threadid
from libc.math cimport exp, sqrt
from libc.stdint cimport int64_t

from o3d_lsmesh._parallel cimport _threads, index_t


cdef Py_ssize_t _rows(const index_t[::1] indptr, Py_ssize_t entries) except -1:
    """The rows ``m`` of a CSR pattern whose ``indptr`` ends at its ``entries`` (a ValueError otherwise)."""
    if indptr.shape[0] < 1:
        raise ValueError("indptr must have at least 1 entry, got 0")
    cdef Py_ssize_t m = indptr.shape[0] - 1
    if indptr[0] != 0 or indptr[m] != entries:
        raise ValueError(f"indptr must run from 0 to the pattern's {entries} entries, got {indptr[0]} to {indptr[m]}")
    return m


cdef int _check_rows(str name, const double[:, ::1] a, Py_ssize_t rows) except -1:
    """A ValueError naming ``name`` unless ``a`` is ``(rows, 3)``."""
    if a.shape[0] != rows or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape ({rows}, 3), got ({a.shape[0]}, {a.shape[1]})")
    return 0


cdef inline double _distance2(const double[:, ::1] c, Py_ssize_t i, Py_ssize_t j) noexcept nogil:
    """``|c_i - c_j|^2``, the three coordinates summed left to right (differences, not ``|a|^2 + |b|^2 -
    2 a.b``: far from the origin that cancels)."""
    cdef double d = c[i, 0] - c[j, 0]
    cdef double s = d * d
    d = c[i, 1] - c[j, 1]
    s = s + d * d
    d = c[i, 2] - c[j, 2]
    return s + d * d


cdef inline double _dot(const double[:, ::1] a, Py_ssize_t i, const double[:, ::1] b,
                        Py_ssize_t j) noexcept nogil:
    return a[i, 0] * b[j, 0] + a[i, 1] * b[j, 1] + a[i, 2] * b[j, 2]


def ring_spacing(const index_t[::1] indptr, const index_t[::1] indices, const double[:, ::1] centroid):
    """The sum over the stored entries ``(i, j)`` of an ``(m, m)`` CSR pattern of ``|c_i - c_j|``:
    ``centroid`` ``(m, 3)``; each row's distances summed in stored order into an ``(m,)`` array, then
    that array's NumPy sum (the same value whatever the thread count)."""
    cdef Py_ssize_t m = _rows(indptr, indices.shape[0]), i
    cdef index_t k
    cdef double s
    _check_rows("centroid", centroid, m)
    partial_array = np.empty(m)
    cdef double[::1] partial = partial_array
    with nogil:
        for i in prange(m, schedule="static", num_threads=_threads(m)):
            s = 0.0
            for k in range(indptr[i], indptr[i + 1]):
                s = s + sqrt(_distance2(centroid, i, indices[k]))
            partial[i] = s
    return float(partial_array.sum())


def filtered_normals(const index_t[::1] indptr, const index_t[::1] indices, const double[:, ::1] centroid,
                     const double[:, ::1] guide, const double[::1] area, const double[:, ::1] normals,
                     double range_divisor, double space_divisor, double[:, ::1] out):
    """The bilateral (or guided) filter's weighted sums, ``out`` ``(m, 3)``: for each row ``i`` of an
    ``(m, m)`` CSR pattern, over its stored entries ``(i, j)`` in order,
    ``sum_j exp((g_i . g_j - 1) / range_divisor - |c_i - c_j|^2 / space_divisor) a_j n_j``.

    ``centroid``, ``guide`` (``g``) and ``normals`` (``n``) ``(m, 3)``, ``area`` (``a``) ``(m,)``. The
    operations in the order of the former entry-sized NumPy arrays: the dot product and the squared
    distance summed left to right, then ``- 1``, the divisions, the difference, ``exp``, times ``a_j``,
    times ``n_j``.
    """
    cdef Py_ssize_t m = _rows(indptr, indices.shape[0]), i
    cdef index_t k, j
    cdef double w, s0, s1, s2
    _check_rows("centroid", centroid, m)
    _check_rows("guide", guide, m)
    _check_rows("normals", normals, m)
    _check_rows("out", out, m)
    if area.shape[0] != m:
        raise ValueError(f"area must have shape ({m},), got ({area.shape[0]},)")
    with nogil:
        for i in prange(m, schedule="static", num_threads=_threads(m)):
            s0, s1, s2 = 0.0, 0.0, 0.0
            for k in range(indptr[i], indptr[i + 1]):
                j = indices[k]
                w = (_dot(guide, i, guide, j) - 1.0) / range_divisor
                w = exp(w - _distance2(centroid, i, j) / space_divisor) * area[j]
                s0 = s0 + w * normals[j, 0]
                s1 = s1 + w * normals[j, 1]
                s2 = s2 + w * normals[j, 2]
            out[i, 0], out[i, 1], out[i, 2] = s0, s1, s2


def least_dot(const index_t[::1] indptr, const index_t[::1] indices, const double[:, ::1] a,
              const double[:, ::1] b):
    """Per row ``i`` of an ``(m, m)`` CSR pattern, ``(m,)``: the least ``a_i . b_j`` over its stored
    entries ``(i, j)`` (three columns summed left to right; a NaN stays, as ``np.minimum``'s), 0 on an
    empty row; ``a`` and ``b`` ``(m, 3)``."""
    cdef Py_ssize_t m = _rows(indptr, indices.shape[0]), i
    cdef index_t k
    cdef double least, v
    _check_rows("a", a, m)
    _check_rows("b", b, m)
    out_array = np.empty(m)
    cdef double[::1] out = out_array
    with nogil:
        for i in prange(m, schedule="static", num_threads=_threads(m)):
            least = _dot(a, i, b, indices[indptr[i]]) if indptr[i] < indptr[i + 1] else 0.0
            for k in range(indptr[i] + 1, indptr[i + 1]):
                v = _dot(a, i, b, indices[k])
                if v != v:  # predicted never taken: the minimum itself stays a branchless select
                    least = v
                    break
                least = v if v < least else least
            out[i] = least
    return out_array


def ring_least(const index_t[::1] indptr, const index_t[::1] indices, const double[::1] values):
    """Per row of a CSR pattern, ``(m,)``: the first column ``j`` (in stored order) of least ``values[j]``
    (``-1`` on an empty row)."""
    cdef Py_ssize_t m = indptr.shape[0] - 1, i
    cdef index_t k, j, first
    if indptr[m] != indices.shape[0]:
        raise ValueError(f"indptr ends at {indptr[m]}, the pattern has {indices.shape[0]} entries")
    out_array = np.empty(m, dtype=np.intp)
    cdef Py_ssize_t[::1] least = out_array
    with nogil:
        for i in prange(m, schedule="static", num_threads=_threads(m)):
            first = -1
            for k in range(indptr[i], indptr[i + 1]):
                j = indices[k]
                if first < 0 or values[j] < values[first]:
                    first = j
            least[i] = first
    return out_array


def plane_steps(const index_t[::1] corners, const index_t[::1] indptr, const index_t[::1] faces,
                const double[:, ::1] normals, double[:, ::1] x, Py_ssize_t iterations):
    """Sun et al.'s vertex update in place, ``iterations`` steps of ``x_v += 1/|F_v| sum_(f in F_v) n_f
    (n_f . (c_f - x_v))``: ``corners`` the faces' vertices ``(3m,)``, ``(indptr, faces)`` each vertex's
    faces in increasing order (once per corner: the incidence's CSC). Each step reads the planes
    ``n_f . c_f`` of the previous positions (one pass over the faces, then one over the vertices)."""
    cdef Py_ssize_t m = normals.shape[0], n = x.shape[0], f, v, step, c, e
    cdef index_t k
    cdef double d, s0, s1, s2
    if corners.shape[0] != 3 * m or indptr.shape[0] != n + 1 or indptr[n] != faces.shape[0]:
        raise ValueError(f"corners must have {3 * m} entries and indptr {n + 1}, ending at len(faces)")
    if normals.shape[1] != 3 or x.shape[1] != 3:
        raise ValueError(f"normals and x must have 3 columns, got {normals.shape[1]} and {x.shape[1]}")
    plane_array, outer_array = np.empty(m), np.zeros((n, 9))
    cdef double[::1] plane = plane_array
    cdef double[:, ::1] outer = outer_array
    with nogil:
        for v in prange(n, schedule="static", num_threads=_threads(n)):
            for k in range(indptr[v], indptr[v + 1]):
                for e in range(9):
                    outer[v, e] += normals[faces[k], e // 3] * normals[faces[k], e % 3]
        for step in range(iterations):
            for f in prange(m, schedule="static", num_threads=_threads(m)):
                d = 0.0
                for c in range(3):
                    d = d + normals[f, c] * (x[corners[3 * f], c] + x[corners[3 * f + 1], c] + x[corners[3 * f + 2], c])
                plane[f] = d / 3.0
            for v in prange(n, schedule="static", num_threads=_threads(n)):
                s0, s1, s2 = 0.0, 0.0, 0.0
                for k in range(indptr[v], indptr[v + 1]):
                    s0 = s0 + normals[faces[k], 0] * plane[faces[k]]
                    s1 = s1 + normals[faces[k], 1] * plane[faces[k]]
                    s2 = s2 + normals[faces[k], 2] * plane[faces[k]]
                d = max(indptr[v + 1] - indptr[v], 1)
                s0 = (s0 - (outer[v, 0] * x[v, 0] + outer[v, 1] * x[v, 1] + outer[v, 2] * x[v, 2])) / d
                s1 = (s1 - (outer[v, 3] * x[v, 0] + outer[v, 4] * x[v, 1] + outer[v, 5] * x[v, 2])) / d
                s2 = (s2 - (outer[v, 6] * x[v, 0] + outer[v, 7] * x[v, 1] + outer[v, 8] * x[v, 2])) / d
                x[v, 0], x[v, 1], x[v, 2] = x[v, 0] + s0, x[v, 1] + s1, x[v, 2] + s2


def pair_jumps(const int64_t[:, ::1] pairs, const double[:, ::1] normals):
    """``|n_a - n_b|`` of each pair ``(a, b)`` of ``pairs`` ``(p, 2)``, ``(p,)``; ``normals`` ``(m, 3)``.
    The operations of ``np.linalg.norm(normals[a] - normals[b], axis=1)``: ``sqrt((x*x + y*y) + z*z)``."""
    cdef Py_ssize_t p = pairs.shape[0], m = normals.shape[0], k
    cdef int64_t a, b
    cdef double d0, d1, d2
    if pairs.shape[1] != 2:
        raise ValueError(f"pairs must have shape (p, 2), got ({p}, {pairs.shape[1]})")
    if normals.shape[1] != 3:
        raise ValueError(f"normals must have shape (m, 3), got ({m}, {normals.shape[1]})")
    for k in range(p):
        if not (0 <= pairs[k, 0] < m and 0 <= pairs[k, 1] < m):
            raise ValueError(f"pairs must name rows of normals in 0..{m - 1}, got pair {k}: {pairs[k, 0]}, {pairs[k, 1]}")
    out_array = np.empty(p)
    cdef double[::1] out = out_array
    with nogil:
        for k in prange(p, schedule="static", num_threads=_threads(p)):
            a, b = pairs[k, 0], pairs[k, 1]
            d0, d1, d2 = normals[a, 0] - normals[b, 0], normals[a, 1] - normals[b, 1], normals[a, 2] - normals[b, 2]
            out[k] = sqrt((d0 * d0 + d1 * d1) + d2 * d2)
    return out_array



def patch_pairs(const index_t[::1] indptr, const index_t[::1] indices, const index_t[::1] first_indptr,
                const index_t[::1] first_pairs, const int64_t[::1] second):
    """The edge-adjacent pairs with both faces in each face's ring (its patch), CSR ``(indptr (m + 1,),
    pairs)`` in the ring's index type: for face ``i``, each ring face ``j`` in stored order, then ``j``'s
    pairs as their first face (``(first_indptr, first_pairs)``, so each pair once) whose other face
    ``second[p]`` is in the ring (its mark is ``i``; each thread marks the faces of the ring it reads).
    Two passes (count, fill); no sparse product (at 1.4M vertices ``ring @ ends`` took seconds and
    gigabytes)."""
    cdef Py_ssize_t m = _rows(indptr, indices.shape[0]), p = second.shape[0], i, q, t, threads = _threads(m)
    cdef index_t k, j, at
    if _rows(first_indptr, first_pairs.shape[0]) != m:
        raise ValueError(f"first_indptr must have {m + 1} entries (the ring's rows + 1), got {first_indptr.shape[0]}")
    for q in range(first_pairs.shape[0]):
        if not 0 <= first_pairs[q] < p:
            raise ValueError(f"first_pairs must name pairs of second in 0..{p - 1}, got {first_pairs[q]} at {q}")
    for q in range(p):
        if not 0 <= second[q] < m:
            raise ValueError(f"second must name faces in 0..{m - 1}, got {second[q]} at {q}")
    dtype = np.asarray(indptr).dtype
    counts_array = np.zeros(m + 1, dtype=dtype)
    marks_array = np.full((threads, m), -1, dtype=np.intp)
    cdef index_t[::1] counts = counts_array
    cdef Py_ssize_t[:, ::1] marks = marks_array
    with nogil:
        for i in prange(m, schedule="static", num_threads=threads):
            t = threadid()
            for k in range(indptr[i], indptr[i + 1]):
                marks[t, indices[k]] = i
            for k in range(indptr[i], indptr[i + 1]):
                j = indices[k]
                for q in range(first_indptr[j], first_indptr[j + 1]):
                    if marks[t, second[first_pairs[q]]] == i:
                        counts[i + 1] += 1
    np.cumsum(counts_array, out=counts_array)
    pairs_array = np.empty(counts_array[m], dtype=dtype)
    cdef index_t[::1] out = pairs_array
    marks_array.fill(-1)
    with nogil:
        for i in prange(m, schedule="static", num_threads=threads):
            t = threadid()
            for k in range(indptr[i], indptr[i + 1]):
                marks[t, indices[k]] = i
            at = counts[i]
            for k in range(indptr[i], indptr[i + 1]):
                j = indices[k]
                for q in range(first_indptr[j], first_indptr[j + 1]):
                    if marks[t, second[first_pairs[q]]] == i:
                        out[at] = first_pairs[q]
                        at = at + 1
    return counts_array, pairs_array


def patch_saliency(const index_t[::1] indptr, const index_t[::1] pairs, const double[::1] jump):
    """Zhang et al.'s patch saliency per face, ``(m,)``: ``max_p jump[p] / (1e-9 + sum_p jump[p])`` over
    its patch's pairs (:func:`patch_pairs`' CSR, summed in stored order; 0 on a patch without a pair)."""
    cdef Py_ssize_t m = _rows(indptr, pairs.shape[0]), i
    cdef index_t k
    cdef double most, total
    for k in range(pairs.shape[0]):
        if not 0 <= pairs[k] < jump.shape[0]:
            raise ValueError(f"pairs must name entries of jump in 0..{jump.shape[0] - 1}, got {pairs[k]} at {k}")
    out_array = np.empty(m)
    cdef double[::1] out = out_array
    with nogil:
        for i in prange(m, schedule="static", num_threads=_threads(m)):
            most, total = 0.0, 0.0
            for k in range(indptr[i], indptr[i + 1]):
                most = max(most, jump[pairs[k]])
                total = total + jump[pairs[k]]
            out[i] = most / (1e-9 + total)
    return out_array

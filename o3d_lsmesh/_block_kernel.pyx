# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Sparse products and Gauss-Seidel sweeps on ``(n, k)`` blocks: the iterative solver's inner loops.

SciPy's block product and pyamg's Gauss-Seidel stream the matrix once per column; these stream it
once for all ``k`` columns (row-major blocks: a row's ``k`` values share a cache line), on every core
(OpenMP; ``OMP_NUM_THREADS`` sets how many), with results that never depend on the thread count.
:func:`empty_small_pages` is the package's one OS memory advice (for large work arrays).
"""

import numpy as np

from cython.parallel cimport prange
from libc.math cimport fabs, sqrt
from libc.stdint cimport int32_t, int64_t

from o3d_lsmesh._parallel cimport PARALLEL_ROWS, _threads, index_t

cdef extern from *:
    # the OS's public madvise where it has transparent huge pages (Linux; NumPy advises them there only),
    # nothing elsewhere (macOS, Windows)
    """
    #if defined(__linux__)
    #include <stdint.h>
    #include <sys/mman.h>
    #include <unistd.h>
    #endif
    static int o3d_no_huge_pages(char* p, size_t n) {
    #if defined(__linux__) && defined(MADV_NOHUGEPAGE)
        uintptr_t page = (uintptr_t)sysconf(_SC_PAGESIZE);
        uintptr_t start = ((uintptr_t)p + page - 1) / page * page, end = ((uintptr_t)p + n) / page * page;
        return end > start ? madvise((void*)start, end - start, MADV_NOHUGEPAGE) : 0;
    #else
        (void)p; (void)n;
        return 0;
    #endif
    }
    """
    int o3d_no_huge_pages(char* p, size_t n) noexcept nogil


def empty_small_pages(shape, dtype=np.float64, fill=None):
    """A new array, its buffer's whole pages advised to the OS as no transparent huge pages (``madvise``)
    before it is written, ``fill`` if given: the package's mesh-sized outputs and work arrays.

    NumPy advises huge pages for arrays of many megabytes, and on a kernel that compacts memory at the
    fault they cost more system time than they save (``docs/algorithms/constrained_fairing.rst``); no
    advice outside Linux, none for an array within a page.
    """
    array = np.empty(shape, dtype)
    if array.nbytes:
        o3d_no_huge_pages(<char*> <size_t> array.__array_interface__["data"][0], array.nbytes)
    if fill is not None:
        array.fill(fill)
    return array


cdef inline void _product3(const index_t[::1] indptr, const index_t[::1] indices, const double[::1] data,
                           const double[:, ::1] x, double[:, ::1] out, double scale,
                           const double[:, ::1] offset, bint shifted, Py_ssize_t start,
                           Py_ssize_t stop) noexcept nogil:
    """:func:`block_product`'s rows ``start:stop`` for three columns, the sums in registers."""
    cdef Py_ssize_t i
    cdef index_t jj, j
    cdef double a, s0, s1, s2
    for i in range(start, stop):
        s0 = s1 = s2 = 0.0
        for jj in range(indptr[i], indptr[i + 1]):
            j, a = indices[jj], data[jj]
            s0, s1, s2 = s0 + a * x[j, 0], s1 + a * x[j, 1], s2 + a * x[j, 2]
        if shifted:
            out[i, 0], out[i, 1], out[i, 2] = offset[i, 0] + scale * s0, offset[i, 1] + scale * s1, offset[i, 2] + scale * s2
        else:
            out[i, 0], out[i, 1], out[i, 2] = scale * s0, scale * s1, scale * s2


def block_product(const index_t[::1] indptr, const index_t[::1] indices, const double[::1] data,
                  const double[:, ::1] x, double[:, ::1] out, double scale=1.0,
                  const double[:, ::1] offset=None):
    """``out = offset + scale A @ x`` for CSR ``A`` (``(m, n)``), ``x`` ``(n, k)``, ``out`` and ``offset``
    ``(m, k)`` (no ``offset``: zero). ``offset`` may be ``out`` itself (accumulate) or ``b`` with
    ``scale=-1`` (a residual): each row reads its offset before writing, in the same pass."""
    cdef Py_ssize_t m = out.shape[0], k = x.shape[1], i, c, t, threads = _threads(out.shape[0])
    cdef index_t jj
    cdef double s0
    cdef bint shifted = offset is not None
    if shifted and (offset.shape[0] != m or offset.shape[1] != k):
        raise ValueError(f"offset must have the shape of out {(m, k)}, got {(offset.shape[0], offset.shape[1])}")
    with nogil:
        if k == 3 and threads == 1:  # the coordinates: sums in registers, no parallel region (its code is slower)
            _product3(indptr, indices, data, x, out, scale, offset, shifted, 0, m)
        elif k == 3:  # a contiguous block of rows per thread; each row's sum as on one thread
            for t in prange(threads, schedule="static", num_threads=threads):
                _product3(indptr, indices, data, x, out, scale, offset, shifted, t * m // threads,
                          (t + 1) * m // threads)
        else:  # a column at a time: the row's entries are in cache after the first
            for i in prange(m, schedule="static", num_threads=threads):
                for c in range(k):
                    s0 = 0.0
                    for jj in range(indptr[i], indptr[i + 1]):
                        s0 = s0 + data[jj] * x[indices[jj], c]
                    out[i, c] = offset[i, c] + scale * s0 if shifted else scale * s0


def gauss_seidel(const index_t[::1] indptr, const index_t[::1] indices, const double[::1] data,
                 double[:, ::1] x, const double[:, ::1] b, bint forward, Py_ssize_t blocks=1):
    """One Gauss-Seidel sweep of ``A x = b`` over the rows in order (``forward``) or in reverse, in place.

    Row ``i``: ``x_i = (b_i - sum_(j != i) a_ij x_j) / a_ii``, skipped where ``a_ii = 0`` (pyamg's
    ``gauss_seidel``: the same products in the same order, per column).
    With ``blocks > 1`` the rows are cut into that many contiguous blocks, swept in parallel (OpenMP):
    inside a block each row sees its block's updated values, across blocks the values from before the
    sweep (hybrid Gauss-Seidel, as hypre's). The result depends on ``blocks``, not on the thread count,
    and a forward sweep followed by a backward one with the same blocks is symmetric.
    """
    cdef Py_ssize_t n = x.shape[0], k = x.shape[1], block, start, stop
    if k > 16:
        raise ValueError(f"x must have at most 16 columns, got {k}")
    blocks = max(1, min(blocks, n))
    if blocks == 1:
        _sweep(indptr, indices, data, x, x, b, forward, 0, n)
        return
    cdef double[:, ::1] before = np.array(x, copy=True)
    for block in prange(blocks, nogil=True, schedule="dynamic", num_threads=_threads(n)):
        start = block * n // blocks
        stop = (block + 1) * n // blocks
        _sweep(indptr, indices, data, x, before, b, forward, start, stop)


cdef void _sweep(const index_t[::1] indptr, const index_t[::1] indices, const double[::1] data,
                 double[:, ::1] x, const double[:, ::1] before, const double[:, ::1] b, bint forward,
                 Py_ssize_t start, Py_ssize_t stop) noexcept nogil:
    """Gauss-Seidel over rows ``start:stop``: columns inside the range read ``x``, outside ``before``."""
    cdef Py_ssize_t k = x.shape[1], i, c, r
    cdef index_t jj, j
    cdef double a, diagonal, s0, s1, s2
    cdef double[16] rest
    for r in range(stop - start):
        i = start + r if forward else stop - 1 - r
        diagonal = 0.0
        if k == 3:  # the coordinates: sums in registers
            s0 = s1 = s2 = 0.0
            for jj in range(indptr[i], indptr[i + 1]):
                j, a = indices[jj], data[jj]
                if j == i:
                    diagonal = a
                elif start <= j < stop:
                    s0, s1, s2 = s0 + a * x[j, 0], s1 + a * x[j, 1], s2 + a * x[j, 2]
                else:
                    s0, s1, s2 = s0 + a * before[j, 0], s1 + a * before[j, 1], s2 + a * before[j, 2]
            if diagonal != 0.0:
                x[i, 0], x[i, 1], x[i, 2] = (b[i, 0] - s0) / diagonal, (b[i, 1] - s1) / diagonal, (
                    b[i, 2] - s2) / diagonal
        else:
            for c in range(k):
                rest[c] = 0.0
            for jj in range(indptr[i], indptr[i + 1]):
                j, a = indices[jj], data[jj]
                if j == i:
                    diagonal = a
                elif start <= j < stop:
                    for c in range(k):
                        rest[c] += a * x[j, c]
                else:
                    for c in range(k):
                        rest[c] += a * before[j, c]
            if diagonal != 0.0:
                for c in range(k):
                    x[i, c] = (b[i, c] - rest[c]) / diagonal


cdef void _rows3(double[:, ::1] x, double[:, ::1] r, const double[:, ::1] p, const double[:, ::1] q,
                 const double[::1] alpha, const double[::1] w, double[::1] sums, Py_ssize_t start,
                 Py_ssize_t stop, bint step) noexcept nogil:
    """Rows ``start:stop`` of three columns, summed in order: with ``step`` :func:`cg_step`'s update and
    ``|w r|^2``, else the dot products of ``p`` and ``q``."""
    cdef Py_ssize_t i
    cdef double s0 = 0.0, s1 = 0.0, s2 = 0.0, t0, t1, t2
    if step:  # two loops: a test inside one costs the update twice its time
        for i in range(start, stop):
            x[i, 0] += alpha[0] * p[i, 0]
            x[i, 1] += alpha[1] * p[i, 1]
            x[i, 2] += alpha[2] * p[i, 2]
            r[i, 0] -= alpha[0] * q[i, 0]
            r[i, 1] -= alpha[1] * q[i, 1]
            r[i, 2] -= alpha[2] * q[i, 2]
            t0, t1, t2 = w[i] * r[i, 0], w[i] * r[i, 1], w[i] * r[i, 2]
            s0, s1, s2 = s0 + t0 * t0, s1 + t1 * t1, s2 + t2 * t2
    else:
        for i in range(start, stop):
            s0, s1, s2 = s0 + p[i, 0] * q[i, 0], s1 + p[i, 1] * q[i, 1], s2 + p[i, 2] * q[i, 2]
    sums[0], sums[1], sums[2] = s0, s1, s2


cdef _column_sums(double[:, ::1] x, double[:, ::1] r, const double[:, ::1] p, const double[:, ::1] q,
                  const double[::1] alpha, const double[::1] w, bint step):
    # cg_step (step) and column_dots in one pass: for three columns over blocks of PARALLEL_ROWS rows (side
    # by side on every core), then over the blocks in order, so that the sums do not depend on the threads
    cdef Py_ssize_t n = p.shape[0], k = p.shape[1], i, c, t
    cdef Py_ssize_t blocks = max(1, (n + PARALLEL_ROWS - 1) // PARALLEL_ROWS)
    sums_array = np.zeros(k)
    cdef double[::1] sums = sums_array
    cdef double[:, ::1] partial = np.zeros((blocks, 3))
    with nogil:
        if k == 3:
            for t in prange(blocks, schedule="static", num_threads=_threads(n)):
                _rows3(x, r, p, q, alpha, w, partial[t], t * PARALLEL_ROWS, min(n, (t + 1) * PARALLEL_ROWS),
                       step)
            for t in range(blocks):
                for c in range(3):
                    sums[c] += partial[t, c]
        else:
            for i in range(n):
                for c in range(k):
                    if step:
                        x[i, c] += alpha[c] * p[i, c]
                        r[i, c] -= alpha[c] * q[i, c]
                        sums[c] += (w[i] * r[i, c]) * (w[i] * r[i, c])
                    else:
                        sums[c] += p[i, c] * q[i, c]
    return sums_array


def cg_step(double[:, ::1] x, double[:, ::1] r, const double[:, ::1] p, const double[:, ::1] q,
            const double[::1] alpha, const double[::1] w):
    """Conjugate gradients' update ``x += alpha p``, ``r -= alpha q`` (per column) in one pass; returns the
    columns' ``|w r|^2`` after it (``w`` a weight per row), ``(k,)``, summed as :func:`column_dots`'s."""
    return _column_sums(x, r, p, q, alpha, w, True)


def column_dots(const double[:, ::1] a, const double[:, ::1] b):
    """``(k,)`` dot products of the columns of ``a`` and ``b`` (both ``(n, k)``): for three columns summed in
    order over blocks of :data:`PARALLEL_ROWS` rows, then over the blocks in order, so that the sums do not
    depend on the thread count."""
    return _column_sums(None, None, a, b, None, None, False)


def cg_direction(double[:, ::1] p, const double[:, ::1] z, const double[::1] beta):
    """Conjugate gradients' new direction ``p = z + beta p`` (per column), in place, in one pass."""
    cdef Py_ssize_t n = p.shape[0], k = p.shape[1], i, c
    with nogil:
        for i in prange(n, schedule="static", num_threads=_threads(n)):
            for c in range(k):
                p[i, c] = z[i, c] + beta[c] * p[i, c]


def symmetry_gap(const index_t[::1] indptr, const index_t[::1] indices, const double[::1] data):
    """How far a square CSC (or CSR) matrix with sorted indices is from symmetric, without a copy.

    Returns ``(gap, i, j, above)``: the largest ``|a_ij - a_ji|`` (a missing mirror counts as zero) at
    its entry ``(i, j)`` (row, column), and how many entries lie above the diagonal. One pass: the
    columns are read in order, so the mirrors sought in column ``i`` come in increasing rows, and a
    cursor per column walks to each (each column's entries passed over once).
    """
    cdef Py_ssize_t n = indptr.shape[0] - 1, j, lo, wi = 0, wj = 0, above = 0
    cdef index_t k, i
    cdef double mirror, gap, largest = 0.0
    cdef int64_t[::1] cursor = empty_small_pages(n, np.int64)
    with nogil:
        for j in range(n):
            cursor[j] = indptr[j]
        for j in range(n):
            for k in range(indptr[j], indptr[j + 1]):
                i = indices[k]
                if i < j:
                    above += 1
                lo = cursor[i]
                while lo < indptr[i + 1] and indices[lo] < j:  # row j of column i
                    lo += 1
                cursor[i] = lo
                mirror = data[lo] if lo < indptr[i + 1] and indices[lo] == j else 0.0
                gap = fabs(data[k] - mirror)
                if gap > largest:
                    largest, wi, wj = gap, i, j
    return largest, wi, wj, above


def incomplete_cholesky(const index_t[::1] indptr, const index_t[::1] indices, const double[::1] data,
                        double shift):
    """Zero-fill incomplete Cholesky factor ``L`` (IC(0)) of a symmetric matrix, on its own pattern.

    ``indptr, indices, data``: the whole matrix in CSR, each row's columns ascending, the pattern
    symmetric and every diagonal entry stored. Row by row, ``l_ij = (a_ij - sum_(k < j) l_ik l_jk) /
    l_jj`` for the pattern's ``j < i`` (the sum over both rows' entries: row ``i``'s are scattered into
    a dense work row), then ``l_ii = sqrt((1 + shift) a_ii - sum_(k < i) l_ik^2)``: ``L L^T`` equals
    the matrix (its diagonal times ``1 + shift``) on the pattern. Sequential by nature.

    Returns ``(values, diagonal, -1)``: ``values`` on the matrix's pattern hold ``l_ij`` at ``(i, j)``
    and at its mirror ``(j, i)`` (so both triangular solves read rows), ``diagonal`` each row's
    diagonal position. ``(None, None, i)`` when row ``i``'s pivot is not positive (IC(0) breaks down on
    some SPD matrices: the caller retries with a larger ``shift``, Manteuffel's remedy).
    Raises ``ValueError`` for a missing diagonal entry or an unsymmetric pattern.
    """
    cdef Py_ssize_t n = indptr.shape[0] - 1, i, p, q, j, d, failed = -1, bad = -1
    cdef double s, pivot
    values = empty_small_pages(data.shape[0])
    diagonal = empty_small_pages(n, np.int64)
    cdef double[::1] L = values
    cdef int64_t[::1] diag = diagonal
    cdef int64_t[::1] mirror = empty_small_pages(n, np.int64)  # each row's next upper entry to fill
    cdef double[::1] work = empty_small_pages(n, fill=0.0)
    with nogil:
        for i in range(n):
            diag[i] = -1
            for p in range(indptr[i], indptr[i + 1]):
                if indices[p] == i:
                    diag[i] = p
                    break
            if diag[i] < 0:
                bad = i
                break
            mirror[i] = diag[i] + 1
    if bad >= 0:
        raise ValueError(f"matrix must store every diagonal entry, row {bad} has none")
    with nogil:
        for i in range(n):
            d = diag[i]
            pivot = data[d] * (1.0 + shift)
            for p in range(indptr[i], d):
                j = indices[p]
                s = data[p]
                for q in range(indptr[j], diag[j]):
                    s = s - work[indices[q]] * L[q]
                s = s / L[diag[j]]
                L[p] = s
                work[j] = s
                pivot = pivot - s * s
                q = mirror[j]
                if q >= indptr[j + 1] or indices[q] != i:
                    bad = i
                    break
                L[q] = s
                mirror[j] = q + 1
            if bad >= 0:
                break
            if not pivot > 1e-12 * data[d]:  # not positive, or a cancellation to round-off
                failed = i
                break
            L[d] = sqrt(pivot)
            for p in range(indptr[i], d):
                work[indices[p]] = 0.0
    if bad >= 0:
        raise ValueError(f"matrix must have a symmetric pattern, row {bad}'s lower entries are not mirrored")
    if failed >= 0:
        return None, None, failed
    return values, diagonal, -1


def incomplete_cholesky_solve(const index_t[::1] indptr, const index_t[::1] indices, const double[::1] L,
                              const int64_t[::1] diag, const double[:, ::1] r, double[:, ::1] z):
    """``z = (L L^T)^-1 r`` for :func:`incomplete_cholesky`'s ``L``: forward then backward substitution,
    both reading rows (``l_ji`` of ``L^T`` is stored at ``(i, j)``), every column at once (``r`` and
    ``z`` ``(n, k)``; ``z`` may be ``r``). Sequential by nature."""
    with nogil:
        _substitute(indptr, indices, L, diag, r, z, True)  # L y = r
        _substitute(indptr, indices, L, diag, z, z, False)  # L^T z = y


cdef void _substitute(const index_t[::1] indptr, const index_t[::1] indices, const double[::1] L,
                      const int64_t[::1] diag, const double[:, ::1] b, double[:, ::1] z,
                      bint lower) noexcept nogil:
    """``z = L^-1 b`` over the rows in order (``lower``), else ``z = L^-T b`` in reverse; ``b`` may be ``z``."""
    cdef Py_ssize_t n = z.shape[0], k = z.shape[1], t, i, p, c, start, stop
    cdef index_t j
    cdef double l, s0, s1, s2
    for t in range(n):
        i = t if lower else n - 1 - t
        start = indptr[i] if lower else diag[i] + 1
        stop = diag[i] if lower else indptr[i + 1]
        if k == 3:  # the coordinates: sums in registers
            s0, s1, s2 = b[i, 0], b[i, 1], b[i, 2]
            for p in range(start, stop):
                j, l = indices[p], L[p]
                s0, s1, s2 = s0 - l * z[j, 0], s1 - l * z[j, 1], s2 - l * z[j, 2]
            l = L[diag[i]]
            z[i, 0], z[i, 1], z[i, 2] = s0 / l, s1 / l, s2 / l
        else:
            for c in range(k):
                s0 = b[i, c]
                for p in range(start, stop):
                    s0 = s0 - L[p] * z[indices[p], c]
                z[i, c] = s0 / L[diag[i]]


def strong_part(const index_t[::1] indptr, const index_t[::1] indices, const double[::1] data, double theta):
    """The strong entries of a symmetric CSR matrix, its weak ones lumped onto the diagonal.

    Entry ``a_ij`` (``i != j``) is strong where ``|a_ij| >= theta sqrt(|a_ii a_jj|)`` (pyamg's symmetric
    strength of connection); each row's weak entries are summed into its diagonal entry, so the row
    sums (and a constant null space) survive. Returns ``(indptr, indices, data)`` of the filtered
    matrix, rows in the input's order. Every row must store its diagonal.
    """
    cdef Py_ssize_t n = indptr.shape[0] - 1, i, count = 0
    cdef index_t jj, j, out
    cdef double[::1] diagonal = np.zeros(n)
    for i in range(n):
        for jj in range(indptr[i], indptr[i + 1]):
            if indices[jj] == i:
                diagonal[i] = abs(data[jj])
    for i in range(n):
        for jj in range(indptr[i], indptr[i + 1]):
            j = indices[jj]
            if j == i or abs(data[jj]) >= theta * sqrt(diagonal[i] * diagonal[j]):
                count += 1
    dtype = np.int32 if index_t is int32_t else np.int64
    strong_indptr, strong_indices, strong_data = np.empty(n + 1, dtype), np.empty(count, dtype), np.empty(count)
    cdef index_t[::1] sp = strong_indptr, si = strong_indices
    cdef double[::1] sd = strong_data
    cdef double weak
    cdef index_t place
    out = 0
    sp[0] = 0
    for i in range(n):
        weak, place = 0.0, -1
        for jj in range(indptr[i], indptr[i + 1]):
            j = indices[jj]
            if j == i or abs(data[jj]) >= theta * sqrt(diagonal[i] * diagonal[j]):
                if j == i:
                    place = out
                si[out], sd[out] = j, data[jj]
                out += 1
            else:
                weak += data[jj]
        if place >= 0:
            sd[place] += weak
        sp[i + 1] = out
    return strong_indptr, strong_indices, strong_data


def row_span(const index_t[::1] indptr, const index_t[::1] indices):
    """Mean ``|i - j|`` over the stored entries ``(i, j)`` of a CSR matrix: how far, in rows, a row's
    product reaches into ``x`` (0.0 for no entries)."""
    cdef Py_ssize_t n = indptr.shape[0] - 1, i
    cdef index_t jj
    cdef double total = 0.0
    with nogil:
        for i in prange(n, schedule="static", num_threads=_threads(n)):
            for jj in range(indptr[i], indptr[i + 1]):
                total += abs(<double>(indices[jj] - i))
    return total / max(<Py_ssize_t>indptr[n], 1)


cdef inline void _sort_row(index_t[::1] indices, double[::1] data, Py_ssize_t start,
                           Py_ssize_t stop) noexcept nogil:
    """Sort one CSR row's entries ``start:stop`` by column, values alongside (insertion sort: rows are short)."""
    cdef Py_ssize_t a, b
    cdef index_t column
    cdef double value
    for a in range(start + 1, stop):
        column, value, b = indices[a], data[a], a - 1
        while b >= start and indices[b] > column:
            indices[b + 1], data[b + 1] = indices[b], data[b]
            b = b - 1
        indices[b + 1], data[b + 1] = column, value


def permuted(const index_t[::1] indptr, const index_t[::1] indices, const double[::1] data,
             const int64_t[::1] order):
    """A square CSR matrix renumbered, ``B[r, s] = A[order[r], order[s]]``: ``(indptr, indices, data)``,
    each row's columns sorted. One pass, one copy (fancy indexing makes two)."""
    cdef Py_ssize_t n = indptr.shape[0] - 1, r, t
    cdef index_t jj, start
    if order.shape[0] != n:
        raise ValueError(f"order must have one entry per row ({n}), got {order.shape[0]}")
    dtype = np.int32 if index_t is int32_t else np.int64
    inverse_array = empty_small_pages(n, dtype, -1)
    cdef index_t[::1] inverse = inverse_array
    for r in range(n):
        if not 0 <= order[r] < n or inverse[order[r]] != -1:
            raise ValueError("order must be a permutation of the rows")
        inverse[order[r]] = r
    new_indptr, new_indices = empty_small_pages(n + 1, dtype), empty_small_pages(indptr[n], dtype)
    new_data = empty_small_pages(indptr[n])
    cdef index_t[::1] ip = new_indptr, ix = new_indices
    cdef double[::1] dx = new_data
    ip[0] = 0
    for r in range(n):
        ip[r + 1] = ip[r] + indptr[order[r] + 1] - indptr[order[r]]
    with nogil:
        for r in prange(n, schedule="static", num_threads=_threads(n)):
            start = ip[r]
            for jj in range(indptr[order[r]], indptr[order[r] + 1]):
                t = start + jj - indptr[order[r]]
                ix[t], dx[t] = inverse[indices[jj]], data[jj]
            _sort_row(ix, dx, start, ip[r + 1])
    return new_indptr, new_indices, new_data


cdef Py_ssize_t _breadth_first(const index_t[::1] indptr, const index_t[::1] indices, int64_t start,
                               int64_t[::1] queue, int64_t[::1] seen, int64_t stamp) noexcept nogil:
    """Vertices reached from ``start`` in breadth-first order into ``queue``, each vertex's new
    neighbours by increasing degree (Cuthill-McKee), each marked ``seen[v] = stamp``; returns how many."""
    cdef Py_ssize_t head = 0, tail = 1, first, a, b
    cdef int64_t v, w
    cdef index_t jj, degree
    queue[0] = start
    seen[start] = stamp
    while head < tail:
        v = queue[head]
        head += 1
        first = tail
        for jj in range(indptr[v], indptr[v + 1]):
            w = indices[jj]
            if seen[w] != stamp:
                seen[w] = stamp
                queue[tail] = w
                tail += 1
        for a in range(first + 1, tail):  # insertion sort by degree: a handful of neighbours
            w, degree, b = queue[a], indptr[queue[a] + 1] - indptr[queue[a]], a - 1
            while b >= first and indptr[queue[b] + 1] - indptr[queue[b]] > degree:
                queue[b + 1] = queue[b]
                b -= 1
            queue[b + 1] = w
    return tail


def level_order(const index_t[::1] indptr, const index_t[::1] indices):
    """A bandwidth-reducing order of a symmetric graph's ``n`` vertices, ``(n,)`` int64 (new -> old).

    Reverse Cuthill-McKee, as SciPy's ``reverse_cuthill_mckee``: per component, a breadth-first
    search from its vertex of least degree, each vertex's new neighbours by increasing degree, and the
    whole order reversed; linear (a first search finds the component, a second orders it).
    """
    cdef Py_ssize_t n = indptr.shape[0] - 1, done = 0, reached, s = 0, i
    order_array = empty_small_pages(n, np.int64)
    probe_array = empty_small_pages(n, np.int64)
    seen_array = empty_small_pages(n, np.int64, -1)
    cdef int64_t[::1] order = order_array, probe = probe_array, seen = seen_array
    cdef int64_t component = 0, start, v
    with nogil:
        while done < n:
            while seen[s] >= 0:  # the lowest vertex not yet ordered is in the next component
                s += 1
            reached = _breadth_first(indptr, indices, s, probe, seen, 2 * component)
            start = s
            for i in range(reached):  # the component's vertex of least degree (the first reached of ties)
                v = probe[i]
                if indptr[v + 1] - indptr[v] < indptr[start + 1] - indptr[start]:
                    start = v
            _breadth_first(indptr, indices, start, order[done:], seen, 2 * component + 1)
            done += reached
            component += 1
    return order_array[::-1].copy()


cdef void _gram_count(const index_t[::1] row_ptr, const index_t[::1] row_cols, const index_t[::1] col_ptr,
                      const index_t[::1] col_rows, int64_t[::1] marker, int64_t[::1] counts, Py_ssize_t start,
                      Py_ssize_t stop) noexcept nogil:
    """:func:`gram`'s counting pass over rows ``start:stop``, with one thread's marker."""
    cdef Py_ssize_t i
    cdef index_t cc, jj
    for i in range(start, stop):
        for cc in range(row_ptr[i], row_ptr[i + 1]):
            for jj in range(col_ptr[row_cols[cc]], col_ptr[row_cols[cc] + 1]):
                if marker[col_rows[jj]] != i:
                    marker[col_rows[jj]] = i
                    counts[i + 1] += 1


cdef void _gram_fill(const index_t[::1] row_ptr, const index_t[::1] row_cols, const double[::1] row_data,
                     const index_t[::1] col_ptr, const index_t[::1] col_rows, const double[::1] col_data,
                     const index_t[::1] indptr, index_t[::1] indices, double[::1] data, int64_t[::1] marker,
                     Py_ssize_t start, Py_ssize_t stop) noexcept nogil:
    """:func:`gram`'s filling pass over rows ``start:stop`` (ascending), with one thread's marker."""
    cdef Py_ssize_t i
    cdef index_t cc, jj, j
    cdef int64_t first, next_
    cdef double weight
    for i in range(start, stop):
        first = indptr[i]
        next_ = first
        for cc in range(row_ptr[i], row_ptr[i + 1]):
            weight = row_data[cc]
            for jj in range(col_ptr[row_cols[cc]], col_ptr[row_cols[cc] + 1]):
                j = col_rows[jj]
                if marker[j] < first:  # the rows ascend: older marks are below the row's first entry
                    marker[j] = next_
                    indices[next_] = j
                    data[next_] = weight * col_data[jj]
                    next_ = next_ + 1
                else:
                    data[marker[j]] += weight * col_data[jj]
        _sort_row(indices, data, first, next_)


def gram(const index_t[::1] row_ptr, const index_t[::1] row_cols, const double[::1] row_data,
         const index_t[::1] col_ptr, const index_t[::1] col_rows, const double[::1] col_data):
    """``A A^T`` for an ``(n, k)`` sparse ``A`` given both as CSR (``row_*``) and as CSC (``col_*``):
    CSR ``(indptr, indices, data)`` of the ``(n, n)`` product, each row's columns sorted, on every core.

    Row ``i`` is ``sum_(c in row i) a_ic A[:, c]^T``, gathered with a per-thread marker (Gustavson's
    algorithm): a counting pass, then a filling one, each thread on a contiguous block of rows. Entry
    ``(i, j)`` sums ``a_ic a_jc`` over the common columns in increasing ``c``, as ``(j, i)`` does: the
    product is exactly symmetric (SciPy's runs on one thread, then transposes to sort).
    """
    cdef Py_ssize_t n = row_ptr.shape[0] - 1, t, threads = _threads(row_ptr.shape[0] - 1)
    dtype = np.int32 if index_t is int32_t else np.int64
    marker_array = empty_small_pages((threads, max(n, 1)), np.int64, -1)
    cdef int64_t[:, ::1] marker = marker_array
    counts_array = empty_small_pages(n + 1, np.int64, 0)
    cdef int64_t[::1] counts = counts_array
    with nogil:
        for t in prange(threads, schedule="static", num_threads=threads):
            _gram_count(row_ptr, row_cols, col_ptr, col_rows, marker[t], counts, t * n // threads,
                        (t + 1) * n // threads)
    indptr_array = np.cumsum(counts_array)
    if indptr_array[n] >= np.iinfo(dtype).max:
        raise ValueError("the product has too many entries for 32-bit indices: pass 64-bit ones")
    indptr_array = indptr_array.astype(dtype)
    indices_array, data_array = empty_small_pages(indptr_array[n], dtype), empty_small_pages(indptr_array[n])
    cdef index_t[::1] indptr = indptr_array, indices = indices_array
    cdef double[::1] data = data_array
    marker_array.fill(-1)
    with nogil:
        for t in prange(threads, schedule="static", num_threads=threads):
            _gram_fill(row_ptr, row_cols, row_data, col_ptr, col_rows, col_data, indptr, indices, data,
                       marker[t], t * n // threads, (t + 1) * n // threads)
    return indptr_array, indices_array, data_array


def pair_product(const index_t[::1] indptr, const index_t[::1] indices, const double[::1] a,
                 const double[:, ::1] xa, const double[::1] b, const double[:, ::1] xb,
                 const double[:, ::1] offset, double[:, ::1] out):
    """``out = offset + A @ xa + B @ xb`` for CSR ``A`` and ``B`` on one pattern ``(indptr, indices)``
    (values ``a`` and ``b``), every block ``(n, 3)``: one pass over the pattern instead of two, on every
    core (local fairing's ``E2 X + E1 (W X)``)."""
    cdef Py_ssize_t m = out.shape[0], i
    cdef index_t jj, j
    cdef double va, vb, s0, s1, s2
    for name, block in (("xa", xa), ("xb", xb), ("offset", offset), ("out", out)):
        if block.shape[1] != 3:
            raise ValueError(f"{name} must have 3 columns, got {block.shape[1]}")
    if offset.shape[0] != m:
        raise ValueError(f"offset must have the shape of out {(m, 3)}, got {(offset.shape[0], 3)}")
    with nogil:
        for i in prange(m, schedule="static", num_threads=_threads(m)):
            s0, s1, s2 = offset[i, 0], offset[i, 1], offset[i, 2]
            for jj in range(indptr[i], indptr[i + 1]):
                j, va, vb = indices[jj], a[jj], b[jj]
                s0 = s0 + va * xa[j, 0] + vb * xb[j, 0]
                s1 = s1 + va * xa[j, 1] + vb * xb[j, 1]
                s2 = s2 + va * xa[j, 2] + vb * xb[j, 2]
            out[i, 0], out[i, 1], out[i, 2] = s0, s1, s2


def add_subset(const index_t[::1] indptr, const index_t[::1] indices, double[::1] data,
               const index_t[::1] sub_indptr, const index_t[::1] sub_indices, const double[::1] sub_data):
    """``A += B`` in place, for CSR ``A`` and ``B`` of one shape with sorted rows and ``B``'s pattern within
    ``A``'s (a 1-ring term added to a 2-ring matrix without a third matrix); on every core. Returns the
    number of ``B``'s entries not in ``A``'s pattern (left out; 0 when the pattern holds them all)."""
    cdef Py_ssize_t n = indptr.shape[0] - 1, i
    cdef index_t p, end, q
    cdef Py_ssize_t missing = 0
    if sub_indptr.shape[0] != indptr.shape[0]:
        raise ValueError(f"sub_indptr must have {indptr.shape[0]} entries, got {sub_indptr.shape[0]}")
    with nogil:
        for i in prange(n, schedule="static", num_threads=_threads(n)):
            p, end = indptr[i], indptr[i + 1]
            for q in range(sub_indptr[i], sub_indptr[i + 1]):
                while p < end and indices[p] < sub_indices[q]:
                    p = p + 1
                if p < end and indices[p] == sub_indices[q]:
                    data[p] += sub_data[q]
                else:
                    missing += 1
    return missing


def area_normals(const double[:, ::1] positions, const index_t[:, ::1] triangles):
    """Each vertex's sum of the cross products ``(b - a) x (c - a)`` of its triangles ``(a, b, c)``,
    ``(n, 3)``, in one pass over the triangles (arrays.area_weighted_normals' loop). Each corner's sums
    are kept apart and added at the end, corner 0's and 1's first: the order of
    ``sum(np.bincount(triangles[:, i], face) for i in range(3))``, whose values it reproduces."""
    cdef Py_ssize_t n = positions.shape[0], m = triangles.shape[0], t, c, v
    cdef index_t a, b, d
    cdef double u0, u1, u2, w0, w1, w2
    if triangles.shape[1] != 3 or positions.shape[1] != 3:
        raise ValueError(f"positions and triangles must have 3 columns, got {positions.shape[1]} and {triangles.shape[1]}")
    for t in range(m):
        for c in range(3):
            if not 0 <= triangles[t, c] < n:
                raise ValueError(f"triangle {t} names vertex {triangles[t, c]}, outside 0..{n - 1}")
    sums_array = empty_small_pages((3, n, 3), fill=0.0)
    cdef double[:, :, ::1] sums = sums_array
    with nogil:
        for t in range(m):
            a, b, d = triangles[t, 0], triangles[t, 1], triangles[t, 2]
            u0, u1, u2 = positions[b, 0] - positions[a, 0], positions[b, 1] - positions[a, 1], positions[b, 2] - positions[a, 2]
            w0, w1, w2 = positions[d, 0] - positions[a, 0], positions[d, 1] - positions[a, 1], positions[d, 2] - positions[a, 2]
            # numpy's cross: each product rounded, then the difference
            w0, w1, w2 = u1 * w2 - u2 * w1, u2 * w0 - u0 * w2, u0 * w1 - u1 * w0
            for c in range(3):
                v = triangles[t, c]
                sums[c, v, 0] += w0
                sums[c, v, 1] += w1
                sums[c, v, 2] += w2
        for v in range(n):
            for c in range(3):
                sums[0, v, c] = sums[0, v, c] + sums[1, v, c] + sums[2, v, c]
    return sums_array[0]


def edge_sums(const index_t[:, ::1] edges, const double[:, ::1] values):
    """``(n, k)``: each vertex's sum of ``values`` over its ``edges`` neighbours (an edge listed twice
    counts twice), in one pass: the sums over the edges where it is first, then those where it is second,
    each in the edges' order (``np.bincount(lo, values[hi]) + np.bincount(hi, values[lo])``)."""
    cdef Py_ssize_t n = values.shape[0], k = values.shape[1], e = edges.shape[0], t, c
    cdef index_t lo, hi
    if edges.shape[1] != 2:
        raise ValueError(f"edges must have 2 columns, got {edges.shape[1]}")
    for t in range(e):
        if not (0 <= edges[t, 0] < n and 0 <= edges[t, 1] < n):
            raise ValueError(f"edge {t} names a vertex outside 0..{n - 1}")
    first_array, second_array = empty_small_pages((n, k), fill=0.0), empty_small_pages((n, k), fill=0.0)
    cdef double[:, ::1] first = first_array, second = second_array
    with nogil:
        for t in range(e):
            lo, hi = edges[t, 0], edges[t, 1]
            for c in range(k):
                first[lo, c] += values[hi, c]
                second[hi, c] += values[lo, c]
        for t in range(n):
            for c in range(k):
                first[t, c] = first[t, c] + second[t, c]
    return first_array


def two_ring_sums(const index_t[::1] indptr, const index_t[::1] indices, const int64_t[::1] rows,
                  const double[:, ::1] values):
    """For each of ``rows``: how many vertices lie within two edges of it (itself excluded) and the sum of
    their ``values`` rows, ``((r,) float64, (r, k))``, from the 1-ring CSR ``(indptr, indices)`` without
    the 2-ring's matrix (a mark per vertex: each counted once)."""
    cdef Py_ssize_t n = indptr.shape[0] - 1, r = rows.shape[0], k = values.shape[1], s, c
    cdef int64_t i, a, b
    cdef index_t p, q
    if values.shape[0] != n:
        raise ValueError(f"values must have {n} rows, got {values.shape[0]}")
    for s in range(r):
        if not 0 <= rows[s] < n:
            raise ValueError(f"rows must lie in 0..{n - 1}, got {rows[s]}")
    counts_array, sums_array = np.zeros(r), np.zeros((r, k))
    cdef double[::1] counts = counts_array
    cdef double[:, ::1] sums = sums_array
    cdef int64_t[::1] mark = empty_small_pages(n, np.int64, -1)
    with nogil:
        for s in range(r):
            i = rows[s]
            mark[i] = s
            for p in range(indptr[i], indptr[i + 1]):
                a = indices[p]
                q = indptr[a] - 1
                while q < indptr[a + 1]:  # the neighbour, then its own neighbours
                    b = a if q < indptr[a] else indices[q]
                    q = q + 1
                    if mark[b] != s:
                        mark[b] = s
                        counts[s] += 1.0
                        for c in range(k):
                            sums[s, c] += values[b, c]
    return counts_array, sums_array


def triangle_normals(const double[:, ::1] positions, const index_t[:, ::1] triangles, bint centroids=False):
    """Each triangle's unit normal ``(m, 3)`` (zero on a degenerate one), area ``(m,)`` and, with
    ``centroids``, centroid ``(m, 3)`` (``None`` without), in one pass (arrays.face_normals' loop).

    The operations of the NumPy code, whose values it reproduces: ``np.cross`` (each product rounded,
    then the difference), ``np.linalg.norm`` (``sqrt((x*x + y*y) + z*z)``), the division by
    ``max(length, tiny)``, ``0.5 * length``; a centroid is ``(((0 + a) + b) + c) / 3``, the sums of the
    triangle-vertex incidence's product in its stored order.
    """
    cdef Py_ssize_t n = positions.shape[0], m = triangles.shape[0], t, c
    cdef index_t a, b, d
    cdef double u0, u1, u2, w0, w1, w2, length, s
    cdef double tiny = np.finfo(np.float64).tiny
    if positions.shape[1] != 3:
        raise ValueError(f"positions must have shape (n, 3), got ({n}, {positions.shape[1]})")
    if triangles.shape[1] != 3:
        raise ValueError(f"triangles must have shape (m, 3), got ({m}, {triangles.shape[1]})")
    for t in range(m):
        for c in range(3):
            if not 0 <= triangles[t, c] < n:
                raise ValueError(f"triangles must name vertices in 0..{n - 1}, got {triangles[t, c]} in triangle {t}")
    normals_array, area_array = np.empty((m, 3)), np.empty(m)
    centroid_array = np.empty((m if centroids else 0, 3))
    cdef double[:, ::1] normal = normals_array, centroid = centroid_array
    cdef double[::1] area = area_array
    with nogil:
        for t in prange(m, schedule="static", num_threads=_threads(m)):
            a, b, d = triangles[t, 0], triangles[t, 1], triangles[t, 2]
            u0, u1, u2 = positions[b, 0] - positions[a, 0], positions[b, 1] - positions[a, 1], positions[b, 2] - positions[a, 2]
            w0, w1, w2 = positions[d, 0] - positions[a, 0], positions[d, 1] - positions[a, 1], positions[d, 2] - positions[a, 2]
            # numpy's cross: each product rounded, then the difference
            w0, w1, w2 = u1 * w2 - u2 * w1, u2 * w0 - u0 * w2, u0 * w1 - u1 * w0
            length = sqrt((w0 * w0 + w1 * w1) + w2 * w2)
            area[t] = 0.5 * length
            length = max(length, tiny)
            normal[t, 0], normal[t, 1], normal[t, 2] = w0 / length, w1 / length, w2 / length
            if centroids:
                for c in range(3):
                    # from 0, as the sparse product's sums: a -0.0 corner gives +0.0 as there
                    s = 0.0
                    s = s + positions[a, c]
                    s = s + positions[b, c]
                    s = s + positions[d, c]
                    centroid[t, c] = s / 3.0
    return normals_array, area_array, centroid_array if centroids else None

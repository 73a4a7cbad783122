# cython: language_level=3
# What both hole-filling kernels (_triangulation_kernel, _patch_kernel) share: 3-vector arithmetic, a
# triangle's smallest angle, undirected edge keys and their sorting and search, the index check of their
# arguments.

from libc.math cimport asin, fmax, fmin, sqrt
from libc.stdint cimport int64_t
from libc.string cimport memcpy, memset

cdef inline bint _outside(const int64_t* a, int64_t count, int64_t n) noexcept nogil:
    """Whether an index of ``a`` is outside ``[0, n)`` (the arguments' check, without NumPy's reductions)."""
    cdef int64_t k
    for k in range(count):
        if a[k] < 0 or a[k] >= n:
            return True
    return False

cdef inline double _max(double a, double b) noexcept nogil:
    """``fmax`` of two numbers (not NaN) in one instruction (libm's is a call): the same value but a
    zero's sign, which comparisons and squares ignore (the crossing test's only uses)."""
    return a if a > b else b

cdef inline double _min(double a, double b) noexcept nogil:
    """``fmin`` likewise."""
    return a if a < b else b

cdef inline double _dot(const double* a, const double* b) noexcept nogil:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]

cdef inline void _sub(const double* a, const double* b, double* out) noexcept nogil:
    out[0] = a[0] - b[0]
    out[1] = a[1] - b[1]
    out[2] = a[2] - b[2]

cdef inline void _cross(const double* u, const double* v, double* out) noexcept nogil:
    out[0] = u[1] * v[2] - u[2] * v[1]
    out[1] = u[2] * v[0] - u[0] * v[2]
    out[2] = u[0] * v[1] - u[1] * v[0]

cdef inline void _normal(const double* p0, const double* p1, const double* p2, double* out) noexcept nogil:
    """Triangle ``(p0, p1, p2)``'s normal ``(p1 - p0) x (p2 - p0)``, twice its area long."""
    cdef double[3] u, v
    _sub(p1, p0, u)
    _sub(p2, p0, v)
    _cross(u, v, out)

cdef inline double _min_angle(const double* p0, const double* p1, const double* p2) noexcept nogil:
    """The smallest interior angle, opposite the shortest edge (law of sines): ``arcsin(2 area / (l_mid
    l_max))``."""
    cdef double[3] a, b, c, n
    cdef double la, lb, lc, mid, top, denominator, ratio
    _sub(p1, p0, a)
    _sub(p2, p1, b)
    _sub(p0, p2, c)
    la, lb, lc = _dot(a, a), _dot(b, b), _dot(c, c)
    top = fmax(la, fmax(lb, lc))
    mid = fmax(fmin(la, lb), fmin(fmax(la, lb), lc))  # the median of three
    _cross(a, c, n)
    denominator = sqrt(mid * top)
    ratio = sqrt(_dot(n, n)) / denominator if denominator > 0 else 0.0
    return asin(fmin(ratio, 1.0))

ctypedef struct Half:  # a half-edge's undirected key and its index 3 t + s
    int64_t key
    int64_t h

cdef inline int _by_key(const void* x, const void* y) noexcept nogil:
    cdef const Half* p = <const Half*>x
    cdef const Half* q = <const Half*>y
    if p.key != q.key:
        return -1 if p.key < q.key else 1
    return -1 if p.h < q.h else (1 if p.h > q.h else 0)

cdef inline int _by_value(const void* x, const void* y) noexcept nogil:
    cdef int64_t p = (<const int64_t*>x)[0], q = (<const int64_t*>y)[0]
    return -1 if p < q else (1 if p > q else 0)

cdef inline int64_t _key(int64_t a, int64_t b) noexcept nogil:
    """An undirected edge's key, ordered as ``(min, max)``."""
    return (a << 32) | b if a < b else (b << 32) | a

cdef inline int64_t _lower(const int64_t* sorted_, int64_t n, int64_t key, int64_t stride) noexcept nogil:
    """The first of the ``n`` sorted values ``sorted_[0], sorted_[stride], ...`` not below ``key`` (or ``n``)."""
    cdef int64_t lo = 0, hi = n, mid
    while lo < hi:
        mid = (lo + hi) >> 1
        if sorted_[mid * stride] < key:
            lo = mid + 1
        else:
            hi = mid
    return lo

cdef inline void _sort_halves(Half* a, Half* tmp, int64_t n, int64_t* count) noexcept nogil:
    """Sort ``n`` half-edges given in index order by (key, index): a stable radix sort of the keys, 8 bits a
    pass, digits that all share skipped (``tmp``: ``n`` more, ``count``: 8 * 256 scratch); the same order
    as qsort by ``_by_key`` in linear time (a pass of flips, a patch's system, sorted every half-edge)."""
    cdef int64_t i, s, total, c
    cdef int d
    cdef Half* src = a
    cdef Half* dst = tmp
    cdef Half* swap
    memset(count, 0, 8 * 256 * sizeof(int64_t))
    for i in range(n):
        for d in range(8):
            count[d * 256 + ((a[i].key >> (8 * d)) & 0xFF)] += 1
    for d in range(8):
        if n == 0 or count[d * 256 + ((a[0].key >> (8 * d)) & 0xFF)] == n:
            continue
        total = 0
        for s in range(256):
            c = count[d * 256 + s]
            count[d * 256 + s] = total
            total += c
        for i in range(n):
            s = d * 256 + ((src[i].key >> (8 * d)) & 0xFF)
            dst[count[s]] = src[i]
            count[s] += 1
        swap = src
        src = dst
        dst = swap
    if src != a:
        memcpy(a, src, n * sizeof(Half))

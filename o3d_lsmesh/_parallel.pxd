# cython: language_level=3
# What both OpenMP kernels (_block_kernel, _feature_kernel) share: the thread rule of their parallel loops
# and the index type of their sparse patterns.

from libc.stdint cimport int32_t, int64_t

cdef extern from *:
    # OpenMP's thread count where the build has OpenMP (setup.py's probe), one thread otherwise: prange
    # and threadid() fall back to serial loops by themselves, omp.h may not exist (Apple's clang)
    """
    #ifdef _OPENMP
    #include <omp.h>
    #else
    static int omp_get_max_threads(void) { return 1; }
    #endif
    """
    int omp_get_max_threads() noexcept nogil

#: Loops over fewer rows stay on one thread: a parallel region costs a time slice whenever another job
#: holds a core the team waits for. Chosen on the per-loop table of benchmarks/results/under_load.md
#: (two threads pay under 10% below 80k rows quiet and lose beside busy processes), scored on the whole
#: default call on a 40k raw scan in the same file; results do not depend on the thread count.
cdef enum:
    PARALLEL_ROWS = 65536


cdef inline int _threads(Py_ssize_t rows) noexcept nogil:
    return omp_get_max_threads() if rows >= PARALLEL_ROWS else 1


ctypedef fused index_t:
    int32_t
    int64_t

# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""One level of the volume-cost hierarchy (Liu et al. 2001, section 4.1) as a sequential loop.

The rules are stated in :mod:`o3d_lsmesh.hierarchy.collapse`; the plain-Python
oracle in ``tests/_hierarchy_oracle.py`` performs the same arithmetic in the
same order, so both give identical levels.
"""

import numpy as np

from libc.math cimport sqrt, fabs, INFINITY
from libc.stdint cimport int32_t, int64_t, uint8_t, uint64_t
from libc.stdlib cimport malloc, free
from libc.string cimport memset, memcpy

ctypedef int32_t idx


cdef void* _alloc(size_t size) except NULL:
    cdef void* p = malloc(size if size > 0 else 1)
    if p == NULL:
        raise MemoryError(f"the hierarchy kernel could not allocate {size} bytes")
    return p


cdef void _sort_candidates(const double* cost, idx* order, idx* scratch, uint64_t* keys, uint64_t* keys2,
                           Py_ssize_t count) noexcept nogil:
    """Stable LSD radix sort of ``order`` by ``cost`` (non-negative doubles: their bits sort as integers).

    ``order`` comes in increasing index order, so ties stay in index order.
    """
    cdef Py_ssize_t i, shift, pass_, total
    cdef Py_ssize_t[6][2048] hist
    cdef uint64_t key
    cdef idx* src = order
    cdef idx* dst = scratch
    cdef uint64_t* ksrc = keys
    cdef uint64_t* kdst = keys2
    cdef idx* tmp
    cdef uint64_t* ktmp
    memset(&hist[0][0], 0, sizeof(hist))
    for i in range(count):
        key = (<const uint64_t*> cost)[order[i]]
        keys[i] = key
        for pass_ in range(6):
            hist[pass_][(key >> (11 * pass_)) & 2047] += 1
    for pass_ in range(6):
        if hist[pass_][(keys[0] >> (11 * pass_)) & 2047] == count:
            continue  # every key has this digit: the pass would not move anything
        total = 0
        for i in range(2048):
            shift = hist[pass_][i]
            hist[pass_][i] = total
            total += shift
        for i in range(count):
            key = ksrc[i]
            shift = (key >> (11 * pass_)) & 2047
            dst[hist[pass_][shift]] = src[i]
            kdst[hist[pass_][shift]] = key
            hist[pass_][shift] += 1
        tmp = src
        src = dst
        dst = tmp
        ktmp = ksrc
        ksrc = kdst
        kdst = ktmp
    if src != order:
        memcpy(order, src, count * sizeof(idx))


cdef inline bint _geometry_ok(const double[:, ::1] V, const idx* pair, int64_t c0, int64_t c1, idx x, idx k,
                              double cos_sq, double min_quality) noexcept nogil:
    """No surviving triangle ``(x, a, b)`` of the star of ``x`` (corners ``c0:c1``) turns its normal by
    ``max_normal_angle`` or more, or falls to ``min_quality`` or less, when ``x`` moves onto ``k``."""
    cdef int64_t j
    cdef idx a, b
    cdef double ax, ay, az, bx, by, bz, nx, ny, nz, ox, oy, oz, dot, new_sq, old_sq, ex, ey, ez, squared
    for j in range(c0, c1):
        a = pair[2 * j]
        b = pair[2 * j + 1]
        if a == k or b == k:
            continue  # the triangle collapses with the edge
        ax = V[a, 0] - V[x, 0]
        ay = V[a, 1] - V[x, 1]
        az = V[a, 2] - V[x, 2]
        bx = V[b, 0] - V[x, 0]
        by = V[b, 1] - V[x, 1]
        bz = V[b, 2] - V[x, 2]
        ox = ay * bz - az * by
        oy = az * bx - ax * bz
        oz = ax * by - ay * bx
        ax = V[a, 0] - V[k, 0]
        ay = V[a, 1] - V[k, 1]
        az = V[a, 2] - V[k, 2]
        bx = V[b, 0] - V[k, 0]
        by = V[b, 1] - V[k, 1]
        bz = V[b, 2] - V[k, 2]
        nx = ay * bz - az * by
        ny = az * bx - ax * bz
        nz = ax * by - ay * bx
        dot = nx * ox + ny * oy + nz * oz
        if dot <= 0.0:
            return False  # flipped (or degenerate before or after)
        new_sq = nx * nx + ny * ny + nz * nz
        old_sq = ox * ox + oy * oy + oz * oz
        if dot * dot <= new_sq * cos_sq * old_sq:
            return False  # the normal turns by max_normal_angle or more
        ex = bx - ax
        ey = by - ay
        ez = bz - az
        squared = ax * ax + ay * ay + az * az + bx * bx + by * by + bz * bz + ex * ex + ey * ey + ez * ez
        squared *= min_quality
        if new_sq <= squared * squared:
            return False  # 2 * area / (sum of squared edge lengths) too small
    return True


cdef inline bint _link_ok(const idx* nb, const int64_t* vt_ptr, const int32_t* valence, idx x, idx k,
                          int edge_count) noexcept nogil:
    """Link condition: ``x`` and ``k`` share exactly the opposite vertices of their edge (sorted rings)."""
    cdef int64_t i = 2 * vt_ptr[x], i_end = 2 * vt_ptr[x] + valence[x]
    cdef int64_t j = 2 * vt_ptr[k], j_end = 2 * vt_ptr[k] + valence[k]
    cdef int common = 0
    while i < i_end and j < j_end:
        if nb[i] < nb[j]:
            i += 1
        elif nb[i] > nb[j]:
            j += 1
        else:
            common += 1
            i += 1
            j += 1
    return common == edge_count


cdef extern from *:
    """
    #if defined(__GNUC__) || defined(__clang__)
    #define O3D_LSMESH_PREFETCH(p) __builtin_prefetch(p)
    #else
    #define O3D_LSMESH_PREFETCH(p) ((void)0)
    #endif
    """
    void prefetch "O3D_LSMESH_PREFETCH"(const void* p) noexcept nogil


cdef class Workspace:
    """Buffers for the levels of one hierarchy, allocated for the first (largest) level and reused.

    Fresh memory costs page faults that take longer than the loop's arithmetic
    on it, so every level after the first runs in the same pages. Not shared
    between threads: each build makes its own.
    """

    cdef Py_ssize_t n_cap, m_cap, ring_cap
    cdef int64_t* corner_ptr  # corners of vertex v: corner_ptr[v]:corner_ptr[v + 1]
    cdef idx* pair  # the next and previous vertex of each corner's triangle, 2 per corner
    cdef idx* nb  # sorted 1-ring of v at nb[2 * corner_ptr[v]:][:valence[v]]
    cdef uint8_t* ec  # triangles on each ring edge (capped at 255)
    cdef int32_t* valence
    cdef uint8_t* flags  # 1 locked, 2 on the boundary, 4 in the closed 1-ring of a removal
    cdef double* cost
    cdef idx* order
    cdef idx* scratch
    cdef uint64_t* keys
    cdef uint64_t* keys2
    cdef idx* target
    cdef double* ring_vol
    cdef double* ring_len
    cdef uint8_t* ring_ok
    cdef idx* root

    def __dealloc__(self):
        self._release()

    cdef void _release(self) noexcept:
        free(self.corner_ptr); free(self.pair); free(self.nb); free(self.ec); free(self.valence); free(self.flags)
        free(self.cost); free(self.order); free(self.scratch); free(self.keys); free(self.keys2); free(self.target)
        free(self.ring_vol); free(self.ring_len); free(self.ring_ok); free(self.root)
        self.corner_ptr = NULL; self.pair = NULL; self.nb = NULL; self.ec = NULL; self.valence = NULL
        self.flags = NULL; self.cost = NULL; self.order = NULL; self.scratch = NULL; self.keys = NULL
        self.keys2 = NULL; self.target = NULL; self.ring_vol = NULL; self.ring_len = NULL; self.ring_ok = NULL
        self.root = NULL
        self.n_cap = self.m_cap = self.ring_cap = 0

    cdef int _reserve(self, Py_ssize_t n, Py_ssize_t m) except -1:
        if n <= self.n_cap and m <= self.m_cap:
            return 0
        self._release()
        self.corner_ptr = <int64_t*> _alloc((n + 1) * sizeof(int64_t))
        self.pair = <idx*> _alloc(6 * m * sizeof(idx))
        self.nb = <idx*> _alloc(6 * m * sizeof(idx))
        self.ec = <uint8_t*> _alloc(6 * m * sizeof(uint8_t))
        self.valence = <int32_t*> _alloc(n * sizeof(int32_t))
        self.flags = <uint8_t*> _alloc(n * sizeof(uint8_t))
        self.cost = <double*> _alloc(n * sizeof(double))
        self.order = <idx*> _alloc(n * sizeof(idx))
        self.scratch = <idx*> _alloc(n * sizeof(idx))
        self.keys = <uint64_t*> _alloc(n * sizeof(uint64_t))
        self.keys2 = <uint64_t*> _alloc(n * sizeof(uint64_t))
        self.target = <idx*> _alloc(n * sizeof(idx))
        self.n_cap, self.m_cap = n, m
        return 0

    cdef int _reserve_ring(self, Py_ssize_t size) except -1:
        if size <= self.ring_cap:
            return 0
        free(self.ring_vol); free(self.ring_len); free(self.ring_ok); free(self.root)
        self.ring_vol = self.ring_len = NULL
        self.ring_ok = NULL
        self.root = NULL
        self.ring_vol = <double*> _alloc(size * sizeof(double))
        self.ring_len = <double*> _alloc(size * sizeof(double))
        self.ring_ok = <uint8_t*> _alloc(size * sizeof(uint8_t))
        self.root = <idx*> _alloc(size * sizeof(idx))
        self.ring_cap = size
        return 0

    cdef int _rings(self, Py_ssize_t n, const int64_t[:, ::1] F, const uint8_t[::1] locked) except -1:
        """Corners of every vertex, sorted 1-rings with triangle counts per edge, flags.

        Returns the largest valence.
        """
        cdef Py_ssize_t m = F.shape[0], i
        cdef int64_t s, e, e0, e1, slot
        cdef idx t, v, u
        cdef int c, deg, max_valence = 0
        cdef int64_t* corner_ptr = self.corner_ptr
        cdef idx* pair = self.pair
        cdef idx* nb = self.nb
        cdef uint8_t* ec = self.ec
        cdef idx* fill = self.order
        with nogil:
            memset(corner_ptr, 0, (n + 1) * sizeof(int64_t))
            for t in range(m):
                for c in range(3):
                    corner_ptr[F[t, c] + 1] += 1
            for i in range(n):
                corner_ptr[i + 1] += corner_ptr[i]
                fill[i] = 0
            # each corner's next and previous vertex, to its vertex's slots (in triangle order)
            for t in range(m):
                for c in range(3):
                    v = <idx> F[t, c]
                    slot = corner_ptr[v] + fill[v]
                    fill[v] += 1
                    pair[2 * slot] = <idx> F[t, (c + 1) % 3]
                    pair[2 * slot + 1] = <idx> F[t, (c + 2) % 3]
            for v in range(n):
                s = 2 * corner_ptr[v]
                e = 2 * corner_ptr[v + 1]
                for e0 in range(s, e):  # insertion sort: rings are short
                    u = pair[e0]
                    e1 = e0
                    while e1 > s and nb[e1 - 1] > u:
                        nb[e1] = nb[e1 - 1]
                        e1 -= 1
                    nb[e1] = u
                deg = 0
                self.flags[v] = 1 if locked[v] else 0
                e0 = s
                while e0 < e:
                    e1 = e0
                    while e1 < e and nb[e1] == nb[e0]:
                        e1 += 1
                    nb[s + deg] = nb[e0]
                    ec[s + deg] = <uint8_t> (e1 - e0 if e1 - e0 < 255 else 255)
                    if e1 - e0 == 1:
                        self.flags[v] |= 2
                    elif e1 - e0 > 2:
                        self.flags[v] |= 1  # on an edge of more than two triangles
                    deg += 1
                    e0 = e1
                self.valence[v] = deg
                if deg > max_valence:
                    max_valence = deg
        return max_valence

    def locked_vertices(self, const int64_t[:, ::1] F, Py_ssize_t n):
        """``(n,) bool``: unreferenced vertices, vertices on an edge of more than two triangles, and vertices
        whose triangles form more than one fan (their links, over shared ring vertices, fall apart)."""
        cdef Py_ssize_t m = F.shape[0]
        cdef idx v, ra, rb
        cdef int64_t s, j
        cdef int deg, parts, max_valence
        _check_sizes(n, m)
        if m and (np.min(F) < 0 or np.max(F) >= n):
            raise ValueError(f"triangles must index vertices in [0, {n})")
        self._reserve(n, m)
        max_valence = self._rings(n, F, np.zeros(n, dtype=np.uint8))
        self._reserve_ring(max_valence)
        out = np.zeros(n, dtype=bool)
        cdef uint8_t[::1] locked = out.view(np.uint8)
        cdef idx* root = self.root
        with nogil:
            for v in range(n):
                deg = self.valence[v]
                if deg == 0 or self.flags[v] & 1:
                    locked[v] = 1
                    continue
                s = 2 * self.corner_ptr[v]
                for j in range(deg):
                    root[j] = <idx> j
                parts = deg
                for j in range(self.corner_ptr[v], self.corner_ptr[v + 1]):
                    ra = _position(self.nb, s, deg, self.pair[2 * j])
                    rb = _position(self.nb, s, deg, self.pair[2 * j + 1])
                    while root[ra] != ra:
                        ra = root[ra]
                    while root[rb] != rb:
                        rb = root[rb]
                    if ra != rb:
                        root[ra if ra > rb else rb] = ra if ra < rb else rb
                        parts -= 1
                if parts > 1:
                    locked[v] = 1
        return out

    def collapse_level(self, const double[:, ::1] V, const int64_t[:, ::1] F, const uint8_t[::1] locked,
                       double alpha, double beta, Py_ssize_t max_removals, double cos_sq, double min_quality,
                       int max_tries):
        """Select and apply one level; see :func:`o3d_lsmesh.hierarchy.collapse.collapse_level`.

        Returns ``(removed, targets, ring_offsets, ring, parent, triangles)`` or ``None``.
        """
        cdef Py_ssize_t n = V.shape[0], m = F.shape[0]
        cdef Py_ssize_t i, count, selected = 0, alive = 0, ring_total = 0
        cdef int64_t j, e, s
        cdef idx v, u, x, k, t, best
        cdef int c, attempt, deg, max_valence
        cdef double dx, dy, dz, length, lo, hi, best_vol, best_len, threshold, sx, sy, sz, ax, ay, az, bx, by, bz
        cdef idx a, b
        cdef int64_t[::1] removed, targets, offsets, parent, ring
        cdef int64_t[:, ::1] triangles
        _check_sizes(n, m)
        if locked.shape[0] != n:
            raise ValueError(f"locked must have one entry per vertex ({n}), got {locked.shape[0]}")
        self._reserve(n, m)
        max_valence = self._rings(n, F, locked)
        self._reserve_ring(max_valence)
        cdef int64_t* vt_ptr = self.corner_ptr
        cdef idx* pair = self.pair
        cdef idx* nb = self.nb
        cdef uint8_t* ec = self.ec
        cdef int32_t* valence = self.valence
        cdef uint8_t* flags = self.flags
        cdef double* cost = self.cost
        cdef idx* order = self.order
        cdef idx* target = self.target
        cdef double* ring_vol = self.ring_vol
        cdef double* ring_len = self.ring_len
        cdef uint8_t* ring_ok = self.ring_ok
        with nogil:
            # cost of section 4.1 and the candidates: unlocked vertices with neighbours
            count = 0
            for v in range(n):
                target[v] = -1
                if valence[v] == 0 or flags[v] & 1:
                    continue
                lo = INFINITY
                hi = 0.0
                s = 2 * vt_ptr[v]
                for e in range(s, s + valence[v]):
                    u = nb[e]
                    dx = V[u, 0] - V[v, 0]
                    dy = V[u, 1] - V[v, 1]
                    dz = V[u, 2] - V[v, 2]
                    length = sqrt(dx * dx + dy * dy + dz * dz)
                    if length < lo:
                        lo = length
                    if length > hi:
                        hi = length
                cost[v] = alpha * lo + beta * hi
                order[count] = v
                count += 1
            _sort_candidates(cost, order, self.scratch, self.keys, self.keys2, count)
            for i in range(count):
                if selected >= max_removals:
                    break
                if i + 16 < count:  # the visit goes in cost order, all over memory: ask for it early
                    prefetch(&flags[order[i + 16]])
                    prefetch(&vt_ptr[order[i + 16]])
                    prefetch(&valence[order[i + 16]])
                    prefetch(&V[order[i + 16], 0])
                if i + 8 < count:
                    prefetch(&nb[2 * vt_ptr[order[i + 8]]])
                    prefetch(&pair[2 * vt_ptr[order[i + 8]]])
                x = order[i]
                if flags[x] & 4:
                    continue
                # N_x: the summed normals of the triangles around x, from the corner of x
                sx = sy = sz = 0.0
                for e in range(vt_ptr[x], vt_ptr[x + 1]):
                    a = pair[2 * e]
                    b = pair[2 * e + 1]
                    ax = V[a, 0] - V[x, 0]
                    ay = V[a, 1] - V[x, 1]
                    az = V[a, 2] - V[x, 2]
                    bx = V[b, 0] - V[x, 0]
                    by = V[b, 1] - V[x, 1]
                    bz = V[b, 2] - V[x, 2]
                    sx += ay * bz - az * by
                    sy += az * bx - ax * bz
                    sz += ax * by - ay * bx
                # the allowed edges of x with their cone volume |N_x . (x_k - x)| and length
                s = 2 * vt_ptr[x]
                deg = valence[x]
                for e in range(deg):
                    k = nb[s + e]
                    c = ec[s + e]
                    ring_ok[e] = not (flags[k] & 1)
                    if flags[x] & 2:
                        ring_ok[e] = ring_ok[e] and c == 1  # along the boundary
                        if deg == 2 and valence[k] == 2 and flags[k] & 2:
                            ring_ok[e] = False  # an isolated triangle
                    else:
                        ring_ok[e] = ring_ok[e] and c == 2
                        if deg == 3 and valence[k] == 3 and not (flags[k] & 2):
                            ring_ok[e] = False  # a closed tetrahedron
                    dx = V[k, 0] - V[x, 0]
                    dy = V[k, 1] - V[x, 1]
                    dz = V[k, 2] - V[x, 2]
                    ring_len[e] = sqrt(dx * dx + dy * dy + dz * dz)
                    ring_vol[e] = fabs(sx * dx + sy * dy + sz * dz)
                best = -1
                for attempt in range(max_tries):
                    # least volume (within a relative 1e-9), then shortest edge, then first
                    best_vol = INFINITY
                    for e in range(deg):
                        if ring_ok[e] and ring_vol[e] < best_vol:
                            best_vol = ring_vol[e]
                    if best_vol == INFINITY:
                        break
                    threshold = best_vol * (1.0 + 1e-9)
                    best_len = INFINITY
                    for e in range(deg):
                        if ring_ok[e] and ring_vol[e] <= threshold and ring_len[e] < best_len:
                            best_len = ring_len[e]
                            best = <idx> e
                    k = nb[s + best]
                    if (_geometry_ok(V, pair, vt_ptr[x], vt_ptr[x + 1], x, k, cos_sq, min_quality)
                            and _link_ok(nb, vt_ptr, valence, x, k, ec[s + best])):
                        break
                    ring_ok[best] = False
                    best = -1
                if best < 0:
                    continue
                k = nb[s + best]
                if flags[k] & 4:
                    continue  # its target is in the closed 1-ring of an earlier removal
                target[x] = k
                selected += 1
                flags[x] |= 4
                for e in range(s, s + deg):
                    flags[nb[e]] |= 4
        if selected == 0:
            return None

        removed_a = np.zeros(selected, dtype=np.int64)
        targets_a = np.zeros(selected, dtype=np.int64)
        offsets_a = np.zeros(selected + 1, dtype=np.int64)
        parent_a = np.zeros(n, dtype=np.int64)
        removed, targets, offsets, parent = removed_a, targets_a, offsets_a, parent_a
        with nogil:
            count = 0
            j = 0
            for v in range(n):
                if target[v] >= 0:
                    removed[count] = v
                    targets[count] = target[v]
                    ring_total += valence[v]
                    count += 1
                    offsets[count] = ring_total
                else:
                    parent[v] = j
                    j += 1
            for i in range(selected):
                parent[removed[i]] = parent[targets[i]]
            for t in range(m):
                if (parent[F[t, 0]] != parent[F[t, 1]] and parent[F[t, 1]] != parent[F[t, 2]]
                        and parent[F[t, 2]] != parent[F[t, 0]]):
                    alive += 1
        ring_a = np.zeros(ring_total, dtype=np.int64)
        triangles_a = np.zeros((alive, 3), dtype=np.int64)
        ring, triangles = ring_a, triangles_a
        with nogil:
            j = 0
            for i in range(selected):
                v = <idx> removed[i]
                s = 2 * vt_ptr[v]
                for e in range(s, s + valence[v]):
                    ring[j] = nb[e]
                    j += 1
            j = 0
            for t in range(m):
                if (parent[F[t, 0]] != parent[F[t, 1]] and parent[F[t, 1]] != parent[F[t, 2]]
                        and parent[F[t, 2]] != parent[F[t, 0]]):
                    for c in range(3):
                        triangles[j, c] = parent[F[t, c]]
                    j += 1
        return removed_a, targets_a, offsets_a, ring_a, parent_a, triangles_a


cdef inline idx _position(const idx* nb, int64_t s, int deg, idx value) noexcept nogil:
    """Index of ``value`` in the sorted ring ``nb[s:s + deg]`` (it is there)."""
    cdef int lo = 0, hi = deg - 1, mid
    while lo < hi:
        mid = (lo + hi) // 2
        if nb[s + mid] < value:
            lo = mid + 1
        else:
            hi = mid
    return <idx> lo


def _check_sizes(Py_ssize_t n, Py_ssize_t m):
    if n >= 2 ** 31 - 1 or 3 * m >= 2 ** 31 - 1:
        raise ValueError(f"mesh must have fewer than 2**31 vertices and 2**31 / 3 triangles, got {n} and {m}")

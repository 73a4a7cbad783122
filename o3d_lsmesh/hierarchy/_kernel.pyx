# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""The volume-cost hierarchy as one sequential loop, shaped like OpenMesh's ``DecimaterT`` (rules:
:mod:`o3d_lsmesh.hierarchy.collapse`). ``tests/_hierarchy_oracle.py`` does the same floating-point operations
in the same order, so the levels are identical."""

import numpy as np

from libc.math cimport INFINITY, fabs, sqrt
from libc.stdint cimport int32_t, int64_t, uint8_t, uint64_t
from libc.string cimport memcpy, memset

cdef enum:
    LOCKED = 1
    BOUNDARY = 2
    TOUCHED = 4  # in the closed 1-ring of a vertex removed in this level

cdef struct Vertex:  # together, so that a visit's random reads of a neighbour hit one cache line
    int32_t start, corners, valence, flags  # corners start:start + corners; ring ring[2 * start:][:valence]

cdef extern from *:
    "#if defined(__GNUC__) || defined(__clang__)\n#define PREFETCH(p) __builtin_prefetch(p)\n#else\n#define PREFETCH(p) ((void)0)\n#endif"
    void prefetch "PREFETCH"(const void* p) noexcept nogil


cdef void _sort(int32_t* order, int32_t* spare, uint64_t* key, uint64_t* key2, Py_ssize_t count) noexcept nogil:
    """Stable LSD radix sort of ``order`` by ``key``, bits of non-negative doubles: ties stay in index order."""
    cdef Py_ssize_t hist[2048]
    cdef Py_ssize_t i, d, total
    cdef int p
    for p in range(0, 66, 11):
        memset(hist, 0, sizeof(hist))
        for i in range(count):
            hist[(key[i] >> p) & 2047] += 1
        if hist[(key[0] >> p) & 2047] < count:  # else every key has this digit (key has a spare slot)
            total = 0
            for d in range(2048):
                total, hist[d] = total + hist[d], total
            for i in range(count):
                d = (key[i] >> p) & 2047
                spare[hist[d]], key2[hist[d]], hist[d] = order[i], key[i], hist[d] + 1
            memcpy(order, spare, count * sizeof(int32_t))
            memcpy(key, key2, count * sizeof(uint64_t))


cdef bint _legal(const double* P, const Vertex* V, const int32_t* pair, const int32_t* ring, const uint8_t* count,
                 int32_t x, int32_t e, double cos_sq, double min_quality) noexcept nogil:
    """Whether ``x`` may collapse into its ring slot ``e`` (the geometric rules, then the link condition)."""
    cdef int32_t k = ring[2 * V[x].start + e], i = 2 * V[x].start, l = 2 * V[k].start, j, c, common = 0
    cdef double[3] o, n, u, w
    cdef double dot, new_sq
    for j in range(2 * V[x].start, 2 * (V[x].start + V[x].corners), 2):
        if pair[j] == k or pair[j + 1] == k:
            continue  # the triangle collapses with the edge
        for c in range(3):
            u[c], w[c] = P[3 * pair[j] + c] - P[3 * x + c], P[3 * pair[j + 1] + c] - P[3 * x + c]
        o[0], o[1], o[2] = u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]
        for c in range(3):
            u[c], w[c] = P[3 * pair[j] + c] - P[3 * k + c], P[3 * pair[j + 1] + c] - P[3 * k + c]
        n[0], n[1], n[2] = u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]
        dot, new_sq = n[0] * o[0] + n[1] * o[1] + n[2] * o[2], n[0] * n[0] + n[1] * n[1] + n[2] * n[2]
        if dot <= 0.0 or dot * dot <= new_sq * cos_sq * (o[0] * o[0] + o[1] * o[1] + o[2] * o[2]):
            return False  # flipped (or degenerate), or turned by max_normal_angle or more
        o[0], o[1], o[2] = w[0] - u[0], w[1] - u[1], w[2] - u[2]
        dot = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2] + w[0] * w[0] + w[1] * w[1] + w[2] * w[2] + o[0] * o[0]
               + o[1] * o[1] + o[2] * o[2]) * min_quality
        if new_sq <= dot * dot:
            return False  # 2 * area / (sum of squared edge lengths) at most min_quality
    while i < 2 * V[x].start + V[x].valence and l < 2 * V[k].start + V[k].valence:  # merge the sorted rings
        common, c = common + (ring[i] == ring[l]), ring[i] <= ring[l]
        l += ring[l] <= ring[i]
        i += c
    return common == count[2 * V[x].start + e]  # link condition: only the edge's opposite vertices in common


def hierarchy(double[:, ::1] positions, const int64_t[:, ::1] triangles, uint8_t[::1] lock, double alpha,
              double beta, Py_ssize_t min_vertices, Py_ssize_t max_levels, double cos_sq, double min_quality,
              int max_tries, bint lock_fans, report):
    """:func:`o3d_lsmesh.hierarchy.collapse.collapse_levels`; compacts ``positions`` and ``lock`` in place."""
    cdef Py_ssize_t n = positions.shape[0], m = triangles.shape[0], i, count, selected, alive, total
    if n >= 2 ** 31 - 1 or 6 * m >= 2 ** 31 - 1:
        raise ValueError(f"mesh must have fewer than 2**31 vertices and 2**31 / 6 triangles, got {n} and {m}")
    # np.empty: every slot is written before it is read, and freed heap memory is reused without zeroing
    vertex_a, pair_a, ring_a = np.empty((n + 1, 4), np.int32), np.empty(6 * m, np.int32), np.empty(6 * m, np.int32)
    mult_a, key_a, order_a = np.empty(6 * m, np.uint8), np.zeros((2, n + 1), np.uint64), np.empty((3, n + 1), np.int32)
    kept_a = np.arange(n, dtype=np.int64)
    cdef int32_t[:, ::1] vertex = vertex_a, order = order_a  # order: candidates, sort spare, targets
    cdef int32_t[::1] pair = pair_a, ring = ring_a, root
    cdef uint8_t[::1] mult = mult_a  # triangles on each ring edge (at most 255 counted)
    cdef int64_t[::1] kept = kept_a, removed, target, offsets, flat, parent
    cdef uint64_t[:, ::1] key = key_a
    cdef const int64_t[:, ::1] T = triangles
    cdef int64_t[:, ::1] out
    cdef double[:, ::1] edge  # volume, length, allowed of each ring edge of the visited vertex
    cdef Vertex* V = <Vertex*> &vertex[0, 0]
    cdef int32_t* goal = &order[2, 0]
    cdef double* p = &positions[0, 0] if n else NULL
    cdef int32_t v, u, x, k, best, j, s, r, c, e, deg, attempt, max_valence
    cdef double dx, dy, dz, d, lo, hi, sx, sy, sz, least
    levels = []
    while True:
        m = T.shape[0]
        with nogil:  # corners (next and previous vertex of each triangle of a vertex), sorted unique 1-rings
            memset(V, 0, n * sizeof(Vertex))
            for i in range(3 * m):
                V[T[i // 3, i % 3]].corners += 1
            for v in range(1, n):
                V[v].start = V[v - 1].start + V[v - 1].corners
            for i in range(3 * m):
                v, c, j = T[i // 3, i % 3], i % 3, 2 * (V[T[i // 3, i % 3]].start + V[T[i // 3, i % 3]].valence)
                pair[j], pair[j + 1], V[v].valence = T[i // 3, (c + 1) % 3], T[i // 3, (c + 2) % 3], V[v].valence + 1
            max_valence = 0
            for v in range(n):
                s, deg, V[v].flags = 2 * V[v].start, 0, lock[v]
                for j in range(s, s + 2 * V[v].corners):  # insertion into the sorted unique ring: rings are short
                    r = s + deg
                    while r > s and ring[r - 1] > pair[j]:
                        r -= 1
                    if r > s and ring[r - 1] == pair[j]:
                        mult[r - 1] += mult[r - 1] < 255
                    else:
                        for c in range(s + deg, r, -1):
                            ring[c], mult[c] = ring[c - 1], mult[c - 1]
                        ring[r], mult[r], deg = pair[j], 1, deg + 1
                for j in range(s, s + deg):
                    V[v].flags |= BOUNDARY if mult[j] == 1 else (LOCKED if mult[j] > 2 else 0)
                V[v].valence, max_valence = deg, max(max_valence, deg)
        edge, root = np.zeros((3, max_valence)), np.zeros(max_valence, np.int32)
        if lock_fans and not levels:  # also lock unreferenced vertices and those whose corners form several fans
            with nogil:
                for v in range(n):
                    s, deg = 2 * V[v].start, V[v].valence
                    for e in range(deg):
                        root[e] = e
                    for j in range(s, s + 2 * V[v].corners, 2):  # union-find of ring slots joined by a corner
                        r, e = 0, 0
                        while ring[s + r] != pair[j]: r += 1
                        while ring[s + e] != pair[j + 1]: e += 1
                        while root[r] != r: r = root[r]
                        while root[e] != e: e = root[e]
                        root[max(r, e)], deg = min(r, e), deg - (r != e)
                    if V[v].valence == 0 or deg > 1 or V[v].flags & LOCKED:
                        lock[v], V[v].flags = 1, V[v].flags | LOCKED
        if not levels:
            first = np.array(lock, dtype=bool)
        if len(levels) == max_levels or n <= min_vertices:
            return first, levels
        with nogil:
            count = selected = total = 0  # candidates: unlocked vertices with neighbours, by cost (section 4.1)
            for v in range(n):
                goal[v] = -1
                if V[v].valence and not V[v].flags & LOCKED:
                    lo, hi = INFINITY, 0.0
                    for j in range(2 * V[v].start, 2 * V[v].start + V[v].valence):
                        u = ring[j]
                        dx, dy, dz = p[3 * u] - p[3 * v], p[3 * u + 1] - p[3 * v + 1], p[3 * u + 2] - p[3 * v + 2]
                        d = sqrt(dx * dx + dy * dy + dz * dz)
                        lo, hi = min(lo, d), max(hi, d)
                    d = alpha * lo + beta * hi
                    memcpy(&key[0, count], &d, sizeof(double))
                    order[0, count], count = v, count + 1
            _sort(&order[0, 0], &order[1, 0], &key[0, 0], &key[1, 0], count)
            for i in range(count):
                if selected >= n - min_vertices:
                    break
                x = order[0, i + 16 if i + 16 < count else i]  # the visit goes all over memory: ask early
                prefetch(&V[x]); prefetch(&p[3 * x])
                x = order[0, i + 8 if i + 8 < count else i]
                prefetch(&ring[2 * V[x].start]); prefetch(&pair[2 * V[x].start])
                x = order[0, i + 4 if i + 4 < count else i]  # its ring arrived: its neighbours' flags and positions
                for j in range(2 * V[x].start, 2 * V[x].start + V[x].valence):
                    prefetch(&V[ring[j]]); prefetch(&p[3 * ring[j]])
                x = order[0, i + 2 if i + 2 < count else i]  # the neighbours' rings, one of which the link check reads
                for j in range(2 * V[x].start, 2 * V[x].start + V[x].valence):
                    prefetch(&ring[2 * V[ring[j]].start])
                x, sx, sy, sz, best = order[0, i], 0.0, 0.0, 0.0, -1
                if V[x].flags & TOUCHED:
                    continue  # the independence rule
                for j in range(2 * V[x].start, 2 * (V[x].start + V[x].corners), 2):  # N_x, summed normals
                    u, v = pair[j], pair[j + 1]
                    dx, dy, dz = p[3 * u] - p[3 * x], p[3 * u + 1] - p[3 * x + 1], p[3 * u + 2] - p[3 * x + 2]
                    lo, hi, d = p[3 * v] - p[3 * x], p[3 * v + 1] - p[3 * x + 1], p[3 * v + 2] - p[3 * x + 2]
                    sx, sy, sz = sx + (dy * d - dz * hi), sy + (dz * lo - dx * d), sz + (dx * hi - dy * lo)
                s, deg = 2 * V[x].start, V[x].valence
                for e in range(deg):  # allowed edges with their cone volume |N_x . (x_k - x)| and length
                    k = ring[s + e]  # k unlocked; a boundary x along the boundary; no lone triangle or tetrahedron
                    edge[2, e] = not V[k].flags & LOCKED and (mult[s + e] == 1 or not V[x].flags & BOUNDARY) and not (
                        deg == (2 if V[x].flags & BOUNDARY else 3) == V[k].valence
                        and (V[k].flags & BOUNDARY) == (V[x].flags & BOUNDARY))
                    dx, dy, dz = p[3 * k] - p[3 * x], p[3 * k + 1] - p[3 * x + 1], p[3 * k + 2] - p[3 * x + 2]
                    edge[1, e], edge[0, e] = sqrt(dx * dx + dy * dy + dz * dz), fabs(sx * dx + sy * dy + sz * dz)
                for attempt in range(max_tries):  # least volume (within 1e-9), then shortest, then first
                    best, least, d = -1, INFINITY, INFINITY
                    for e in range(deg):
                        if edge[2, e] and edge[0, e] < least:
                            least = edge[0, e]
                    for e in range(deg):
                        if edge[2, e] and edge[0, e] <= least * (1.0 + 1e-9) and edge[1, e] < d:
                            d, best = edge[1, e], e
                    if best < 0 or _legal(p, V, &pair[0], &ring[0], &mult[0], x, best, cos_sq, min_quality):
                        break
                    edge[2, best], best = 0, -1
                if best >= 0 and not V[ring[s + best]].flags & TOUCHED:  # its target, too, must be untouched
                    goal[x], selected, total, V[x].flags = ring[s + best], selected + 1, total + deg, V[x].flags | TOUCHED
                    for j in range(s, s + deg):
                        V[ring[j]].flags |= TOUCHED
        if selected == 0:
            return first, levels
        level = [np.empty(selected, np.int64), np.empty(selected, np.int64), np.empty(selected + 1, np.int64),
                 np.empty(total, np.int64), np.empty(n, np.int64), np.empty((m, 3), np.int64)]
        removed, target, offsets, flat, parent, out = level
        with nogil:  # apply: the parent map, the removed 1-rings, the triangles with three distinct vertices
            i = j = total = alive = offsets[0] = 0
            for v in range(n):
                if goal[v] >= 0:
                    removed[i], target[i] = v, goal[v]
                    for e in range(2 * V[v].start, 2 * V[v].start + V[v].valence):
                        flat[total], total = ring[e], total + 1
                    offsets[i + 1], i = total, i + 1
                else:
                    parent[v], p[3 * j], p[3 * j + 1], p[3 * j + 2] = j, p[3 * v], p[3 * v + 1], p[3 * v + 2]
                    lock[j], kept[j], j = lock[v], kept[v], j + 1
            for i in range(selected):
                parent[removed[i]] = parent[target[i]]
            for i in range(m):
                out[alive, 0], out[alive, 1], out[alive, 2] = parent[T[i, 0]], parent[T[i, 1]], parent[T[i, 2]]
                alive += out[alive, 0] != out[alive, 1] != out[alive, 2] != out[alive, 0]
        out = None  # let go of the buffer, then cut it to the triangles kept (pages never written cost nothing)
        level[5].resize((alive, 3), refcheck=False)
        n, T = n - selected, level[5]
        levels.append((*level, kept_a[:n].copy()))
        report(selected)

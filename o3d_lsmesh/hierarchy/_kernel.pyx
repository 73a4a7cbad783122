# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""The volume-cost hierarchy as one sequential loop, shaped like OpenMesh's ``DecimaterT``: per level, corners
and sorted 1-rings, candidates in cost order, the independence rule, the legality checks, apply, compact.
Rules: :mod:`o3d_lsmesh.hierarchy.collapse`; ``tests/_hierarchy_oracle.py`` does the same floating-point
operations in the same order, so the levels are identical."""

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


cdef void _radix_sort(int32_t* order, int32_t* spare, uint64_t* key, uint64_t* key2, Py_ssize_t count) noexcept nogil:
    """Stable LSD sort of ``order`` by ``key``, the bits of non-negative doubles: ties stay in index order."""
    cdef Py_ssize_t hist[2048]
    cdef Py_ssize_t i, d, total, h
    cdef int p
    for p in range(0, 66, 11):
        memset(hist, 0, sizeof(hist))
        for i in range(count):
            hist[(key[i] >> p) & 2047] += 1
        if count == 0 or hist[(key[0] >> p) & 2047] == count:
            continue  # every key has this digit
        total = 0
        for d in range(2048):
            total, hist[d] = total + hist[d], total
        for i in range(count):
            d = (key[i] >> p) & 2047
            spare[hist[d]], key2[hist[d]] = order[i], key[i]
            hist[d] += 1
        memcpy(order, spare, count * sizeof(int32_t))
        memcpy(key, key2, count * sizeof(uint64_t))


cdef bint _legal(const double* P, const Vertex* V, const int32_t* pair, const int32_t* ring, const uint8_t* count,
                 int32_t x, int32_t e, double cos_sq, double min_quality) noexcept nogil:
    """Whether collapsing ``x`` into its ring slot ``e`` keeps every surviving triangle of the star of ``x``
    unflipped, turning by less than ``max_normal_angle`` and above ``min_quality``, and the link condition."""
    cdef int32_t k = ring[2 * V[x].start + e], i = 2 * V[x].start, l = 2 * V[k].start, j, c, common = 0
    cdef const double* a
    cdef const double* b
    cdef double o[3]
    cdef double n[3]
    cdef double u[3]
    cdef double w[3]
    cdef double dot, new_sq, squared
    for j in range(V[x].start, V[x].start + V[x].corners):
        if pair[2 * j] == k or pair[2 * j + 1] == k:
            continue  # the triangle collapses with the edge
        a, b = &P[3 * pair[2 * j]], &P[3 * pair[2 * j + 1]]
        for c in range(3):
            u[c], w[c] = a[c] - P[3 * x + c], b[c] - P[3 * x + c]
        o[0], o[1], o[2] = u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]
        for c in range(3):
            u[c], w[c] = a[c] - P[3 * k + c], b[c] - P[3 * k + c]
        n[0], n[1], n[2] = u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]
        dot = n[0] * o[0] + n[1] * o[1] + n[2] * o[2]
        if dot <= 0.0:
            return False  # flipped (or degenerate before or after)
        new_sq = n[0] * n[0] + n[1] * n[1] + n[2] * n[2]
        if dot * dot <= new_sq * cos_sq * (o[0] * o[0] + o[1] * o[1] + o[2] * o[2]):
            return False  # the normal turns by max_normal_angle or more
        o[0], o[1], o[2] = w[0] - u[0], w[1] - u[1], w[2] - u[2]
        squared = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2] + w[0] * w[0] + w[1] * w[1] + w[2] * w[2]
                   + o[0] * o[0] + o[1] * o[1] + o[2] * o[2]) * min_quality
        if new_sq <= squared * squared:
            return False  # 2 * area / (sum of squared edge lengths) too small
    while i < 2 * V[x].start + V[x].valence and l < 2 * V[k].start + V[k].valence:  # merge the sorted rings
        common += ring[i] == ring[l]
        c = ring[i] <= ring[l]
        l += ring[l] <= ring[i]
        i += c
    return common == count[2 * V[x].start + e]  # link condition: only the edge's opposite vertices in common


def hierarchy(double[:, ::1] positions, const int64_t[:, ::1] triangles, uint8_t[::1] lock, double alpha,
              double beta, Py_ssize_t min_vertices, Py_ssize_t max_levels, double cos_sq, double min_quality,
              int max_tries, bint lock_fans, report=None):
    """See :func:`o3d_lsmesh.hierarchy.collapse.collapse_levels`; ``positions`` and ``lock`` are compacted in
    place. Returns level 0's lock and ``(removed, targets, ring_offsets, ring, parent, triangles, kept)``s."""
    cdef Py_ssize_t n = positions.shape[0], m = triangles.shape[0], i, cnt, selected, alive, total
    if n >= 2 ** 31 - 1 or 6 * m >= 2 ** 31 - 1:
        raise ValueError(f"mesh must have fewer than 2**31 vertices and 2**31 / 6 triangles, got {n} and {m}")
    vertex_a, pair_a, ring_a = np.zeros((n, 4), np.int32), np.zeros(6 * m, np.int32), np.zeros(6 * m, np.int32)
    count_a, kept_a, key_a = np.zeros(6 * m, np.uint8), np.arange(n, dtype=np.int64), np.zeros((2, n), np.uint64)
    order_a = np.zeros((3, n), np.int32)  # candidates, sort spare, then targets
    cdef int32_t[:, ::1] vertex = vertex_a
    cdef Vertex* V = <Vertex*> &vertex[0, 0] if n else NULL
    cdef int32_t[::1] pair = pair_a, ring = ring_a
    cdef int32_t[:, ::1] order = order_a
    cdef uint8_t[::1] count = count_a
    cdef int64_t[::1] kept = kept_a, removed, target, offsets, flat, parent
    cdef uint64_t[:, ::1] key = key_a
    cdef const int64_t[:, ::1] T = triangles
    cdef int64_t[:, ::1] out
    cdef double[:, ::1] vol
    cdef int32_t[::1] root
    cdef int32_t* goal = &order[2, 0] if n else NULL
    cdef int32_t v, u, x, k, best, j, s, r, c, e, deg, attempt, max_valence, parts
    cdef double dx, dy, dz, d, lo, hi, sx, sy, sz, least, shortest
    cdef double* p = &positions[0, 0] if n else NULL
    levels = []
    while True:
        m = T.shape[0]
        with nogil:  # corners of each vertex (next and previous vertex of its triangles), sorted 1-rings
            memset(V, 0, n * sizeof(Vertex))
            for i in range(3 * m):
                V[T[i // 3, i % 3]].corners += 1
            for v in range(1, n):
                V[v].start = V[v - 1].start + V[v - 1].corners
            for i in range(3 * m):
                v, c = <int32_t> T[i // 3, i % 3], i % 3
                j = V[v].start + V[v].valence  # valence counts the corners placed so far
                V[v].valence += 1
                pair[2 * j], pair[2 * j + 1] = <int32_t> T[i // 3, (c + 1) % 3], <int32_t> T[i // 3, (c + 2) % 3]
            max_valence = 0
            for v in range(n):
                s, deg, V[v].flags = 2 * V[v].start, 0, lock[v]
                for j in range(s, s + 2 * V[v].corners):  # insertion sort: rings are short
                    u, r = pair[j], j
                    while r > s and ring[r - 1] > u:
                        ring[r], r = ring[r - 1], r - 1
                    ring[r] = u
                j = s
                while j < s + 2 * V[v].corners:  # unique, with the triangle count of each ring edge
                    r = j
                    while r < s + 2 * V[v].corners and ring[r] == ring[j]:
                        r += 1
                    ring[s + deg], count[s + deg] = ring[j], <uint8_t> min(r - j, 255)
                    V[v].flags |= BOUNDARY if r - j == 1 else (LOCKED if r - j > 2 else 0)
                    deg, j = deg + 1, r
                V[v].valence, max_valence = deg, max(max_valence, deg)
        vol, root = np.zeros((3, max_valence)), np.zeros(max_valence, np.int32)  # volume, length, allowed
        if lock_fans:  # level 0: also lock unreferenced vertices and those whose corners form several fans
            with nogil:
                for v in range(n):
                    s, deg, parts = 2 * V[v].start, V[v].valence, V[v].valence
                    for e in range(deg):
                        root[e] = e
                    for j in range(V[v].start, V[v].start + V[v].corners):  # union-find of the corner pairs
                        r = 0
                        while ring[s + r] != pair[2 * j]:
                            r += 1
                        e = 0
                        while ring[s + e] != pair[2 * j + 1]:
                            e += 1
                        while root[r] != r:
                            r = root[r]
                        while root[e] != e:
                            e = root[e]
                        if r != e:
                            root[max(r, e)], parts = min(r, e), parts - 1
                    if deg == 0 or parts > 1 or V[v].flags & LOCKED:
                        lock[v], V[v].flags = 1, V[v].flags | LOCKED
            lock_fans = False
        if not levels:
            first = np.array(lock, dtype=bool)  # level 0's lock
        if len(levels) == max_levels or n <= min_vertices:
            break
        with nogil:
            cnt = 0  # candidates: unlocked vertices with neighbours, by cost of section 4.1
            for v in range(n):
                goal[v] = -1
                if V[v].valence == 0 or V[v].flags & LOCKED:
                    continue
                lo, hi, s = INFINITY, 0.0, 2 * V[v].start
                for j in range(s, s + V[v].valence):
                    u = ring[j]
                    dx, dy, dz = p[3 * u] - p[3 * v], p[3 * u + 1] - p[3 * v + 1], p[3 * u + 2] - p[3 * v + 2]
                    d = sqrt(dx * dx + dy * dy + dz * dz)
                    lo, hi = min(lo, d), max(hi, d)
                d = alpha * lo + beta * hi
                memcpy(&key[0, cnt], &d, sizeof(double))
                order[0, cnt], cnt = v, cnt + 1
            _radix_sort(&order[0, 0], &order[1, 0], &key[0, 0], &key[1, 0], cnt)
            selected = total = 0
            for i in range(cnt):
                if selected >= n - min_vertices:
                    break
                if i + 16 < cnt:  # the visit goes all over memory: ask for it early
                    prefetch(&V[order[0, i + 16]]); prefetch(&p[3 * order[0, i + 16]])
                if i + 8 < cnt:
                    prefetch(&ring[2 * V[order[0, i + 8]].start]); prefetch(&pair[2 * V[order[0, i + 8]].start])
                x = order[0, i]
                if V[x].flags & TOUCHED:
                    continue  # the independence rule
                sx = sy = sz = 0.0  # N_x: the summed (doubled-area) normals of the triangles around x
                for j in range(V[x].start, V[x].start + V[x].corners):
                    u, v = pair[2 * j], pair[2 * j + 1]
                    dx, dy, dz = p[3 * u] - p[3 * x], p[3 * u + 1] - p[3 * x + 1], p[3 * u + 2] - p[3 * x + 2]
                    lo, hi, d = p[3 * v] - p[3 * x], p[3 * v + 1] - p[3 * x + 1], p[3 * v + 2] - p[3 * x + 2]
                    sx += dy * d - dz * hi
                    sy += dz * lo - dx * d
                    sz += dx * hi - dy * lo
                s, deg = 2 * V[x].start, V[x].valence
                for e in range(deg):  # allowed edges with their cone volume |N_x . (x_k - x)| and length
                    k, c = ring[s + e], count[s + e]
                    # (an interior x has only 2-triangle edges: a 1 makes it boundary, a 3 locks it)
                    vol[2, e] = not (V[k].flags & LOCKED) and (c == 1 or not (V[x].flags & BOUNDARY))
                    if deg == (2 if V[x].flags & BOUNDARY else 3) == V[k].valence and (
                            (V[k].flags & BOUNDARY) == (V[x].flags & BOUNDARY)):
                        vol[2, e] = 0  # an isolated triangle or a closed tetrahedron would remain
                    dx, dy, dz = p[3 * k] - p[3 * x], p[3 * k + 1] - p[3 * x + 1], p[3 * k + 2] - p[3 * x + 2]
                    vol[1, e], vol[0, e] = sqrt(dx * dx + dy * dy + dz * dz), fabs(sx * dx + sy * dy + sz * dz)
                best = -1
                for attempt in range(max_tries):  # least volume (within 1e-9), then shortest, then first
                    least = INFINITY
                    for e in range(deg):
                        if vol[2, e] and vol[0, e] < least:
                            least = vol[0, e]
                    if least == INFINITY:
                        break
                    least, shortest = least * (1.0 + 1e-9), INFINITY
                    for e in range(deg):
                        if vol[2, e] and vol[0, e] <= least and vol[1, e] < shortest:
                            shortest, best = vol[1, e], e
                    if _legal(p, V, &pair[0], &ring[0], &count[0], x, best, cos_sq, min_quality):
                        break
                    vol[2, best], best = 0, -1
                if best < 0 or V[ring[s + best]].flags & TOUCHED:
                    continue  # no legal target, or it is in the closed 1-ring of an earlier removal
                goal[x], selected, total, V[x].flags = ring[s + best], selected + 1, total + deg, V[x].flags | TOUCHED
                for j in range(s, s + deg):
                    V[ring[j]].flags |= TOUCHED
        if selected == 0:
            break
        level = [np.zeros(selected, np.int64), np.zeros(selected, np.int64), np.zeros(selected + 1, np.int64)]
        level += [np.zeros(total, np.int64), np.zeros(n, np.int64)]
        level.append(np.empty((m, 3), np.int64))  # cut to the surviving triangles below (untouched pages are free)
        removed, target, offsets, flat, parent, out = level
        with nogil:  # apply: parent map, rings, the triangles that keep three distinct vertices
            i = j = total = alive = 0
            for v in range(n):
                if goal[v] >= 0:
                    removed[i], target[i] = v, goal[v]
                    for e in range(V[v].valence):
                        flat[total + e] = ring[2 * V[v].start + e]
                    i, total = i + 1, total + V[v].valence
                    offsets[i] = total
                else:
                    parent[v], p[3 * j], p[3 * j + 1], p[3 * j + 2] = j, p[3 * v], p[3 * v + 1], p[3 * v + 2]
                    lock[j], kept[j], j = lock[v], kept[v], j + 1
            for i in range(selected):
                parent[removed[i]] = parent[target[i]]
            for i in range(m):
                out[alive, 0], out[alive, 1], out[alive, 2] = parent[T[i, 0]], parent[T[i, 1]], parent[T[i, 2]]
                alive += out[alive, 0] != out[alive, 1] and out[alive, 1] != out[alive, 2] and out[alive, 2] != out[alive, 0]
        out = None  # let go of the buffer, to cut it
        level[5].resize((alive, 3), refcheck=False)
        n, T = n - selected, level[5]
        levels.append((*level, kept_a[:n].copy()))
        if report is not None:
            report(selected)
    return first, levels

# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Levels of the volume-cost hierarchy (Liu et al. 2001, section 4.1): one sequential loop, like OpenMesh's
``DecimaterT``; ``tests/_hierarchy_oracle.py`` is this loop in plain Python (same arithmetic, same levels).
The visiting order, the targets' rules and the locked vertices: ``docs/algorithms/mesh_hierarchy.rst``.
"""

import numpy as np

from .._block_kernel import empty_small_pages as _empty  # small pages: docs/algorithms/mesh_hierarchy.rst

from libc.math cimport INFINITY, fabs, rint, sqrt
from libc.stdint cimport int32_t, int64_t, uint8_t
from libc.string cimport memset

cdef enum: LOCKED = 1, BOUNDARY = 2, TOUCHED = 4  # TOUCHED: in the closed 1-ring of a vertex removed in this level

cdef struct Vertex:  # together, so that a visit's random reads of a neighbour hit one cache line
    int32_t start, corners, valence, flags  # corners pair[2 * start:][:2 * corners]; ring ring[2 * start:][:valence]

cdef extern from *:
    "#if defined(__GNUC__) || defined(__clang__)\n#define PREFETCH(p) __builtin_prefetch(p)\n#else\n#define PREFETCH(p) ((void)0)\n#endif"
    void prefetch "PREFETCH"(const void* p) noexcept nogil

cdef inline double _dot(const double* a, const double* b) noexcept nogil:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]

cdef inline void _edge(const double* p, int32_t a, int32_t c, double* out) noexcept nogil:
    out[0], out[1], out[2] = p[3 * a] - p[3 * c], p[3 * a + 1] - p[3 * c + 1], p[3 * a + 2] - p[3 * c + 2]

cdef inline void _cross(const double* p, int32_t a, int32_t b, int32_t c, double* u, double* w,
                        double* out) noexcept nogil:  # out = u x w, the edges u = p_a - p_c and w = p_b - p_c
    _edge(p, a, c, u)
    _edge(p, b, c, w)
    out[0], out[1], out[2] = u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]

cdef bint _legal(const double* p, const Vertex* V, const int32_t* pair, const int32_t* ring, const uint8_t* mult,
                 int32_t x, int32_t e, double cos_sq, double min_quality) noexcept nogil:
    """Whether ``x`` may collapse into its ring slot ``e`` (the geometric rules, then the link condition)."""
    cdef int32_t k = ring[2 * V[x].start + e], i = 2 * V[x].start, l = 2 * V[k].start, common = 0, j
    cdef double[3] old, new, u, w
    cdef double dot, squared
    for j in range(2 * V[x].start, 2 * (V[x].start + V[x].corners), 2):
        if pair[j] == k or pair[j + 1] == k:
            continue  # the triangle collapses with the edge
        _cross(p, pair[j], pair[j + 1], x, u, w, old)
        _cross(p, pair[j], pair[j + 1], k, u, w, new)  # u, w: its edges from k
        dot = _dot(new, old)
        if dot <= 0.0 or dot * dot <= _dot(new, new) * cos_sq * _dot(old, old):
            return False  # flipped (or degenerate), or turned by max_normal_angle or more
        old[0], old[1], old[2] = w[0] - u[0], w[1] - u[1], w[2] - u[2]  # its third edge
        squared = (_dot(u, u) + _dot(w, w) + _dot(old, old)) * min_quality
        if _dot(new, new) <= squared * squared:
            return False  # 2 * area / (sum of squared edge lengths) at most min_quality
    while i < 2 * V[x].start + V[x].valence and l < 2 * V[k].start + V[k].valence:  # merge the sorted rings
        common += ring[i] == ring[l]
        i, l = i + (ring[i] <= ring[l]), l + (ring[l] <= ring[i])
    return common == mult[2 * V[x].start + e]  # link condition: only the edge's opposite vertices in common

#: Lengths are compared in units of this fraction of the input's mean edge length ``h`` (squared: ``TIE h^2``).
TIE = 2.0 ** -20
#: Squared distances to the centroid (the last tie-break) are compared in units of this fraction of ``h^2``.
FAR = 2.0 ** -8


def _far(positions, vertices, centre):
    offset = np.asarray(positions)[vertices] - centre
    return (offset * offset).sum(axis=1)


def visiting_order(costs, spreads, candidates, positions, centre, double h):
    """The candidates' visiting order (indices into them): by cost, then ring spread (the sum of squared edge
    lengths), then squared distance to the input's centroid ``centre``, in :data:`TIE` and :data:`FAR` units of
    the mean edge length ``h``, then index (why: ``docs/algorithms/mesh_hierarchy.rst``)."""
    q = h * h * TIE
    cost, spread = np.rint(costs / (h * TIE)), np.rint(spreads / q)
    if cost.size == 0 or max(cost.max(), spread.max()) >= 2.0**32:  # past 4096 mean edges: the general sort
        return np.lexsort((candidates, np.rint(_far(positions, candidates, centre) / (h * h * FAR)), spread, cost))
    key = cost.astype(np.uint64) << np.uint64(32) | spread.astype(np.uint64)  # both in one word: one fast sort
    order = np.argsort(key, kind="stable")  # the candidates ascend: ties by index
    key = key[order]
    same = key[1:] == key[:-1]
    if same.any():  # rows of identical rings: their members re-sorted within their run by distance, then index
        tied = np.zeros(len(key), dtype=bool)
        tied[1:] = same
        tied[:-1] |= same
        members = np.flatnonzero(tied)
        sub = order[members]
        run = np.cumsum(np.r_[True, key[members][1:] != key[members][:-1]])
        distance = np.rint(_far(positions, candidates[sub], centre) / (h * h * FAR))
        order[members] = sub[np.lexsort((sub, distance, run))]
    return order


def collapse_levels(vertices, triangles, *, double alpha, double beta, double max_normal_angle, double min_quality,
                    int max_tries, Py_ssize_t min_vertices=0, max_levels=None, report=None):
    """``(locked vertices (n,) bool, levels)``: levels of at most ``n_i - min_vertices`` removals until ``max_levels``
    or no valid collapse, ``report(removals)`` after each; the tuned options come from ``hierarchy.py``'s head. A level
    (int64, level ``i - 1`` indices): ``(removed, targets, ring_offsets, ring, parent, triangles, kept)``: the removed
    vertices, their targets and sorted 1-rings (CSR), the index at level ``i``, the triangles (mapped in order,
    collapsed ones dropped), the input indices."""
    # at 90 degrees or more only the flip test (a positive dot product of the normals) remains
    cdef double cos_sq = float(np.cos(np.deg2rad(max_normal_angle)) ** 2) if max_normal_angle < 90 else 0.0
    cdef double[:, ::1] positions = np.array(vertices, dtype=np.float64, order="C")  # compacted in place
    locked = np.zeros(len(positions), np.uint8)
    cdef uint8_t[::1] lock = locked
    cdef const int64_t[:, ::1] T = np.ascontiguousarray(triangles, dtype=np.int64)
    cdef Py_ssize_t n = positions.shape[0], m = T.shape[0], i, count, selected = 1, alive, total
    max_levels, report = n + 1 if max_levels is None else max_levels, report or (lambda _: None)
    if n >= 2 ** 31 - 1 or 6 * m >= 2 ** 31 - 1:
        raise ValueError(f"mesh must have fewer than 2**31 vertices and 2**31 / 6 triangles, got {n} and {m}")
    # np.empty: every slot is written before it is read; order: fan roots, targets
    cdef int32_t[:, ::1] vertex = _empty((n + 1, 4), np.int32), order = _empty((2, n + 1), np.int32)
    cdef int32_t[::1] pair = _empty(6 * m, np.int32), ring = _empty(6 * m, np.int32)
    cdef uint8_t[::1] mult = _empty(6 * m, np.uint8)  # triangles on each ring edge (at most 255 counted)
    # the candidates, their costs and ring spreads (sums of squared edge lengths), their visiting ranks
    costs, spreads, candidates = _empty(n + 1, np.float64), _empty(n + 1, np.float64), _empty(n + 1, np.int32)
    ranks = _empty(n + 1, np.int32)
    cdef double[::1] cost = costs, spread = spreads
    cdef int32_t[::1] candidate = candidates, key, rank = ranks
    cdef double scale = 0.0, unit = 1.0  # the mean edge length (at the first level), its TIE
    centre = np.asarray(positions).mean(axis=0) if n else np.zeros(3)  # the input's centroid
    cdef Py_ssize_t summed = 0
    cdef double[:, ::1] edge = np.empty((3, n + 1))  # the visited vertex's edges
    cdef int64_t[::1] kept = np.arange(n, dtype=np.int64), removed, target, offsets, flat, parent
    cdef int64_t[:, ::1] out
    cdef Vertex* V = <Vertex*> &vertex[0, 0]
    cdef int32_t* root = &order[0, 0]
    cdef double* p = &positions[0, 0] if n else NULL
    cdef int32_t v, x, k, best, j, s, r, c, e, deg, attempt
    cdef double d, lo, hi, least, height, normal[3], a[3], b[3], cross[3]
    levels = []
    while selected:
        m, depth = T.shape[0], len(levels)
        with nogil:  # corners (next and previous vertex of each triangle of a vertex)
            memset(V, 0, n * sizeof(Vertex))
            for i in range(3 * m):
                V[T[i // 3, i % 3]].corners += 1
            for v in range(1, n):
                V[v].start = V[v - 1].start + V[v - 1].corners
            for i in range(3 * m):
                v, c = T[i // 3, i % 3], i % 3
                j, V[v].valence = 2 * (V[v].start + V[v].valence), V[v].valence + 1  # valence: corners so far
                pair[j], pair[j + 1] = T[i // 3, (c + 1) % 3], T[i // 3, (c + 2) % 3]
            count = 0
            for v in range(n):  # the sorted unique 1-ring, flags, the candidates by cost
                x = min(v + 8, n - 1)  # the cost reads the neighbours' positions: ask early
                for j in range(2 * V[x].start, 2 * (V[x].start + V[x].corners), 2):
                    prefetch(&p[3 * pair[j]])
                s, deg, V[v].flags = 2 * V[v].start, 0, lock[kept[v]]
                for j in range(s, s + 2 * V[v].corners):  # insertion: rings are short
                    r = s + deg
                    while r > s and ring[r - 1] > pair[j]:
                        r -= 1
                    if r > s and ring[r - 1] == pair[j]:
                        mult[r - 1] += mult[r - 1] < 255
                        continue
                    for c in range(s + deg, r, -1):
                        ring[c], mult[c] = ring[c - 1], mult[c - 1]
                    ring[r], mult[r], deg = pair[j], 1, deg + 1
                for j in range(s, s + deg):
                    V[v].flags |= BOUNDARY if mult[j] == 1 else (LOCKED if mult[j] > 2 else 0)
                V[v].valence = deg
                if depth == 0:  # also lock unreferenced vertices and those with several fans
                    for j in range(s, s + deg):
                        root[ring[j]] = ring[j]
                    for j in range(s, s + 2 * V[v].corners, 2):  # union-find of the neighbours joined by a corner
                        r, e = pair[j], pair[j + 1]
                        while root[r] != r:
                            r = root[r]
                        while root[e] != e:
                            e = root[e]
                        root[max(r, e)], deg = min(r, e), deg - (r != e)
                    if V[v].valence == 0 or deg > 1 or V[v].flags & LOCKED:
                        lock[v], V[v].flags = 1, V[v].flags | LOCKED
                if V[v].valence and not V[v].flags & LOCKED:  # cost(v) (section 4.1)
                    lo, hi, spread[count] = INFINITY, 0.0, 0.0
                    for j in range(s, s + V[v].valence):
                        _edge(p, ring[j], v, a)
                        spread[count] += _dot(a, a)
                        d = sqrt(_dot(a, a))
                        lo, hi = min(lo, d), max(hi, d)
                        if depth == 0:
                            scale, summed = scale + d, summed + 1
                    cost[count], candidate[count], count = alpha * lo + beta * hi, v, count + 1
        if depth == max_levels or n <= min_vertices:
            break
        if depth == 0 and summed:  # the mean edge length around the candidates: a scale rigid motions keep
            scale /= summed
            unit = scale * TIE
        key = candidates[visiting_order(costs[:count], spreads[:count], candidates[:count], positions, centre, scale)]
        ranks[key] = np.arange(count, dtype=np.int32)
        with nogil:
            selected = total = 0
            memset(&order[1, 0], -1, n * sizeof(int32_t))  # the targets
            for i in range(count):
                if selected >= n - min_vertices:
                    break
                x = key[min(i + 16, count - 1)]  # the visit goes all over memory: ask early, step by step
                prefetch(&V[x]); prefetch(&p[3 * x])
                x = key[min(i + 8, count - 1)]
                prefetch(&ring[2 * V[x].start]); prefetch(&pair[2 * V[x].start])
                x = key[min(i + 4, count - 1)]  # unless touched already: its neighbours
                for j in range(2 * V[x].start, 2 * V[x].start + V[x].valence * (not V[x].flags & TOUCHED)):
                    prefetch(&V[ring[j]]); prefetch(&p[3 * ring[j]])
                x = key[i]
                s, deg, best = 2 * V[x].start, V[x].valence, -1
                if V[x].flags & TOUCHED:
                    continue  # the independence rule
                normal[0] = normal[1] = normal[2] = 0.0  # N_x, the summed doubled-area normals
                for j in range(s, s + 2 * V[x].corners, 2):
                    _cross(p, pair[j], pair[j + 1], x, a, b, cross)
                    normal[0], normal[1], normal[2] = normal[0] + cross[0], normal[1] + cross[1], normal[2] + cross[2]
                height = sqrt(_dot(normal, normal)) * unit  # cone volumes as heights over x's plane, in units
                height = height if height > 0.0 else 1.0
                for e in range(deg):  # allowed edges, their cone volume |N_x . (x_k - x)| and length
                    k = ring[s + e]  # k unlocked; a boundary x along the boundary; no lone triangle or tetrahedron
                    edge[2, e] = not (V[k].flags & LOCKED or (V[x].flags & BOUNDARY and mult[s + e] != 1) or (
                        deg == V[k].valence == (2 if V[x].flags & BOUNDARY else 3)
                        and (V[k].flags & BOUNDARY) == (V[x].flags & BOUNDARY)))
                    _edge(p, k, x, a)
                    edge[0, e], edge[1, e] = rint(fabs(_dot(normal, a)) / height), rint(sqrt(_dot(a, a)) / unit)
                for attempt in range(max_tries):  # least volume, then shortest (both in units), then first visited
                    best, least, d = -1, INFINITY, INFINITY
                    for e in range(deg):
                        if edge[2, e] and edge[0, e] < least:
                            least = edge[0, e]
                    for e in range(deg):
                        if edge[2, e] and edge[0, e] == least and (edge[1, e] < d or (
                                edge[1, e] == d and rank[ring[s + e]] < rank[ring[s + best]])):
                            d, best = edge[1, e], e
                    if best >= 0 and V[ring[s + best]].flags & TOUCHED:
                        best = -1  # a touched target ends the search: the independence rule
                    if best < 0 or _legal(p, V, &pair[0], &ring[0], &mult[0], x, best, cos_sq, min_quality):
                        break
                    edge[2, best], best = 0, -1
                if best >= 0:
                    order[1, x], selected, total = ring[s + best], selected + 1, total + deg
                    V[x].flags |= TOUCHED
                    for j in range(s, s + deg):
                        V[ring[j]].flags |= TOUCHED
        if selected:
            level = [_empty(size, np.int64) for size in (selected, selected, selected + 1, total, n, (m, 3))]
            removed, target, offsets, flat, parent, out = level
            with nogil:  # apply: the parent map, the removed 1-rings, the triangles with three distinct vertices
                i = j = total = alive = offsets[0] = 0
                for v in range(n):
                    if order[1, v] < 0:
                        root[v], p[3 * j], p[3 * j + 1], p[3 * j + 2] = j, p[3 * v], p[3 * v + 1], p[3 * v + 2]
                        kept[j], j = kept[v], j + 1
                        continue
                    removed[i], target[i] = v, order[1, v]
                    for e in range(2 * V[v].start, 2 * V[v].start + V[v].valence):
                        flat[total], total = ring[e], total + 1
                    offsets[i + 1], i = total, i + 1
                for i in range(selected):
                    root[removed[i]] = root[target[i]]
                for v in range(n):  # the map read below as int32: half the cache lines
                    parent[v] = root[v]
                for i in range(m):
                    out[alive, 0], out[alive, 1], out[alive, 2] = root[T[i, 0]], root[T[i, 1]], root[T[i, 2]]
                    alive += out[alive, 0] != out[alive, 1] != out[alive, 2] != out[alive, 0]
            out = None  # let go of the buffer, then cut it to the triangles kept
            level[5].resize((alive, 3), refcheck=False)
            n, T = n - selected, level[5]
            levels.append((*level, np.array(kept[:n])))
            report(selected)
    return locked.view(bool), levels

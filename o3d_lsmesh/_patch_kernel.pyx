# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Hole filling's sequential loops, compiled (2 of 2): the fairing's local mesh and system, the tangential
relaxation and the crossing test (docs/algorithms/hole_filling.rst). Liepa's programme, the refinement
and a loop's geometry: ``_triangulation_kernel``.

Local meshes index their vertices below 2^31: edge keys pack two indices in one int64.
"""

import numpy as np

from libc.math cimport INFINITY, fabs, floor, fmax, fmin, sqrt
from libc.stdint cimport int64_t, uint8_t
from libc.stdlib cimport calloc, free, malloc, qsort

from o3d_lsmesh._fill_common cimport (
    Half, _by_value, _cross, _dot, _key, _max, _min, _min_angle, _normal, _outside, _sort_halves, _sub
)

# tangential relaxation and the crossing test

def tangential_relax(const double[:, ::1] vertices, const int64_t[:, ::1] new_tris, int64_t first_new,
                     int iterations=10):
    """The new vertices (from ``first_new``) moved ``iterations`` times half-way to their star's
    area-weighted centroid, tangentially, each step kept only where it does not lower the smallest angle
    of the vertex's star (the others held): ``(n - first_new, 3)``."""
    cdef int64_t n = vertices.shape[0], p = n - first_new, q = new_tris.shape[0], i, r, v, c
    if p < 0:
        raise ValueError("first_new beyond the vertices")
    out = np.array(vertices[first_new:], dtype=np.float64, order="C")
    if p == 0:
        return out
    sums_ = np.empty((p, 9))  # per new vertex: normal sum, weighted centroid sum, area sum, star's angles
    cdef double[:, ::1] x = out, acc = sums_
    cdef double[3][3] pts
    cdef double[3] fn, move, kept
    cdef double area, norm, along, before
    cdef int it
    with nogil:
        for it in range(iterations):
            for v in range(p):
                for c in range(7):
                    acc[v, c] = 0.0
                acc[v, 7] = INFINITY
                acc[v, 8] = INFINITY
            for i in range(q):
                for r in range(3):
                    v = new_tris[i, r]
                    for c in range(3):
                        pts[r][c] = x[v - first_new, c] if v >= first_new else vertices[v, c]
                _normal(pts[0], pts[1], pts[2], fn)
                area = sqrt(_dot(fn, fn))
                for r in range(3):
                    v = new_tris[i, r] - first_new
                    if v < 0:
                        continue
                    for c in range(3):
                        acc[v, c] += fn[c]
                        acc[v, 3 + c] += area * ((pts[0][c] + pts[1][c] + pts[2][c]) / 3.0)
                    acc[v, 6] += area
            for v in range(p):
                norm = sqrt(_dot(&acc[v, 0], &acc[v, 0]))
                if norm > 0:
                    for c in range(3):
                        acc[v, c] = acc[v, c] / norm
                for c in range(3):
                    move[c] = acc[v, 3 + c] / fmax(acc[v, 6], 1e-300) - x[v, c]
                along = _dot(move, &acc[v, 0])
                for c in range(3):
                    acc[v, 3 + c] = move[c] - along * acc[v, c]  # the move, kept until every one is known
            # each star's smallest angle before and after its vertex's own half-step (Freitag's "smart"
            # smoothing): a step towards the centroid can narrow a triangle on a short loop edge
            for i in range(q):
                for r in range(3):
                    v = new_tris[i, r]
                    for c in range(3):
                        pts[r][c] = x[v - first_new, c] if v >= first_new else vertices[v, c]
                before = _min_angle(pts[0], pts[1], pts[2])
                for r in range(3):
                    v = new_tris[i, r] - first_new
                    if v < 0:
                        continue
                    for c in range(3):
                        kept[c] = pts[r][c]
                        pts[r][c] = kept[c] + 0.5 * acc[v, 3 + c]
                    acc[v, 7] = fmin(acc[v, 7], before)
                    acc[v, 8] = fmin(acc[v, 8], _min_angle(pts[0], pts[1], pts[2]))
                    for c in range(3):
                        pts[r][c] = kept[c]
            for v in range(p):
                if acc[v, 8] >= acc[v, 7]:
                    for c in range(3):
                        x[v, c] += 0.5 * acc[v, 3 + c]
    return out

cdef bint _cross_pair(const double* P, const double* Q) noexcept nogil:
    """Whether triangles ``P`` and ``Q`` (3 x 3; a segment repeats its last corner) intersect: no
    separating axis among the 23 candidates; touching and coplanar pairs cross. Each axis is made when
    its turn comes (most pairs part on one of the first)."""
    cdef double[3][3] eP, eQ
    cdef double[3] nP, nQ, axis
    cdef double scale = 0.0, spread = 0.0, length, inv, x, p_lo, p_hi, q_lo, q_hi
    cdef int c, r
    for c in range(3):
        _sub(P + 3 * ((c + 1) % 3), P + 3 * c, eP[c])
        _sub(Q + 3 * ((c + 1) % 3), Q + 3 * c, eQ[c])
    _cross(eP[0], eP[1], nP)
    _cross(eQ[0], eQ[1], nQ)
    for c in range(9):
        scale = _max(scale, _max(fabs(P[c]), fabs(Q[c])))
        spread = _max(spread, _max(fabs(eP[c // 3][c % 3]), fabs(eQ[c // 3][c % 3])))
    scale = scale + spread
    for r in range(23):  # the normals, the edges' crosses, then each normal's with each edge
        if r < 2:
            for c in range(3):
                axis[c] = nP[c] if r == 0 else nQ[c]
        elif r < 11:
            _cross(eP[(r - 2) // 3], eQ[(r - 2) % 3], axis)
        elif r < 14:
            _cross(nP, eP[r - 11], axis)
        elif r < 17:
            _cross(nQ, eQ[r - 14], axis)
        elif r < 20:
            _cross(nQ, eP[r - 17], axis)
        else:
            _cross(nP, eQ[r - 20], axis)
        length = sqrt((axis[0] * axis[0] + axis[1] * axis[1]) + axis[2] * axis[2])
        if not length > 1e-12 * (scale * scale):
            continue
        inv = 1.0 / length
        for c in range(3):
            axis[c] = axis[c] * inv
        p_lo, p_hi, q_lo, q_hi = INFINITY, -INFINITY, INFINITY, -INFINITY
        for c in range(3):
            x = (axis[0] * P[3 * c] + axis[1] * P[3 * c + 1]) + axis[2] * P[3 * c + 2]
            p_lo, p_hi = _min(p_lo, x), _max(p_hi, x)
            x = (axis[0] * Q[3 * c] + axis[1] * Q[3 * c + 1]) + axis[2] * Q[3 * c + 2]
            q_lo, q_hi = _min(q_lo, x), _max(q_hi, x)
        if _max(q_lo - p_hi, p_lo - q_hi) > 1e-12 * scale:
            return False
    return True

cdef bint _folded(const double* u, const double* w, const double* a, const double* b) noexcept nogil:
    """Whether ``(u, w, a)`` and ``(u, w, b)`` fold flat onto each other beyond their shared edge."""
    cdef double[3] na, nb, both
    _normal(u, w, a, na)
    _normal(u, w, b, nb)
    _cross(na, nb, both)
    return _dot(na, nb) > 0 and sqrt(_dot(both, both)) <= 1e-9 * sqrt(_dot(na, na) * _dot(nb, nb))

cdef inline bint _same_point(const double* V, int64_t a, int64_t b) noexcept nogil:
    """One vertex, or two at the same position (a duplicated vertex: the triangles share that corner)."""
    return a == b or (V[3 * a] == V[3 * b] and V[3 * a + 1] == V[3 * b + 1] and V[3 * a + 2] == V[3 * b + 2])

cdef bint _pair_crosses(const double* V, const int64_t* T, int64_t ta, int64_t tb) noexcept nogil:
    """Whether triangles ``ta`` and ``tb`` meet anywhere but at the corners and edge they share (finite
    coordinates: boxes apart share no corner, so the box test comes first, for every pair)."""
    cdef double[9] P, Q, S
    cdef double origin
    cdef int r, s, c, shared = 0, ra = 0, rb = 0
    cdef int[3] in_a, in_b
    for r in range(3):
        for c in range(3):
            P[3 * r + c] = V[3 * T[3 * ta + r] + c]
            Q[3 * r + c] = V[3 * T[3 * tb + r] + c]
    for c in range(3):
        if _min(_min(P[c], P[3 + c]), P[6 + c]) > _max(_max(Q[c], Q[3 + c]), Q[6 + c]) or (
            _min(_min(Q[c], Q[3 + c]), Q[6 + c]) > _max(_max(P[c], P[3 + c]), P[6 + c])
        ):
            return False
    for c in range(3):  # about P's first corner: the tests' tolerances follow the pair's size, not the
        origin = P[c]  # distance to the origin (a scan in world coordinates); near points subtract exactly
        for r in range(3):
            P[3 * r + c] -= origin
            Q[3 * r + c] -= origin
    for r in range(3):
        in_a[r], in_b[r] = 0, 0
    for r in range(3):
        for s in range(3):
            if _same_point(V, T[3 * ta + r], T[3 * tb + s]) and not in_b[s]:
                shared += 1
                in_a[r], in_b[s] = 1, 1
                break
    if shared == 3:
        return True
    if shared == 0:
        return _cross_pair(P, Q)
    for r in range(3):
        if in_a[r] == (shared == 1):  # one corner: the shared one; an edge: the unshared one
            ra = r
        if in_b[r] == (shared == 1):
            rb = r
    if shared == 2:
        return _folded(P + 3 * ((ra + 1) % 3), P + 3 * ((ra + 2) % 3), P + 3 * ra, Q + 3 * rb)
    for c in range(3):  # the edge opposite the shared corner, as a degenerate triangle
        S[c], S[3 + c], S[6 + c] = P[3 * ((ra + 1) % 3) + c], P[3 * ((ra + 2) % 3) + c], P[3 * ((ra + 2) % 3) + c]
    if _cross_pair(S, Q):
        return True
    for c in range(3):
        S[c], S[3 + c], S[6 + c] = Q[3 * ((rb + 1) % 3) + c], Q[3 * ((rb + 2) % 3) + c], Q[3 * ((rb + 2) % 3) + c]
    return _cross_pair(S, P)

# the fairing's local mesh

def local_mesh(const int64_t[:, ::1] triangles, const int64_t[::1] indptr, const int64_t[::1] data,
               const int64_t[::1] seeds, int64_t count, new_tris):
    """The triangles within ``count`` rings of ``seeds`` (breadth first over each vertex's triangles, CSR
    ``indptr``, ``data``), sorted, then ``new_tris``, renumbered: the sorted vertices ``(l,)``, the local
    triangles ``(r + q, 3)`` and the ``count + 1`` rings locally (ring 0 ``seeds``, each next one sorted)."""
    cdef int64_t n = indptr.shape[0] - 1, m = triangles.shape[0], k = seeds.shape[0], nd = data.shape[0]
    cdef int64_t step, f, r, t, c, w, start = 0, stop = 0, taken = 0, first
    cdef bint bad = k and _outside(&seeds[0], k, n)
    tri_, vert_, stops_ = np.empty(m, dtype=np.int64), np.empty(n + k, dtype=np.int64), np.empty(count + 1, np.int64)
    cdef int64_t[::1] tri = tri_, vert = vert_, stops = stops_
    cdef uint8_t* seen = <uint8_t*>calloc(max(n, 1), 1)
    cdef uint8_t* took = <uint8_t*>calloc(max(m, 1), 1)
    if not (seen and took):
        free(seen); free(took)
        raise MemoryError
    ring0 = np.zeros(0, dtype=np.int64) if bad else np.unique(seeds)  # ring 0's vertices, each once
    vert_[: len(ring0)], stop = ring0, len(ring0)
    with nogil:
        for r in range(stop):
            seen[vert[r]] = 1
        for step in range(count if not bad else 0):
            stops[step], first = stop, taken
            for f in range(start, stop):  # the front's triangles not taken yet, then their new vertices
                for r in range(indptr[vert[f]], indptr[vert[f] + 1]):
                    t = data[r] if 0 <= r < nd else -1
                    bad = bad or not 0 <= t < m
                    if not bad and not took[t]:
                        took[t] = 1
                        tri[taken] = t
                        taken += 1
            qsort(&tri[first], taken - first, sizeof(int64_t), _by_value)
            start = stop
            for t in range(first, taken):
                for c in range(3):
                    w = triangles[tri[t], c]
                    bad = bad or not 0 <= w < n
                    if not bad and not seen[w]:
                        seen[w] = 1
                        vert[stop] = w
                        stop += 1
            qsort(&vert[start], stop - start, sizeof(int64_t), _by_value)
        stops[count] = stop
        qsort(&tri[0], taken, sizeof(int64_t), _by_value)
    free(seen); free(took)
    if bad:
        raise ValueError("seeds, data and triangles must index the mesh")
    local_ = np.concatenate([np.asarray(triangles)[tri_[:taken]], np.asarray(new_tris, dtype=np.int64)])
    ids_, corners = np.unique(local_, return_inverse=True)  # the sorted vertices, each corner's among them
    rings = [np.asarray(seeds)] + [vert_[stops[r]:stops[r + 1]] for r in range(count)]
    return ids_, corners.reshape(-1, 3), [np.searchsorted(ids_, ring) for ring in rings]

# the fairing system (docs page)

cdef void _weights(const int64_t[:, ::1] tris, const double[:, ::1] x, const int64_t[::1] i, const int64_t[::1] j,
                   const int64_t[::1] inverse, bint cot, double[::1] w, double[::1] degree,
                   double[::1] scale) noexcept nogil:
    """Edge weights ``w``, degrees ``sum w`` and Laplacian row scales (all zeroed on entry): uniform, or
    cotangent weights clamped at 5% of their mean ``|w|`` with the inverse vertex areas normalized to mean 1."""
    cdef int64_t t = tris.shape[0], e = i.shape[0], nv = degree.shape[0], h, k, c, a, b, o, positive = 0
    cdef double[3] u, v, n
    cdef double total = 0.0, area, mean
    for h in range(e):
        w[h] = 0.0 if cot else 1.0
    if cot:
        for c in range(3):  # corner-major, as the half-edges: the angle at c + 2, opposite (c, c + 1)
            for k in range(t):
                a, b, o = tris[k, c], tris[k, (c + 1) % 3], tris[k, (c + 2) % 3]
                _sub(&x[a, 0], &x[o, 0], u)
                _sub(&x[b, 0], &x[o, 0], v)
                _cross(u, v, n)
                w[inverse[c * t + k]] += _dot(u, v) / fmax(sqrt(_dot(n, n)), 1e-300)
        for h in range(e):
            w[h] = 0.5 * w[h]
            total += fabs(w[h])
        for h in range(e):
            w[h] = fmax(w[h], 0.05 * (total / e))
    for h in range(e):
        degree[i[h]] += w[h]
        degree[j[h]] += w[h]
    if not cot:
        for k in range(nv):
            scale[k] = 1.0 / degree[k] if degree[k] > 0 else 0.0
        return
    for k in range(t):  # the vertex areas, a third of each triangle's, gathered in scale first
        _normal(&x[tris[k, 0], 0], &x[tris[k, 1], 0], &x[tris[k, 2], 0], n)
        area = 0.5 * sqrt(_dot(n, n))
        for c in range(3):
            scale[tris[k, c]] += area / 3.0
    total = 0.0
    for k in range(nv):
        if scale[k] > 0:
            total += scale[k]
            positive += 1
    mean = total / positive if positive else 1.0
    for k in range(nv):
        area = scale[k] / mean
        scale[k] = 1.0 / area if area > 0 else 0.0

# the fairing system of a local mesh

cdef int64_t _edges(const int64_t[:, ::1] tris, int64_t[::1] i, int64_t[::1] j, int64_t[::1] inverse,
                    Half* half, int64_t* counts) noexcept nogil:
    """The sorted edges ``i < j`` of a local mesh and the edge of each corner-major half-edge; how many
    (``half``: 6 t half-edges of room, ``counts``: the radix sort's)."""
    cdef int64_t t = tris.shape[0], e = 0, h, k, c
    for c in range(3):
        for k in range(t):
            half[c * t + k].key, half[c * t + k].h = _key(tris[k, c], tris[k, (c + 1) % 3]), c * t + k
    _sort_halves(half, half + 3 * t, 3 * t, counts)
    for h in range(3 * t):
        if h == 0 or half[h].key != half[h - 1].key:
            i[e], j[e] = half[h].key >> 32, half[h].key & <int64_t>0xFFFFFFFF
            e += 1
        inverse[half[h].h] = e - 1
    return e

def patch_system(const double[:, ::1] x, const int64_t[:, ::1] tris, const int64_t[::1] unknown,
                 const int64_t[::1] ring0, const int64_t[::1] ring1, int level, bint cot, bint dense):
    """The fairing system of the ``unknown`` vertices at continuity ``level`` (docs page), the others fixed
    at ``x``. ``dense``: the normal matrix ``(p, p)`` and right-hand side ``(p, 3)``. Else the CSR
    ``(indptr, indices, data)`` of ``M`` and ``b``: level 0 ``M = K_uu``, ``b = -K_uk x_k``; 1 and 2 the
    rows ``M = A_u`` and ``b = A_k x_k`` of the least squares (the system ``M^T M = -M^T b``).
    """
    cdef int64_t nv = x.shape[0], e, p = unknown.shape[0], t = tris.shape[0], rows, r, k, s, c, v
    cdef int64_t a, count, u1, u2, side, size = 0, capacity = 0
    if level not in (0, 1, 2) or nv >= 2**31:
        raise ValueError("level must be 0, 1 or 2, and a local mesh has fewer than 2^31 vertices")
    if (p and _outside(&unknown[0], p, nv)) or (t and _outside(&tris[0, 0], 3 * t, nv)):
        raise ValueError("unknown and tris index the vertices of x")
    i_, j_, inverse_ = np.empty(3 * t, dtype=np.int64), np.empty(3 * t, dtype=np.int64), np.empty(3 * t, dtype=np.int64)
    cdef int64_t[::1] i = i_, j = j_, inverse = inverse_
    cdef Half* half = <Half*>malloc(max(6 * t, 1) * sizeof(Half))  # and the sort's spare half
    cdef int64_t* counts = <int64_t*>malloc(8 * 256 * sizeof(int64_t))
    if not half or not counts:
        free(half)
        free(counts)
        raise MemoryError
    with nogil:
        e = _edges(tris, i, j, inverse, half, counts)
    free(half)
    free(counts)
    i, j = i[:e], j[:e]
    w_, degree_, scale_ = np.zeros(e), np.zeros(nv), np.zeros(nv)
    cdef double[::1] w = w_, degree = degree_, scale = scale_
    with nogil:
        _weights(tris, x, i, j, inverse, cot, w, degree, scale)
    mark_ = np.zeros(nv, dtype=np.uint8)
    valid_ = np.zeros(nv, dtype=np.uint8)
    keep_ = np.zeros(e, dtype=np.uint8)
    cdef uint8_t[::1] mark = mark_, valid = valid_, keep = keep_
    for k in range(p):
        mark[unknown[k]] = 1
    for k in range(ring0.shape[0]):
        mark[ring0[k]] = 1
    if level == 1:
        plus_, minus_ = np.flatnonzero(mark_), np.zeros(0, dtype=np.int64)
    else:  # level 2 (level 0 reads none)
        for k in range(nv):
            valid[k] = mark[k]
        for k in range(ring1.shape[0]):
            valid[ring1[k]] = 1
        for k in range(e):
            keep[k] = (mark[i[k]] or mark[j[k]]) and valid[i[k]] and valid[j[k]]
        plus_, minus_ = i_[:e][keep_.view(bool)], j_[:e][keep_.view(bool)]
    cdef const int64_t[::1] plus = plus_, minus = minus_
    rows = plus.shape[0] if level else p
    # each vertex's neighbours (CSR over the edges, both directions)
    indptr_ = np.zeros(nv + 1, dtype=np.int64)
    cdef int64_t[::1] indptr = indptr_
    nbr_ = np.empty(2 * e, dtype=np.int64)
    wt_ = np.empty(2 * e)
    col_ = np.full(nv, -1, dtype=np.int64)
    fixed_ = np.array(x, dtype=np.float64, order="C")
    cdef int64_t[::1] nbr = nbr_, col = col_
    cdef double[::1] wt = wt_
    cdef double[:, ::1] fixed = fixed_
    for k in range(e):
        indptr[i[k] + 1] += 1
        indptr[j[k] + 1] += 1
    for v in range(nv):
        indptr[v + 1] += indptr[v]
    if level == 0:
        capacity = p + 2 * e
    else:
        for r in range(rows):  # each row's entries at most
            capacity += indptr[plus[r] + 1] - indptr[plus[r]] + 1
            if minus.shape[0]:
                capacity += indptr[minus[r] + 1] - indptr[minus[r]] + 1
    normal_ = np.zeros((p, p)) if dense else np.zeros((0, 0))
    rhs_ = np.zeros((p, 3)) if dense or level == 0 else np.zeros((rows, 3))
    out_indptr_ = np.zeros(0 if dense else rows + 1, dtype=np.int64)
    out_indices_ = np.empty(0 if dense else capacity, dtype=np.int64)
    out_data_ = np.empty(0 if dense else capacity)
    cdef double[:, ::1] normal = normal_, rhs = rhs_
    cdef int64_t[::1] out_indptr = out_indptr_, out_indices = out_indices_
    cdef double[::1] out_data = out_data_
    cdef int64_t[::1] slot = indptr_[:-1].copy(), entry = np.empty(nv, dtype=np.int64)
    cdef double[::1] value = np.empty(nv)
    cdef double bx, by, bz, f
    with nogil:
        for k in range(e):
            nbr[slot[i[k]]], wt[slot[i[k]]] = j[k], w[k]
            slot[i[k]] += 1
            nbr[slot[j[k]]], wt[slot[j[k]]] = i[k], w[k]
            slot[j[k]] += 1
        for k in range(p):
            col[unknown[k]] = k
            for c in range(3):
                fixed[unknown[k], c] = 0.0  # A_k x_k as A x with the unknowns zeroed
        for v in range(nv):
            slot[v] = -1
        for r in range(rows):
            count = 0
            if level == 0:  # row r of K: the unknown's degree, minus its edges' weights
                a = unknown[r]
                for k in range(indptr[a] - 1, indptr[a + 1]):
                    entry[count] = a if k < indptr[a] else nbr[k]
                    value[count] = degree[a] if k < indptr[a] else -wt[k]
                    count += 1
            else:  # the row's entries: L[plus[r]], then minus L[minus[r]]
                for side in range(2 if minus.shape[0] else 1):
                    a = plus[r] if side == 0 else minus[r]
                    for k in range(indptr[a] - 1, indptr[a + 1]):
                        v = a if k < indptr[a] else nbr[k]
                        f = scale[a] * (degree[a] if k < indptr[a] else -wt[k])
                        if slot[v] < 0:
                            slot[v] = count
                            entry[count] = v
                            value[count] = f if side == 0 else -f
                            count += 1
                        else:
                            value[slot[v]] = value[slot[v]] - f
                for k in range(count):
                    slot[entry[k]] = -1
            bx = by = bz = 0.0
            for k in range(count):
                v = entry[k]
                bx += value[k] * fixed[v, 0]
                by += value[k] * fixed[v, 1]
                bz += value[k] * fixed[v, 2]
            if not dense:  # the row's unknown entries and its fixed part
                for k in range(count):
                    if col[entry[k]] >= 0:
                        out_indices[size], out_data[size] = col[entry[k]], value[k]
                        size += 1
                out_indptr[r + 1] = size
                f = -1.0 if level == 0 else 1.0
                rhs[r, 0], rhs[r, 1], rhs[r, 2] = f * bx, f * by, f * bz
            elif level == 0:
                for k in range(count):
                    if col[entry[k]] >= 0:
                        normal[r, col[entry[k]]] += value[k]
                rhs[r, 0], rhs[r, 1], rhs[r, 2] = -bx, -by, -bz
            else:
                for k in range(count):
                    u1 = col[entry[k]]
                    if u1 < 0:
                        continue
                    rhs[u1, 0] -= value[k] * bx
                    rhs[u1, 1] -= value[k] * by
                    rhs[u1, 2] -= value[k] * bz
                    for s in range(count):
                        u2 = col[entry[s]]
                        if u2 >= 0:
                            normal[u1, u2] += value[k] * value[s]
    if dense:
        return normal_, rhs_
    return (out_indptr_, out_indices_[:size], out_data_[:size]), rhs_

# the crossing test: candidates from uniform grids of triangle centres

cdef inline bint _overlap(const double* c, double r, const double* d, double s) noexcept nogil:
    cdef double d0 = c[0] - d[0], d1 = c[1] - d[1], d2 = c[2] - d[2]
    return sqrt((d0 * d0 + d1 * d1) + d2 * d2) <= r + s

def triangle_grids(const double[:, ::1] vertices, const int64_t[:, ::1] triangles):
    """The crossing test's bounding spheres of ``triangles``: centres ``(t, 3)`` (the centroids, NumPy's
    ``p.sum(axis=1) / 3`` bits), radii ``(t,)`` (the farthest corner), and their grids: those of radius
    at most 1.5 times the median, at most 4 times, then the rest (docs page), each in cells as wide as its
    largest radius (wider while the cells outnumber ``4 t + 64``), each cell's triangles in index order, a
    list of ``(origin, cell, dims, indptr, members, reach)``."""
    cdef int64_t t = triangles.shape[0], half = t // 2, k, g, count, x
    cdef double reach, width, limit, d0, d1, d2
    cdef double[3] low, high
    cdef const int64_t[::1] members
    cdef int64_t[::1] dims, key, indptr, out
    cdef int c, r
    if t and _outside(&triangles[0, 0], 3 * t, vertices.shape[0]):
        raise ValueError("triangles index the vertices")
    centre_, radius_ = np.empty((t, 3)), np.empty(t)
    cdef double[:, ::1] centre = centre_
    cdef double[::1] radius = radius_
    for k in range(t):
        for c in range(3):
            centre[k, c] = ((vertices[triangles[k, 0], c] + vertices[triangles[k, 1], c])
                            + vertices[triangles[k, 2], c]) / 3.0
        for r in range(3):
            d0 = vertices[triangles[k, r], 0] - centre[k, 0]
            d1 = vertices[triangles[k, r], 1] - centre[k, 1]
            d2 = vertices[triangles[k, r], 2] - centre[k, 2]
            d0 = sqrt((d0 * d0 + d1 * d1) + d2 * d2)
            radius[k] = d0 if r == 0 else _max(radius[k], d0)
    if t == 0:
        return centre_, radius_, []
    part = np.partition(radius_, [half - 1, half] if t % 2 == 0 else [half])
    limit = part[half] if t % 2 else (part[half - 1] + part[half]) / 2.0
    # a band of radius per grid (NaN in the last): a few larger triangles widen only their own grid's cells
    fine_, small_ = radius_ <= 1.5 * limit, radius_ <= 4.0 * limit
    grids = []
    for members_ in (np.flatnonzero(fine_), np.flatnonzero(small_ & ~fine_), np.flatnonzero(~small_)):
        count = members_.shape[0]
        if count == 0:
            continue
        members = members_
        reach = 0.0
        low[0] = low[1] = low[2] = INFINITY
        high[0] = high[1] = high[2] = -INFINITY
        for k in range(count):
            reach = fmax(reach, radius[members[k]])
            for c in range(3):
                low[c], high[c] = fmin(low[c], centre[members[k], c]), fmax(high[c], centre[members[k], c])
        width = reach if reach > 0 else fmax(fmax(fmax(high[0] - low[0], high[1] - low[1]), high[2] - low[2]), 1.0)
        while ((floor((high[0] - low[0]) / width) + 1) * (floor((high[1] - low[1]) / width) + 1)
               * (floor((high[2] - low[2]) / width) + 1)) > 4 * count + 64:  # the grid stays linear in t
            width *= 1.5
        dims_ = np.array([<int64_t>floor((high[c] - low[c]) / width) + 1 for c in range(3)], dtype=np.int64)
        dims = dims_
        key_ = np.empty(count, dtype=np.int64)
        indptr_ = np.zeros(dims[0] * dims[1] * dims[2] + 1, dtype=np.int64)
        sorted_ = np.empty(count, dtype=np.int64)
        key, indptr, out = key_, indptr_, sorted_
        for k in range(count):  # each member's cell, counted, then the members listed by cell (stable)
            x = 0
            for c in range(3):
                x = x * dims[c] + min(<int64_t>floor((centre[members[k], c] - low[c]) / width), dims[c] - 1)
            key[k] = x
            indptr[x + 1] += 1
        for g in range(indptr.shape[0] - 1):
            indptr[g + 1] += indptr[g]
        for k in range(count):
            out[indptr[key[k]]] = members[k]
            indptr[key[k]] += 1
        for g in range(indptr.shape[0] - 1, 0, -1):
            indptr[g] = indptr[g - 1]
        indptr[0] = 0
        grids.append((np.array([low[0], low[1], low[2]]), width, dims_, indptr_, sorted_, reach))
    return centre_, radius_, grids

def patch_crossings(const double[:, ::1] vertices, const int64_t[:, ::1] triangles, int64_t first_new,
                    grids, const double[:, ::1] tri_centre, const double[::1] tri_radius,
                    new_grids, const double[:, ::1] new_centre, const double[::1] new_radius, owner=None):
    """For each new triangle (from ``first_new`` on), the number of triangles it meets beyond the corners
    and edge they share, from grids of the triangles' bounding spheres; with ``owner``, a crossing
    patch's other triangles are not tested (docs page)."""
    cdef int64_t q = triangles.shape[0] - first_new
    result_ = np.zeros(max(q, 0))
    if q <= 0:
        return result_
    if new_centre.shape[0] != q or new_radius.shape[0] != q:
        raise ValueError("new_centre and new_radius must have one row per new triangle")
    owner_ = np.zeros(q, dtype=np.int64) if owner is None else np.ascontiguousarray(owner, dtype=np.int64)
    if owner_.shape[0] != q or owner_.min() < 0:
        raise ValueError("owner must hold one patch (>= 0) per new triangle")
    crossed_ = np.zeros(int(owner_.max()) + 1, dtype=np.uint8)  # holes without a triangle hold a number too
    _grid_crossings(vertices, triangles, first_new, new_centre, new_radius, list(grids), tri_centre, tri_radius,
                    False, result_, owner_, crossed_, owner is not None)
    _grid_crossings(vertices, triangles, first_new, new_centre, new_radius, list(new_grids), new_centre,
                    new_radius, True, result_, owner_, crossed_, owner is not None)
    return result_

cdef _grid_crossings(const double[:, ::1] vertices, const int64_t[:, ::1] triangles, int64_t first_new,
                     const double[:, ::1] centre, const double[::1] radius, list grids,
                     const double[:, ::1] tc, const double[::1] tr, bint among_new, double[::1] result,
                     const int64_t[::1] owner, uint8_t[::1] crossed, bint stop):
    """:func:`patch_crossings` against the triangles of ``grids`` (the new ones if ``among_new``: each pair
    once); with ``stop``, a crossing patch's triangles are no query and a query ends at its first crossing."""
    cdef int64_t q = centre.shape[0], i = 0, k, t, g, count, capacity, first, other, n_grids = len(grids)
    cdef int64_t[3] lo_cell, hi_cell
    cdef double[3] lo, hi
    cdef int c
    cdef const double* V = &vertices[0, 0]
    cdef const int64_t* T = &triangles[0, 0]
    if n_grids == 0 or n_grids > 4:
        if n_grids:
            raise ValueError("at most 4 grids")
        return
    # each grid's arrays (a _TriangleIndex makes at most 3): origin, cell, dims, reach, indptr, members
    cdef double[4][3] origin
    cdef double[4] cell, reach
    cdef int64_t[4][3] dims
    cdef const int64_t* indptr[4]
    cdef const int64_t* members[4]
    cdef const int64_t[::1] view
    keep = []
    for g in range(n_grids):
        o_, cell_, d_, p_, m_, r_ = grids[g]
        cell[g], reach[g] = cell_, r_
        for c in range(3):
            origin[g][c], dims[g][c] = o_[c], d_[c]
        p_, m_ = np.ascontiguousarray(p_, dtype=np.int64), np.ascontiguousarray(m_, dtype=np.int64)
        keep += [p_, m_]
        view = p_
        indptr[g] = &view[0]
        view = m_ if m_.shape[0] else np.zeros(1, dtype=np.int64)
        keep.append(view)
        members[g] = &view[0]
    # among_new with stop: whether each triangle's query ran to its end (its pairs with later ones tested)
    done_ = np.zeros(q, dtype=np.uint8)
    cdef uint8_t[::1] done = done_
    buffer_ = np.empty(4096, dtype=np.int64)
    cdef int64_t[::1] buffer = buffer_
    while i < q:
        with nogil:
            while i < q:
                if stop and crossed[owner[i]]:  # known crossing: its pairs are tested from the other side
                    i += 1
                    continue
                for c in range(3):
                    lo[c], hi[c] = centre[i, c] - radius[i], centre[i, c] + radius[i]
                capacity = 0
                for g in range(n_grids):
                    capacity += _cells(lo, hi, origin[g], cell[g], dims[g], indptr[g], reach[g], lo_cell, hi_cell)
                if capacity > buffer.shape[0]:
                    break
                count = 0
                for g in range(n_grids):
                    _cells(lo, hi, origin[g], cell[g], dims[g], indptr[g], reach[g], lo_cell, hi_cell)
                    count += _gather(&centre[i, 0], radius[i], lo_cell, hi_cell, dims[g], indptr[g], members[g],
                                     &tc[0, 0], &tr[0], &buffer[count])
                done[i] = 1
                for k in range(count):
                    t = buffer[k]
                    # a pair of new ones once: from its first triangle, or from the second where the
                    # first's query was skipped or cut short
                    if among_new and (t == i or (t < i and (done[t] or not stop))):
                        continue
                    first, other = first_new + i, t
                    if among_new:  # the pair in index order, as queried from its first triangle
                        first, other = first_new + min(i, t), first_new + max(i, t)
                    if _pair_crosses(V, T, first, other):
                        result[i] += 1.0
                        crossed[owner[i]] = 1
                        if among_new:
                            result[t] += 1.0
                            crossed[owner[t]] = 1
                        if stop:
                            done[i] = 0
                            break
                i += 1
        if i < q:
            buffer_ = np.empty(2 * capacity, dtype=np.int64)
            buffer = buffer_

cdef int64_t _cells(const double* lo, const double* hi, const double* origin, double cell, const int64_t* dims,
                    const int64_t* indptr, double reach, int64_t* lo_cell, int64_t* hi_cell) noexcept nogil:
    """The cells of one grid within ``reach`` of the box ``lo .. hi`` (clamped to the grid; floor of a
    double) into ``lo_cell``, ``hi_cell``; returns how many triangles they hold."""
    cdef int64_t x, y, capacity = 0
    cdef double d
    cdef int c
    for c in range(3):
        d = (lo[c] - reach - origin[c]) / cell
        lo_cell[c] = <int64_t>d if d >= 0 else 0
        d = (hi[c] + reach - origin[c]) / cell
        hi_cell[c] = min(<int64_t>d, dims[c] - 1) if d >= 0 else -1
    if hi_cell[2] >= lo_cell[2]:
        for x in range(lo_cell[0], hi_cell[0] + 1):
            for y in range(lo_cell[1], hi_cell[1] + 1):
                capacity += indptr[(x * dims[1] + y) * dims[2] + hi_cell[2] + 1] - indptr[
                    (x * dims[1] + y) * dims[2] + lo_cell[2]]
    return capacity

cdef int64_t _gather(const double* centre, double radius, const int64_t* lo_cell, const int64_t* hi_cell,
                     const int64_t* dims, const int64_t* indptr, const int64_t* members,
                     const double* tc, const double* tr, int64_t* out) noexcept nogil:
    """The members of the cells ``lo_cell .. hi_cell`` whose spheres meet the sphere ``centre``, ``radius``
    (:func:`_overlap`), into ``out``; returns how many."""
    cdef int64_t x, y, k, count = 0
    if hi_cell[2] < lo_cell[2]:
        return 0
    for x in range(lo_cell[0], hi_cell[0] + 1):
        for y in range(lo_cell[1], hi_cell[1] + 1):
            for k in range(indptr[(x * dims[1] + y) * dims[2] + lo_cell[2]],
                           indptr[(x * dims[1] + y) * dims[2] + hi_cell[2] + 1]):
                # written always, kept where the spheres meet: most do not, at random, and a branch on it
                # mispredicted cost more than the test
                out[count] = members[k]
                count += _overlap(centre, radius, &tc[3 * members[k]], tr[members[k]])
    return count

# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Hole filling's sequential loops, compiled (1 of 2): Liepa's minimum-weight programme, the refinement's
splits and Delaunay flips, and what the programme needs of a loop (docs/algorithms/hole_filling.rst).
The fairing's local mesh and system, the tangential relaxation and the crossing test: ``_patch_kernel``.

Local meshes index their vertices below 2^31: edge keys pack two indices in one int64.
"""

import numpy as np

from libc.math cimport INFINITY, acos, cos, fabs, fmax, fmin, sqrt
from libc.stdint cimport int64_t, uint8_t
from libc.stdlib cimport free, malloc, qsort

from o3d_lsmesh._fill_common cimport (
    Half, _by_key, _by_value, _cross, _dot, _key, _lower, _min_angle, _normal, _outside, _sort_halves, _sub
)

# numerical tolerances and a safeguard, none fitted to a benchmark (the fitted constants: holes/tuning.py)
cdef double _TIE = 1e-6  # dynamic programme: largest angles this close tie, and the area decides
cdef double _COCIRCULAR = 1.0 - 1e-6  # flips: a point must be this far inside a circumsphere
cdef int64_t _MAX_FAN = 64  # refinement: no split at a corner of this many triangles (runaway fans)

# Liepa's minimum-weight triangulation (SGP 2003, section 3)

cdef void _liepa(const double* P, const double* outer, const uint8_t* forbidden, const uint8_t* allowed,
                 int64_t k, double* angle, double* cosine,
                 double* area, double* shape, int64_t* split, double* normal, uint8_t* known, double* t_angle,
                 double* t_area, double* t_shape, double* t_twice, double* t_normal) noexcept nogil:
    """Fill the programme's tables: weight (largest dihedral angle, area, then shape) of the best triangulation
    of each polygon ``i..j``; ``forbidden`` chords and triangles not ``allowed`` (either may be NULL)
    infinitely bad."""
    cdef int64_t i, j, m, d, c, r, choice
    cdef double[3] u, v, w, cr
    cdef double twice, cos1, cos2, worst, theta, longest, best_angle, best_area, best_shape, uu, vv, sub
    cdef const double* a
    cdef double* nm
    cdef bint closing_known = fabs(outer[3 * (k - 1)]) + fabs(outer[3 * (k - 1) + 1]) + fabs(outer[3 * (k - 1) + 2]) > 0
    for i in range(k - 1):  # the loop's edges: the mesh triangles across them
        for c in range(3):
            normal[3 * (i * k + i + 1) + c] = outer[3 * i + c]
        known[i * k + i + 1] = fabs(outer[3 * i]) + fabs(outer[3 * i + 1]) + fabs(outer[3 * i + 2]) > 0
    for d in range(2, k):
        for i in range(k - d):
            j = i + d
            a = P + 3 * j
            for r in range(d - 1):
                m = i + 1 + r
                # a triangle not allowed or on a forbidden chord is infinitely bad: not computed (with the
                # Delaunay restriction most are not), so the programme's work follows the allowed triangles
                if (allowed != NULL and not allowed[(i * k + m) * k + j]) or (
                    forbidden != NULL and (forbidden[i * k + m] or forbidden[m * k + j])
                ):
                    t_angle[r] = INFINITY
                    t_area[r] = INFINITY
                    t_twice[r] = 0.0
                    t_normal[3 * r] = t_normal[3 * r + 1] = t_normal[3 * r + 2] = 0.0
                    continue
                _sub(P + 3 * m, a, u)
                _sub(P + 3 * i, a, v)
                _cross(u, v, cr)  # triangle (j, m, i)
                twice = sqrt(_dot(cr, cr))
                nm = t_normal + 3 * r
                for c in range(3):
                    nm[c] = cr[c] / (twice if twice > 0 else 1.0)
                cos1 = _dot(nm, normal + 3 * (i * k + m))
                cos2 = _dot(nm, normal + 3 * (m * k + j))
                worst = fmin(cos1 if known[i * k + m] else 1.0, cos2 if known[m * k + j] else 1.0)
                if d == k - 1 and closing_known:  # the triangle on the closing loop edge (k - 1, 0)
                    worst = fmin(worst, _dot(nm, outer + 3 * (k - 1)))
                # a degenerate triangle (collinear chord samples) is worse than any real one: neither
                # its noise normal nor its zero area may win (both sides of a chord taking it make a
                # non-manifold edge)
                uu = _dot(u, u)
                vv = _dot(v, v)
                longest = uu if uu >= vv else vv
                sub = fmax(angle[i * k + m], angle[m * k + j])
                if twice > 1e-9 * longest and worst >= fmin(cosine[i * k + m], cosine[m * k + j]) + 1e-9:
                    t_angle[r] = sub  # its angle is below sub's (|d acos| >= |d cos|): no acos needed
                else:
                    theta = acos(fmin(fmax(worst, -1.0), 1.0))
                    if not twice > 1e-9 * longest:
                        theta = 2.0 * 3.141592653589793
                    t_angle[r] = fmax(theta, sub)
                t_area[r] = 0.5 * twice + area[i * k + m] + area[m * k + j]
                t_twice[r] = twice
            best_angle = INFINITY
            for r in range(d - 1):
                best_angle = fmin(best_angle, t_angle[r])
            best_area = INFINITY
            for r in range(d - 1):
                if t_angle[r] <= best_angle + _TIE:
                    best_area = fmin(best_area, t_area[r])
            # the sum of squared sides decides where angle and area tie (a planar loop: every
            # triangulation): the shortest chords, not the first choice's fan of slivers from one corner
            # (the sum of cotangents, the inverse quality, ties again on a circle)
            best_shape = INFINITY
            for r in range(d - 1):
                t_shape[r] = INFINITY
                if t_angle[r] <= best_angle + _TIE and t_area[r] <= best_area * (1.0 + 1e-9):
                    m = i + 1 + r
                    _sub(P + 3 * m, P + 3 * i, u)
                    _sub(P + 3 * j, P + 3 * m, v)
                    _sub(P + 3 * i, P + 3 * j, w)
                    t_shape[r] = _dot(u, u) + _dot(v, v) + _dot(w, w) + shape[i * k + m] + shape[m * k + j]
                    best_shape = fmin(best_shape, t_shape[r])
            # the first of the (near-)smallest shapes among those: symmetric loops tie exactly, and
            # rounding must not decide
            choice = 0
            for r in range(d - 1):
                if t_shape[r] <= best_shape * (1.0 + 1e-9):
                    choice = r
                    break
            c = i * k + j
            angle[c] = t_angle[choice]
            if forbidden != NULL and d < k - 1 and forbidden[c]:
                angle[c] = INFINITY
            cosine[c] = cos(angle[c])
            area[c] = t_area[choice]
            shape[c] = t_shape[choice]
            split[c] = i + 1 + choice
            for m in range(3):
                normal[3 * c + m] = t_normal[3 * choice + m]
            known[c] = t_twice[choice] > 0

def minimum_weight_triangulation(const double[:, ::1] points, const double[:, ::1] outer_normals,
                                 const uint8_t[:, ::1] forbidden=None, const uint8_t[::1] allowed=None):
    """Liepa's dynamic programme on ``k >= 3`` loop points: the ``k - 2`` triangles ``(j, m, i)``;
    ``outer_normals (k, 3)``, ``forbidden (k, k)`` chords and the ``allowed`` triangles as in the docs page."""
    cdef int64_t k = points.shape[0]
    if outer_normals.shape[0] != k or points.shape[1] != 3 or outer_normals.shape[1] != 3:
        raise ValueError("points and outer_normals must be (k, 3)")
    if forbidden is not None and (forbidden.shape[0] != k or forbidden.shape[1] != k):
        raise ValueError("forbidden must be (k, k)")
    if allowed is not None and allowed.shape[0] != k * k * k:
        raise ValueError("allowed must be (k**3,)")
    if k < 3:
        raise ValueError(f"a loop needs at least 3 points, got {k}")
    out = np.empty((k - 2, 3), dtype=np.int64)
    cdef int64_t[:, ::1] tris = out
    angle_, area_, normal_, known_ = np.zeros(k * k), np.zeros(k * k), np.zeros(3 * k * k), np.zeros(k * k, np.uint8)
    shape_ = np.zeros(k * k)
    split_ = np.full(k * k, -1, dtype=np.int64)
    scratch = np.empty(7 * k)
    cosine_ = np.ones(k * k)  # cos of each angle (a loop edge's: 0, cos 1)
    cdef double[::1] angle = angle_, area = area_, shape = shape_, normal = normal_, s = scratch, cosine = cosine_
    cdef int64_t[::1] split = split_
    cdef uint8_t[::1] known = known_
    cdef const uint8_t* f = NULL if forbidden is None else &forbidden[0, 0]
    with nogil:
        _liepa(&points[0, 0], &outer_normals[0, 0], f, NULL if allowed is None else &allowed[0], k, &angle[0],
               &cosine[0], &area[0], &shape[0], &split[0], &normal[0], &known[0], &s[0], &s[k], &s[2 * k],
               &s[3 * k], &s[4 * k])
    if not np.isfinite(angle_[k - 1]) and (allowed is not None or f != NULL):
        # none within ``allowed``: without it; then none avoids every existing edge: accept one that does not
        return minimum_weight_triangulation(points, outer_normals, forbidden if allowed is not None else None)
    # the triangles from the split table, depth first from the whole polygon (0, k - 1)
    cdef int64_t[::1] stack = np.empty(2 * k, dtype=np.int64)
    cdef int64_t top = 2, lo, hi, mid, found = 0
    stack[0], stack[1] = 0, k - 1
    with nogil:
        while top > 0:
            top -= 2
            lo, hi = stack[top], stack[top + 1]
            if hi - lo >= 2:
                mid = split[lo * k + hi]
                tris[found, 0], tris[found, 1], tris[found, 2] = hi, mid, lo
                found += 1
                stack[top], stack[top + 1], stack[top + 2], stack[top + 3] = lo, mid, mid, hi
                top += 4
    return out

def delaunay_allowed(const double[:, ::1] points, const int64_t[:, ::1] tets, const double[:, ::1] centre,
                     double cospherical):
    """The faces of the tetrahedra ``tets`` of ``points (k, 3)`` as the programme's ``allowed`` ``(k^3,)``,
    or None where a point not on a tetrahedron is within ``cospherical`` (relative) of its circumsphere
    (``centre (t, 3)``; radius from its first corner): the tetrahedralization is then one of several."""
    cdef int64_t k = points.shape[0], t = tets.shape[0], a, v, f, w
    cdef double radius, gap, d0, d1, d2
    cdef int64_t[4] q
    cdef int r
    if centre.shape[0] != t or tets.shape[1] != 4 or (t and _outside(&tets[0, 0], 4 * t, k)):
        raise ValueError("tets index the points, four a row, and centre has one row per tetrahedron")
    allowed_ = np.zeros(k * k * k, dtype=np.uint8)
    cdef uint8_t[::1] allowed = allowed_
    for a in range(t):
        d0, d1, d2 = points[tets[a, 0], 0] - centre[a, 0], points[tets[a, 0], 1] - centre[a, 1], points[tets[a, 0], 2] - centre[a, 2]
        radius = sqrt((d0 * d0 + d1 * d1) + d2 * d2)
        for v in range(k):
            if v == tets[a, 0] or v == tets[a, 1] or v == tets[a, 2] or v == tets[a, 3]:
                continue
            d0, d1, d2 = points[v, 0] - centre[a, 0], points[v, 1] - centre[a, 1], points[v, 2] - centre[a, 2]
            gap = fabs(sqrt((d0 * d0 + d1 * d1) + d2 * d2) - radius)
            if not gap > cospherical * radius:
                return None
        for f in range(4):  # the face without corner f, its corners sorted
            w = 0
            for r in range(4):
                if r != f:
                    q[w] = tets[a, r]
                    w += 1
            if q[0] > q[1]:
                q[0], q[1] = q[1], q[0]
            if q[1] > q[2]:
                q[1], q[2] = q[2], q[1]
            if q[0] > q[1]:
                q[0], q[1] = q[1], q[0]
            allowed[(q[0] * k + q[1]) * k + q[2]] = 1
    return allowed_

# Liepa's refinement (section 4): centroid splits, then Delaunay edge flips

cdef inline bint _has(const int64_t* sorted_, int64_t n, int64_t key, int64_t stride=1) noexcept nogil:
    cdef int64_t lo = _lower(sorted_, n, key, stride)
    return lo < n and sorted_[lo * stride] == key

cdef bint _in_circumsphere(const double* p0, const double* p1, const double* p2, const double* q) noexcept nogil:
    """Whether ``q`` is inside the circumsphere of ``(p0, p1, p2)`` by a relative margin."""
    cdef double[3] u, v, w, wu, vw, centre, e
    cdef double ww, safe, uu, vv, radius
    cdef int c
    _sub(p1, p0, u)
    _sub(p2, p0, v)
    _cross(u, v, w)
    ww = _dot(w, w)
    safe = ww if ww > 0 else 1.0
    uu, vv = _dot(u, u), _dot(v, v)
    _cross(w, u, wu)
    _cross(v, w, vw)
    for c in range(3):
        centre[c] = p0[c] + (wu[c] * vv + vw[c] * uu) / (2.0 * safe)
    _sub(centre, p0, e)
    radius = sqrt(_dot(e, e)) if ww > 0 else INFINITY
    _sub(q, centre, e)
    return sqrt(_dot(e, e)) < radius * _COCIRCULAR

cdef bint _flip_improves(const double* pa, const double* pb, const double* pc, const double* pd,
                         bint smooth=False) noexcept nogil:
    """Whether edge ``(a, b)`` between ``(a, b, c)`` and ``(b, a, d)`` flips to ``(c, d)`` (docs page); with
    ``smooth``, only to a crease no sharper (the cosine of the new triangles' normals not below the old)."""
    cdef double[3] n1, n2, m2, old
    cdef double crease = 0.0
    cdef int c
    if not (_in_circumsphere(pa, pb, pc, pd) or _in_circumsphere(pb, pa, pd, pc)):
        return False
    _normal(pa, pb, pc, n1)
    _normal(pb, pa, pd, n2)
    for c in range(3):
        old[c] = n1[c] + n2[c]
    if smooth:
        crease = _dot(n1, n2) / sqrt(_dot(n1, n1) * _dot(n2, n2))
    _normal(pc, pa, pd, n1)
    if not _dot(n1, old) > 0:
        return False
    _normal(pd, pb, pc, m2)
    if not _dot(m2, old) > 0:
        return False
    if smooth and not _dot(n1, m2) / sqrt(_dot(n1, n1) * _dot(m2, m2)) >= crease:
        return False
    return fmin(_min_angle(pc, pa, pd), _min_angle(pd, pb, pc)) > (
        fmin(_min_angle(pa, pb, pc), _min_angle(pb, pa, pd)) + 1e-9
    )

cdef int _relax(const double* points, int64_t* tris, int64_t t, const int64_t* fixed, int64_t n_fixed,
                uint8_t* dirty, bint smooth=False) noexcept nogil:
    """Delaunay edge flips (Liepa's relaxation) in passes of independent flips until none applies; -1 if
    out of memory."""
    cdef int64_t nh = 3 * t, ne, e, i, h1, h2, t1, t2, s1, s2, a, b, c, d, n_prop, n_cand, n_removed = 0
    cdef int64_t key, n_new
    cdef int pass_
    cdef Half* half = <Half*>malloc(max(nh, 1) * sizeof(Half))
    cdef int64_t* pairs = <int64_t*>malloc(max(nh, 1) * sizeof(int64_t))  # (h1, h2) of each interior edge
    cdef int64_t* proposed = <int64_t*>malloc(max(nh, 1) * sizeof(int64_t))
    cdef int64_t* owner = <int64_t*>malloc(max(t, 1) * sizeof(int64_t))
    cdef int64_t* removed = <int64_t*>malloc(max(nh, 1) * sizeof(int64_t))
    cdef Half* chosen = <Half*>malloc(max(nh, 1) * sizeof(Half))
    cdef uint8_t* keep = <uint8_t*>malloc(max(nh, 1))
    cdef Half* spare = <Half*>malloc(max(nh, 1) * sizeof(Half))
    cdef int64_t* count = <int64_t*>malloc(8 * 256 * sizeof(int64_t))
    if not (half and pairs and proposed and owner and removed and chosen and keep and spare and count):
        free(half); free(pairs); free(proposed); free(owner); free(removed); free(chosen); free(keep)
        free(spare); free(count)
        return -1
    for pass_ in range(100):
        # the interior edges in key order: consecutive equal keys of the sorted half-edges
        for i in range(nh):
            half[i].key = _key(tris[i], tris[3 * (i // 3) + (i % 3 + 1) % 3])
            half[i].h = i
        _sort_halves(half, spare, nh, count)
        ne = 0
        for i in range(nh - 1):
            if half[i + 1].key == half[i].key:
                pairs[2 * ne], pairs[2 * ne + 1] = half[i].h, half[i + 1].h
                ne += 1
        if ne == 0:
            break
        n_prop = 0
        for e in range(ne):
            h1, h2 = pairs[2 * e], pairs[2 * e + 1]
            t1, s1, t2, s2 = h1 // 3, h1 % 3, h2 // 3, h2 % 3
            a, b = tris[h1], tris[3 * t1 + (s1 + 1) % 3]
            c, d = tris[3 * t1 + (s1 + 2) % 3], tris[3 * t2 + (s2 + 2) % 3]
            key = _key(c, d)
            if not (dirty[t1] or dirty[t2] or _has(removed, n_removed, key)):
                continue
            if c == d or _has(&half[0].key, nh, key, 2) or _has(fixed, n_fixed, key):
                continue
            if _flip_improves(points + 3 * a, points + 3 * b, points + 3 * c, points + 3 * d, smooth):
                proposed[n_prop] = e
                n_prop += 1
        if n_prop == 0:
            break
        # independent set: each triangle takes part in at most one flip of this pass, the first proposed
        for i in range(t):
            owner[i] = -1
        for i in range(n_prop):
            e = proposed[i]
            if owner[pairs[2 * e] // 3] < 0:
                owner[pairs[2 * e] // 3] = e
            if owner[pairs[2 * e + 1] // 3] < 0:
                owner[pairs[2 * e + 1] // 3] = e
        n_cand = 0
        for i in range(n_prop):
            e = proposed[i]
            h1, h2 = pairs[2 * e], pairs[2 * e + 1]
            if owner[h1 // 3] == e and owner[h2 // 3] == e:
                t1, s1, t2, s2 = h1 // 3, h1 % 3, h2 // 3, h2 % 3
                chosen[n_cand].key = _key(tris[3 * t1 + (s1 + 2) % 3], tris[3 * t2 + (s2 + 2) % 3])
                chosen[n_cand].h = e
                n_cand += 1
        # two flips must not make the same edge: the first (in edge order) of each new key
        qsort(chosen, n_cand, sizeof(Half), _by_key)
        for i in range(n_cand):
            keep[i] = i == 0 or chosen[i].key != chosen[i - 1].key
        for i in range(t):
            dirty[i] = 0
        for i in range(n_prop):
            e = proposed[i]
            dirty[pairs[2 * e] // 3] = 1
            dirty[pairs[2 * e + 1] // 3] = 1
        n_removed = 0
        for i in range(n_cand):
            if not keep[i]:
                continue
            e = chosen[i].h
            h1, h2 = pairs[2 * e], pairs[2 * e + 1]
            t1, s1, t2, s2 = h1 // 3, h1 % 3, h2 // 3, h2 % 3
            a, b = tris[h1], tris[3 * t1 + (s1 + 1) % 3]
            c, d = tris[3 * t1 + (s1 + 2) % 3], tris[3 * t2 + (s2 + 2) % 3]
            removed[n_removed] = _key(a, b)
            n_removed += 1
            tris[3 * t1], tris[3 * t1 + 1], tris[3 * t1 + 2] = c, a, d
            tris[3 * t2], tris[3 * t2 + 1], tris[3 * t2 + 2] = d, b, c
        qsort(removed, n_removed, sizeof(int64_t), _by_value)
    free(half); free(pairs); free(proposed); free(owner); free(removed); free(chosen); free(keep)
    free(spare); free(count)
    return 0

cdef int64_t[::1] _fixed_keys(fixed_pairs):
    """The sorted keys (``_key``) of edges ``(f, 2)``."""
    pairs = np.ascontiguousarray(fixed_pairs, dtype=np.int64).reshape(-1, 2)
    return np.sort((pairs.min(axis=1) << 32) | pairs.max(axis=1))

def relax(const double[:, ::1] points, triangles, fixed_pairs, dirty, bint smooth=False):
    """Liepa's relaxation of a patch: the flipped ``(t, 3)`` triangles; ``fixed_pairs (f, 2)`` edges no flip
    may make, ``dirty (t,)`` the triangles tested first."""
    out = np.array(triangles, dtype=np.int64, order="C", copy=True)
    mask = np.array(dirty, dtype=np.uint8, copy=True)
    if out.ndim != 2 or out.shape[1] != 3 or mask.shape != (len(out),):
        raise ValueError("triangles must be (t, 3) and dirty (t,)")
    if len(out) and (out.min() < 0 or out.max() >= points.shape[0]):
        raise ValueError("triangles index outside points")
    if points.shape[0] >= 2**31:
        raise ValueError("a local mesh has fewer than 2^31 vertices")
    cdef int64_t[:, ::1] tris = out
    cdef uint8_t[::1] d = mask
    cdef int64_t[::1] fixed = _fixed_keys(fixed_pairs)
    cdef int64_t t = len(out)
    cdef int status = 0
    if t:
        with nogil:
            status = _relax(&points[0, 0], &tris[0, 0], t, &fixed[0] if fixed.shape[0] else NULL,
                            fixed.shape[0], &d[0], smooth)
    if status:
        raise MemoryError
    return out

def refine(points, sigma, triangles, fixed_pairs, owner, double alpha, int64_t max_points=-1):
    """Liepa's refinement: rounds of centroid splits, each followed by a relaxation, until none splits or
    a round would pass ``max_points``; the points, the triangles and the points' owners."""
    cdef int64_t nv = len(points), t = len(triangles), cap_v, cap_t, i, j, m, count, a, b, c, p
    cap_v, cap_t = 2 * nv + 16, 3 * t + 16
    P_, S_, O_ = np.empty((cap_v, 3)), np.empty(cap_v), np.empty(cap_v, dtype=np.int64)
    T_, D_, C_ = np.empty((cap_t, 3), dtype=np.int64), np.empty(cap_t, dtype=np.uint8), np.empty(t, dtype=np.int64)
    P_[:nv], S_[:nv], O_[:nv], T_[:t] = points, sigma, owner, triangles
    cdef double[:, ::1] P = P_
    cdef double[::1] S = S_
    cdef int64_t[::1] O = O_, chosen = C_, fan
    cdef int64_t[:, ::1] T = T_
    cdef uint8_t[::1] D = D_
    cdef int64_t[::1] fixed = _fixed_keys(fixed_pairs)
    cdef double[3] centre, e
    cdef double sigma_c, dist
    cdef bint split, relaxed = False
    cdef int status = 0
    for _ in range(60):
        count = 0
        fan = np.zeros(nv, dtype=np.int64)
        with nogil:
            for i in range(t):
                for m in range(3):
                    fan[T[i, m]] += 1
            for i in range(t):
                for j in range(3):
                    centre[j] = (P[T[i, 0], j] + P[T[i, 1], j] + P[T[i, 2], j]) / 3.0
                sigma_c = (S[T[i, 0]] + S[T[i, 1]] + S[T[i, 2]]) / 3.0
                # a split adds a triangle at each corner: none at a corner of _MAX_FAN triangles, where
                # flips could not keep up (folded pieces of a long loop grew fans of thousands)
                split = fan[T[i, 0]] < _MAX_FAN and fan[T[i, 1]] < _MAX_FAN and fan[T[i, 2]] < _MAX_FAN
                for m in range(3):
                    if not split:
                        break
                    _sub(centre, &P[T[i, m], 0], e)
                    dist = sqrt(_dot(e, e))
                    if not alpha * dist > fmax(sigma_c, S[T[i, m]]):
                        split = False
                if split:
                    chosen[count] = i
                    count += 1
        if count == 0 or (max_points >= 0 and nv + count > max_points):
            break
        if nv + count > cap_v or t + 2 * count > cap_t:  # grow the buffers (amortized doubling)
            cap_v, cap_t = max(2 * cap_v, nv + count), max(2 * cap_t, t + 2 * count)
            P_, S_, O_ = np.resize(P_, (cap_v, 3)), np.resize(S_, cap_v), np.resize(O_, cap_v)
            T_, D_ = np.resize(T_, (cap_t, 3)), np.resize(D_, cap_t)
            P, S, O, T, D = P_, S_, O_, T_, D_
        with nogil:
            for i in range(count):  # the centroid splits (a, b, c) into (a, b, p), (b, c, p), (c, a, p)
                j, p = chosen[i], nv + i
                a, b, c = T[j, 0], T[j, 1], T[j, 2]
                for m in range(3):
                    P[p, m] = (P[a, m] + P[b, m] + P[c, m]) / 3.0
                S[p] = (S[a] + S[b] + S[c]) / 3.0
                O[p] = O[a]
                T[j, 2] = p
                T[t + i, 0], T[t + i, 1], T[t + i, 2] = b, c, p
                T[t + count + i, 0], T[t + count + i, 1], T[t + count + i, 2] = c, a, p
            for i in range(t + 2 * count):
                D[i] = not relaxed or i >= t
            for i in range(count):
                D[chosen[i]] = 1
            nv += count
            t += 2 * count
            status = _relax(&P[0, 0], &T[0, 0], t, &fixed[0] if fixed.shape[0] else NULL, fixed.shape[0],
                            &D[0])
        if status:
            raise MemoryError
        relaxed = True
        if t > chosen.shape[0]:
            C_ = np.empty(t, dtype=np.int64)
            chosen = C_
    return P_[:nv].copy(), T_[:t].copy(), O_[:nv].copy()

# what the triangulation needs of a loop

def loop_geometry(loop_, const int64_t[::1] rows, vertices_, const int64_t[:, ::1] triangles,
                  const int64_t[::1] indptr, const int64_t[::1] data):
    """A loop's points ``(k, 3)``, the unit normals of the mesh triangles on its edges ``(k, 3)``, its mean
    edge length, and its chords that are mesh edges as pairs ``(c, 2)`` (``p < q``, sorted): no ``(k, k)``
    matrix, whose size a silhouette of tens of thousands of edges would square."""
    cdef const int64_t[::1] loop = loop_
    cdef const double[:, ::1] vertices = vertices_
    cdef int64_t k = loop.shape[0], n = vertices.shape[0], m = triangles.shape[0], p, q, r, lo, w
    cdef int64_t c, t
    if rows.shape[0] != k or indptr.shape[0] != n + 1:
        raise ValueError("rows must be (k,), indptr (n + 1,)")
    if k and _outside(&loop[0], k, n):
        raise ValueError("loop outside the mesh")
    loop_ = np.asarray(loop_)
    by_vertex_ = np.argsort(loop_, kind="stable")  # the loop sorted by vertex, ties by position
    sorted_, points_ = loop_[by_vertex_], np.asarray(vertices_)[loop_]
    outer_ = np.empty((k, 3))
    # each chord once per triangle at each end: at most three keys p k + q per triangle at a loop vertex
    fan = np.asarray(indptr)[loop_ + 1] - np.asarray(indptr)[loop_]  # each loop vertex's triangles
    keys_ = np.empty(3 * int(fan.sum()), dtype=np.int64)
    cdef int64_t[::1] by_vertex = by_vertex_, ordered = sorted_, keys = keys_
    cdef int64_t count = 0
    cdef double[:, ::1] points = points_, outer = outer_
    cdef double[3] u
    cdef double norm, spacing = 0.0
    with nogil:
        for p in range(k):
            t = rows[p] % m
            _normal(&vertices[triangles[t, 0], 0], &vertices[triangles[t, 1], 0], &vertices[triangles[t, 2], 0],
                    &outer[p, 0])
            norm = sqrt(_dot(&outer[p, 0], &outer[p, 0]))
            for c in range(3):
                outer[p, c] = outer[p, c] / (norm if norm > 0 else 1.0)
            _sub(&points[(p + 1) % k, 0], &points[p, 0], u)
            spacing += sqrt(_dot(u, u))
        for p in range(k):
            for r in range(indptr[loop[p]], indptr[loop[p] + 1]):
                t = data[r]
                for c in range(3):
                    w = triangles[t, c]
                    lo = _lower(&ordered[0], k, w, 1)
                    if lo < k and ordered[lo] == w and w != loop[p]:
                        q = by_vertex[lo]
                        if q != (p + 1) % k and p != (q + 1) % k:  # not one of the loop's own edges
                            keys[count] = min(p, q) * k + max(p, q)
                            count += 1
    spacing = spacing / k if k else 0.0
    chords = np.unique(keys_[:count])
    return points_, outer_, spacing, np.stack([chords // max(k, 1), chords % max(k, 1)], axis=1)

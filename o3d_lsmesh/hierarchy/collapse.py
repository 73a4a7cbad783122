"""One level of the volume-cost mesh hierarchy (Liu et al. 2001, section 4.1), vectorized.

A level removes an independent set of vertices, each by a half-edge collapse
``x -> k`` into the 1-ring neighbour ``k`` that minimizes the cone volume

    V(x -> k) = | sum_j (x_j - x_k) x (x_{j+1} - x_k) . (x - x_k) |.

Each term is six times the signed volume of the tetrahedron ``(x, x_j,
x_{j+1}, x_k)``, which is affine in ``x_k``; summed over the star of ``x`` it
collapses to ``|N_x . (x_k - x)|`` with ``N_x`` the sum of the (unnormalized,
doubled-area) normals of the triangles around ``x``. So one scatter-add per
level gives the volume of every candidate collapse, and no ordered 1-ring is
needed (boundary vertices use the open fan of their triangles).

Independence. A collapse ``x -> k`` changes the neighbour sets of ``N(x)``
(the 1-ring of ``x``) and nothing else, and its validity reads only the
neighbour sets of ``x`` and ``k`` and the positions of ``x`` and ``N(x)``,
which no half-edge collapse moves. Two collapses ``x -> k`` and ``y -> l``
are therefore independent when ``y, l`` are not in the closed 1-ring
``N[x]`` and ``x, k`` are not in ``N[y]``. Every level selects, greedily in
increasing ``cost(x) = alpha * min_edge(x) + beta * max_edge(x)``, a set of
collapses that are pairwise independent in this sense, so each one can be
validated on the level's mesh and all are applied at once.

Validity of ``x -> k`` (each is a per-edge array test):

* link condition: ``x`` and ``k`` have exactly the common neighbours of the
  edge's triangles (2 inside, 1 on a boundary edge). With a virtual vertex
  coning off each boundary loop this is the link condition of Dey et al.,
  and it keeps the mesh a 2-manifold with the same Euler characteristic;
* a boundary vertex collapses only along a boundary edge (so into a boundary
  neighbour), an interior vertex along an interior edge;
* no closed tetrahedron is collapsed (``x`` and ``k`` interior of valence 3),
  and no isolated triangle (``x`` and ``k`` on the boundary of valence 2):
  there the link condition of vertices holds but the one of edges does not;
* every triangle of the star of ``x`` that survives keeps its orientation
  (its new and old normals make an angle below ``max_normal_angle``) and
  does not become degenerate (area over summed squared edge lengths above
  ``min_quality``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..topology import directed_edges

__all__ = ["LevelCollapse", "collapse_level"]


@dataclass(frozen=True)
class LevelCollapse:
    """The collapses of one level, in the indices of the finer level ``i - 1``.

    Attributes
    ----------
    removed : (r,) int64
        Vertices removed, sorted.
    targets : (r,) int64
        The vertex each one was merged into (kept at level ``i``).
    ring_offsets : (r + 1,) int64
        CSR offsets into ``ring``.
    ring : (sum of valences,) int64
        The 1-ring of each removed vertex at level ``i - 1``, sorted.
    parent : (n_{i-1},) int64
        Index at level ``i`` of every vertex of level ``i - 1``.
    triangles : (m_i, 3) int64
        Triangles of level ``i``.
    """

    removed: np.ndarray
    targets: np.ndarray
    ring_offsets: np.ndarray
    ring: np.ndarray
    parent: np.ndarray
    triangles: np.ndarray


def _ranges(begin: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Concatenated ``arange(b, b + c)`` for every pair, vectorized."""
    total = int(counts.sum())
    offsets = np.cumsum(counts)
    offsets -= counts
    np.subtract(begin, offsets, out=offsets)
    out = np.repeat(offsets, counts)
    out += np.arange(total, dtype=np.int64)
    return out


class _Adjacency:
    """Directed edges of a manifold mesh in CSR order, from one sort of the half-edge keys.

    Every triangle on an edge contributes the key of each direction once, so
    after sorting, the run length of a key is the number of triangles on its
    edge whatever the orientation of the triangles.
    """

    def __init__(self, triangles: np.ndarray, n: int):
        self.src, self.dst, self.triangle_count = directed_edges(triangles, n)
        self.valence = np.bincount(self.src, minlength=n)
        self.indptr = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(self.valence, out=self.indptr[1:])
        self.boundary_edge = self.triangle_count == 1
        self.on_boundary = np.zeros(n, dtype=bool)
        self.on_boundary[self.src[self.boundary_edge]] = True
        self.n = n

    def rings(self, vertices: np.ndarray) -> np.ndarray:
        return self.dst[_ranges(self.indptr[vertices], self.valence[vertices])]

    def per_edge(self, values: np.ndarray) -> np.ndarray:
        """``values[src]``: a repeat, since ``src`` is sorted (cheaper than a gather)."""
        return np.repeat(values, self.valence)


def collapse_level(
    vertices: np.ndarray,
    triangles: np.ndarray,
    *,
    alpha: float = 1.0,
    beta: float = 0.01,
    max_removals: int | None = None,
    max_normal_angle: float = 60.0,
    min_quality: float = 1e-3,
    max_rounds: int = 12,
    max_tries: int = 3,
) -> LevelCollapse | None:
    """Select and apply one level of independent volume-cost half-edge collapses.

    Parameters
    ----------
    vertices : (n, 3) float64
        Positions of the level's vertices (all referenced).
    triangles : (m, 3) int64
        Edge-manifold triangles.
    alpha, beta : float
        Weights of the shortest and longest incident edge in the vertex cost.
    max_removals : int, optional
        Remove at most this many vertices (the cheapest of the selected set).
    max_normal_angle : float
        Largest angle in degrees a surviving triangle's normal may turn.
    min_quality : float
        Smallest ``2 * area / (sum of squared edge lengths)`` of a new triangle
        (an equilateral triangle has ``1/sqrt(3)``).
    max_rounds : int
        Rounds of the parallel greedy selection; undecided vertices wait for
        the next level.
    max_tries : int
        Targets tried per vertex, in increasing volume, before it waits for the
        next level.

    Returns
    -------
    LevelCollapse or None
        ``None`` when no valid collapse remains.
    """
    n = len(vertices)
    F = triangles
    adj = _Adjacency(F, n)
    src, dst, valence, indptr = adj.src, adj.dst, adj.valence, adj.indptr
    on_boundary = adj.on_boundary
    has_edges = valence > 0
    seg = indptr[:-1][has_edges]
    # component arrays: contiguous gathers and no (N, 3) temporaries
    X, Y, Z = (np.ascontiguousarray(vertices[:, i], dtype=np.float64) for i in range(3))

    # vertex cost of section 4.1
    dx = X[dst]
    dx -= adj.per_edge(X)
    dy = Y[dst]
    dy -= adj.per_edge(Y)
    dz = Z[dst]
    dz -= adj.per_edge(Z)
    # (x + z) + y: the summation order of np.einsum("ij,ij->i"), which the
    # levels were first defined with, so that results stay bit-identical
    length = dx * dx
    length += dz * dz
    length += dy * dy
    np.sqrt(length, out=length)
    min_edge = np.zeros(n)
    max_edge = np.zeros(n)
    min_edge[has_edges] = np.minimum.reduceat(length, seg)
    max_edge[has_edges] = np.maximum.reduceat(length, seg)
    cost = alpha * min_edge + beta * max_edge

    # cone volume |N_x . (x_k - x)| (module docstring)
    columns = [np.ascontiguousarray(F[:, c]) for c in range(3)]
    corner_coords = tuple((X[f], Y[f], Z[f]) for f in columns)
    del columns
    (x0, y0, z0), (x1, y1, z1), (x2, y2, z2) = corner_coords
    ux, uy, uz = x1 - x0, y1 - y0, z1 - z0
    vx, vy, vz = x2 - x0, y2 - y0, z2 - z0
    normal = (uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx)
    del ux, uy, uz, vx, vy, vz
    corners = F.ravel()
    volume = np.zeros(len(dst))
    for c in (0, 2, 1):  # einsum's order again
        star = np.bincount(corners, weights=np.repeat(normal[c], 3), minlength=n)
        volume += adj.per_edge(star) * (dx, dy, dz)[c]
    np.abs(volume, out=volume)
    del dx, dy, dz

    # the cheap per-edge rules first; the link condition and the geometry are
    # checked for each vertex's best remaining target only
    src_boundary = adj.per_edge(on_boundary)
    dst_boundary = on_boundary[dst]
    src_valence = adj.per_edge(valence)
    dst_valence = valence[dst]
    ok = np.where(src_boundary, adj.boundary_edge, ~adj.boundary_edge)
    ok &= ~(~src_boundary & ~dst_boundary & (src_valence == 3) & (dst_valence == 3))
    ok &= ~(src_boundary & dst_boundary & (src_valence == 2) & (dst_valence == 2))
    del src_boundary, dst_boundary, src_valence, dst_valence

    geometry = _Geometry(X, Y, Z, F, corner_coords, normal, n, max_normal_angle, min_quality)
    target = np.full(n, -1, dtype=np.int64)
    # every vertex is offered its best target; later tries only revisit the
    # vertices whose pick failed, on their own edges
    pick = _best_targets(volume, length, ok, src, seg)
    for attempt in range(max_tries):
        if len(pick) == 0:
            break
        x, k = src[pick], dst[pick]
        good = _link_condition(adj, x, k, pick) & geometry(x, k)
        target[x[good]] = k[good]
        if attempt == max_tries - 1:
            break
        ok[pick[~good]] = False
        retry = x[~good]
        if len(retry) == 0:
            break
        edges = _ranges(indptr[retry], valence[retry])
        sub_seg = np.zeros(len(retry), dtype=np.int64)
        np.cumsum(valence[retry][:-1], out=sub_seg[1:])
        local = _best_targets(volume[edges], length[edges], ok[edges], src[edges], sub_seg)
        pick = edges[local]
    del volume, length, ok, geometry, corner_coords

    candidate = target >= 0
    if not candidate.any():
        return None
    selected = _select_independent(cost, candidate, target, adj, max_rounds)
    if max_removals is not None and len(selected) > max_removals:
        cheapest = np.lexsort((selected, cost[selected]))[:max_removals]
        selected = np.sort(selected[cheapest])
    if len(selected) == 0:
        return None

    removed = selected
    targets = target[removed]
    keep = np.ones(n, dtype=bool)
    keep[removed] = False
    parent = np.cumsum(keep) - 1
    parent[removed] = parent[targets]
    mapped = parent[F]
    alive = (mapped[:, 0] != mapped[:, 1]) & (mapped[:, 1] != mapped[:, 2]) & (mapped[:, 2] != mapped[:, 0])
    new_triangles = np.ascontiguousarray(mapped[alive])

    ring_counts = valence[removed]
    ring_offsets = np.zeros(len(removed) + 1, dtype=np.int64)
    np.cumsum(ring_counts, out=ring_offsets[1:])
    ring = adj.rings(removed)
    return LevelCollapse(removed, targets, ring_offsets, ring, parent, new_triangles)


def _best_targets(volume, length, ok, src, seg):
    """Edge position of each vertex's valid target of least volume (ties: shortest edge, then first).

    The edges are grouped by vertex, ``seg`` holding the start of each group.
    """
    vol = np.where(ok, volume, np.inf)
    best = np.minimum.reduceat(vol, seg)
    counts = np.diff(np.append(seg, len(vol)))
    near = vol <= np.repeat(best * (1.0 + 1e-9), counts)
    near &= ok
    tie = np.where(near, length, np.inf)
    shortest = np.minimum.reduceat(tie, seg)
    near &= tie == np.repeat(shortest, counts)
    hits = np.flatnonzero(near)
    if len(hits) == 0:
        return hits
    first = np.ones(len(hits), dtype=bool)
    first[1:] = src[hits[1:]] != src[hits[:-1]]
    return hits[first]


def _link_condition(adj: _Adjacency, x: np.ndarray, k: np.ndarray, edge: np.ndarray) -> np.ndarray:
    """Whether ``x`` and ``k`` share exactly the opposite vertices of the edge ``x -> k``.

    Common neighbours are counted by sorting ``(query, neighbour)`` keys of both
    rings together: a neighbour of both appears twice.
    """
    n = np.int64(adj.n)
    q = len(x)
    query = np.arange(q, dtype=np.int64)
    if q == adj.n and q == len(adj.valence) and adj.valence.all():
        # every vertex asks (x is sorted): its rings are the whole CSR
        ring_x = np.repeat(query * n, adj.valence)
        ring_x += adj.dst
    else:
        ring_x = np.repeat(query * n, adj.valence[x])
        ring_x += adj.rings(x)
    ring_k = np.repeat(query * n, adj.valence[k])
    ring_k += adj.rings(k)
    keys = np.concatenate([ring_x, ring_k])
    del ring_x, ring_k
    keys.sort()
    twice = keys[1:][keys[1:] == keys[:-1]]
    twice //= n
    common = np.bincount(twice, minlength=q)
    return common == adj.triangle_count[edge]


class _Geometry:
    """Whether moving ``x`` onto ``k`` keeps every surviving star triangle unflipped and non-degenerate."""

    def __init__(self, X, Y, Z, F, corner_coords, normal, n, max_normal_angle, min_quality):
        self.X, self.Y, self.Z, self.F, self.n = X, Y, Z, F, n
        self.corner_coords = corner_coords  # ((X, Y, Z) of column 0, of column 1, of column 2) of F
        self.normal = normal
        ox, oy, oz = normal
        self.old_sq = ox * ox + oz * oz + oy * oy  # einsum's order
        self.cos_sq = np.cos(np.deg2rad(max_normal_angle)) ** 2
        self.min_quality = min_quality

    def _bad(self, ax, ay, az, bx, by, bz, ox, oy, oz, old_sq):
        """Flipped or degenerate new triangles ``(k, a, b)``, from ``a - k`` and ``b - k``."""
        nx = ay * bz - az * by
        ny = az * bx - ax * bz
        nz = ax * by - ay * bx
        new_sq = nx * nx + ny * ny + nz * nz
        dot = nx * ox + ny * oy + nz * oz
        del nx, ny, nz
        bad = dot <= 0
        dot *= dot
        bound = self.cos_sq * new_sq
        bound *= old_sq
        bad |= dot <= bound
        del dot, bound
        squared = ax * ax + ay * ay + az * az + bx * bx + by * by + bz * bz
        bx = bx - ax
        by = by - ay
        bz = bz - az
        squared += bx * bx
        squared += by * by
        squared += bz * bz
        squared *= self.min_quality
        squared *= squared
        bad |= new_sq <= squared
        return bad

    def __call__(self, x: np.ndarray, k: np.ndarray) -> np.ndarray:
        X, Y, Z, F, n = self.X, self.Y, self.Z, self.F, self.n
        query_of = np.full(n, -1, dtype=np.int64)
        query_of[x] = np.arange(len(x))
        if 2 * len(x) > n:
            return self._all_corners(query_of, k, len(x))
        flat = F.ravel()
        c = np.flatnonzero(query_of[flat] >= 0)
        q = query_of[flat[c]]
        t = c // 3
        p = c - 3 * t
        a = flat[3 * t + _NEXT[p]]
        b = flat[3 * t + _PREV[p]]
        kk = k[q]
        survives = (a != kk) & (b != kk)
        t, a, b, kk, q = t[survives], a[survives], b[survives], kk[survives], q[survives]
        kx, ky, kz = X[kk], Y[kk], Z[kk]
        ox, oy, oz = self.normal
        bad = self._bad(X[a] - kx, Y[a] - ky, Z[a] - kz, X[b] - kx, Y[b] - ky, Z[b] - kz,
                        ox[t], oy[t], oz[t], self.old_sq[t])
        return np.bincount(q[bad], minlength=len(x)) == 0

    def _all_corners(self, query_of, k, q):
        """Most vertices are queried: go triangle by triangle, so that a triangle's own
        coordinates and old normal are read without a gather, one corner column at a time."""
        X, Y, Z, F = self.X, self.Y, self.Z, self.F
        ox, oy, oz = self.normal
        target_of = np.full(self.n, -1, dtype=np.int64)
        asked = query_of >= 0
        target_of[asked] = k[query_of[asked]]
        bad_queries = []
        for p in range(3):
            a, b = _NEXT[p], _PREV[p]
            kk = target_of[F[:, p]]
            live = kk >= 0
            live &= F[:, a] != kk
            live &= F[:, b] != kk
            rows = np.flatnonzero(live)
            kk = kk[rows]
            kx, ky, kz = X[kk], Y[kk], Z[kk]
            (axs, ays, azs), (bxs, bys, bzs) = self.corner_coords[a], self.corner_coords[b]
            bad = self._bad(axs[rows] - kx, ays[rows] - ky, azs[rows] - kz,
                            bxs[rows] - kx, bys[rows] - ky, bzs[rows] - kz,
                            ox[rows], oy[rows], oz[rows], self.old_sq[rows])
            bad_queries.append(query_of[F[rows[bad], p]])
        return np.bincount(np.concatenate(bad_queries), minlength=q) == 0


_NEXT = np.array([1, 2, 0])
_PREV = np.array([2, 0, 1])


def _select_independent(cost, candidate, target, adj: _Adjacency, max_rounds):
    """Greedy independent set of collapses in increasing ``(cost, index)`` order, by rounds of local minima.

    ``x`` and ``y`` conflict when ``y`` is in ``N(x)``, ``target[x]`` is in
    ``N(y)`` or ``target[y]`` is in ``N(x)`` (module docstring). A round takes
    every undecided candidate that precedes all its undecided conflicting
    candidates and drops those; run to the end, the rounds give the sequential
    greedy set.

    Each candidate keeps the number of its undecided conflicting candidates
    that precede it (with the multiplicity of the conflict lists below); a
    round's winners are those at zero, and only the conflicts of the vertices
    dropped in a round are revisited, so all rounds together touch every
    conflict about once instead of once per round.
    """
    n = len(cost)
    src, dst, valence, indptr = adj.src, adj.dst, adj.valence, adj.indptr
    cand = np.flatnonzero(candidate)
    none = np.int64(n)  # rank of non-candidates: after every candidate
    rank = np.full(n, none, dtype=np.int64)
    rank[cand[_stable_argsort(cost[cand])]] = np.arange(len(cand), dtype=np.int64)
    # the candidates grouped by target, for "target[y] in N(x)" (any order within a group)
    t_cand = target[cand]
    aiming = cand[np.argsort(t_cand)]
    aiming_count = np.bincount(t_cand, minlength=n)
    aiming_ptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(aiming_count, out=aiming_ptr[1:])

    # preceding conflicts through adjacency
    rank_src = adj.per_edge(rank)
    rank_dst = rank[dst]
    earlier = rank_dst < rank_src
    earlier &= rank_src < none
    count = np.bincount(src[earlier], minlength=n)
    del rank_src, rank_dst, earlier
    # through a target: pairs (x, w) with w in N(target[x]); x precedes w or w precedes x
    t_valence = valence[t_cand]
    w = dst[_ranges(indptr[t_cand], t_valence)]
    x = np.repeat(cand, t_valence)
    rank_x = np.repeat(rank[cand], t_valence)
    rank_w = rank[w]
    real = (rank_w < none) & (w != x)
    w_first = rank_w < rank_x
    count += np.bincount(x[real & w_first], minlength=n)
    count += np.bincount(w[real & ~w_first], minlength=n)
    del w, x, rank_x, rank_w, real, w_first

    state = np.zeros(n, dtype=np.int8)  # 0 undecided, 1 selected, 2 dropped
    state[~candidate] = 2
    undecided = cand
    for _ in range(max_rounds):
        if len(undecided) == 0:
            break
        winners = undecided[count[undecided] == 0]
        state[winners] = 1
        # every undecided conflicting candidate of a winner comes after it: drop it
        near_winner = np.zeros(n, dtype=bool)
        near_winner[adj.rings(winners)] = True
        near_winner_target = np.zeros(n, dtype=bool)
        near_winner_target[adj.rings(target[winners])] = True
        rest = undecided[state[undecided] == 0]
        lost_mask = near_winner[rest] | near_winner_target[rest] | near_winner[target[rest]]
        lost = rest[lost_mask]
        state[lost] = 2
        undecided = rest[~lost_mask]
        if len(undecided) == 0 or len(lost) == 0:
            continue
        # the dropped ones no longer hold back the undecided ones after them
        live_rank = np.full(n, -1, dtype=np.int64)
        live_rank[undecided] = rank[undecided]
        released = [
            other[live_rank[other] > owner_rank]
            for other, owner_rank in _conflicts(lost, rank, target, adj, aiming, aiming_count, aiming_ptr)
        ]
        count -= np.bincount(np.concatenate(released), minlength=n)
    return np.flatnonzero(state == 1)


def _conflicts(vertices, rank, target, adj, aiming, aiming_count, aiming_ptr):
    """The conflict multiset of each vertex, as counted in :func:`_select_independent`, in three parts.

    Yields ``(other, rank of its owner)``: ``other`` runs over ``N(x)``,
    ``N(target[x])`` and the candidates ``y`` with ``target[y]`` in ``N(x)``;
    ``x`` itself may appear in the last two, with its own rank, which no
    strict rank comparison lets through.
    """
    valence, indptr, dst = adj.valence, adj.indptr, adj.dst
    v1 = valence[vertices]
    ring = dst[_ranges(indptr[vertices], v1)]
    ring_rank = np.repeat(rank[vertices], v1)
    yield ring, ring_rank
    t = target[vertices]
    v2 = valence[t]
    yield dst[_ranges(indptr[t], v2)], np.repeat(rank[vertices], v2)
    c3 = aiming_count[ring]
    yield aiming[_ranges(aiming_ptr[ring], c3)], np.repeat(ring_rank, c3)


def _stable_argsort(values):
    """``np.argsort(values, kind="stable")``, by the much faster unstable sort when there are no ties."""
    order = np.argsort(values)
    ordered = values[order]
    if np.any(ordered[1:] == ordered[:-1]):
        return np.argsort(values, kind="stable")
    return order

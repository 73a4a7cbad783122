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

from ..topology import halfedges

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
    offsets = np.cumsum(counts) - counts
    return np.arange(total, dtype=np.int64) + np.repeat(begin - offsets, counts)


class _Adjacency:
    """Directed edges of a manifold mesh in CSR order, from one sort of the half-edge keys.

    Every triangle on an edge contributes the key of each direction once, so
    after sorting, the run length of a key is the number of triangles on its
    edge whatever the orientation of the triangles.
    """

    def __init__(self, triangles: np.ndarray, n: int):
        he = halfedges(triangles)
        forward = he[:, 0] * np.int64(n) + he[:, 1]
        backward = he[:, 1] * np.int64(n) + he[:, 0]
        keys = np.concatenate([forward, backward])
        keys.sort()
        first = np.ones(len(keys), dtype=bool)
        first[1:] = keys[1:] != keys[:-1]
        at = np.flatnonzero(first)
        self.keys = keys[at]
        self.triangle_count = np.diff(np.append(at, len(keys)))
        self.src = self.keys // n
        self.dst = self.keys - self.src * n
        self.valence = np.bincount(self.src, minlength=n)
        self.indptr = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(self.valence, out=self.indptr[1:])
        self.boundary_edge = self.triangle_count == 1
        self.on_boundary = np.zeros(n, dtype=bool)
        self.on_boundary[self.src[self.boundary_edge]] = True
        self.n = n

    def rings(self, vertices: np.ndarray) -> np.ndarray:
        return self.dst[_ranges(self.indptr[vertices], self.valence[vertices])]


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
    P = vertices
    F = triangles
    adj = _Adjacency(F, n)
    src, dst, valence, indptr = adj.src, adj.dst, adj.valence, adj.indptr
    on_boundary = adj.on_boundary
    has_edges = valence > 0
    seg = indptr[:-1][has_edges]

    # vertex cost of section 4.1
    vec = P[dst] - P[src]
    length = np.sqrt(np.einsum("ij,ij->i", vec, vec))
    min_edge = np.zeros(n)
    max_edge = np.zeros(n)
    min_edge[has_edges] = np.minimum.reduceat(length, seg)
    max_edge[has_edges] = np.maximum.reduceat(length, seg)
    cost = alpha * min_edge + beta * max_edge

    # cone volume |N_x . (x_k - x)| (module docstring)
    face_normal = np.cross(P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]])
    corners = F.ravel()
    star_normal = np.stack(
        [np.bincount(corners, weights=np.repeat(face_normal[:, c], 3), minlength=n) for c in range(3)],
        axis=1,
    )
    volume = np.abs(np.einsum("ij,ij->i", star_normal[src], vec))

    # the cheap per-edge rules first; the link condition and the geometry are
    # checked for each vertex's best remaining target only
    ok = np.where(on_boundary[src], adj.boundary_edge, ~adj.boundary_edge)
    interior_pair = ~on_boundary[src] & ~on_boundary[dst]
    ok &= ~(interior_pair & (valence[src] == 3) & (valence[dst] == 3))
    ok &= ~(on_boundary[src] & on_boundary[dst] & (valence[src] == 2) & (valence[dst] == 2))

    target = np.full(n, -1, dtype=np.int64)
    for _ in range(max_tries):
        pick = _best_targets(volume, length, ok, src, seg, has_edges, n)
        pick = pick[target[src[pick]] < 0]
        if len(pick) == 0:
            break
        x, k = src[pick], dst[pick]
        good = _link_condition(adj, x, k, pick) & _geometry(P, F, face_normal, x, k, n, max_normal_angle, min_quality)
        target[x[good]] = k[good]
        ok[pick[~good]] = False
        # vertices with a valid target are settled: stop offering their other edges
        ok[pick[good]] = False

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


def _best_targets(volume, length, ok, src, seg, has_edges, n):
    """Directed-edge position of each vertex's valid target of least volume (ties: shortest edge)."""
    vol = np.where(ok, volume, np.inf)
    best = np.full(n, np.inf)
    best[has_edges] = np.minimum.reduceat(vol, seg)
    near = ok & (vol <= best[src] * (1.0 + 1e-9))
    tie = np.where(near, length, np.inf)
    shortest = np.full(n, np.inf)
    shortest[has_edges] = np.minimum.reduceat(tie, seg)
    hits = np.flatnonzero(near & (tie == shortest[src]))
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
    n = adj.n
    q = len(x)
    query = np.arange(q, dtype=np.int64)
    keys = np.concatenate(
        [
            np.repeat(query, adj.valence[x]) * n + adj.rings(x),
            np.repeat(query, adj.valence[k]) * n + adj.rings(k),
        ]
    )
    keys.sort()
    twice = keys[1:][keys[1:] == keys[:-1]]
    common = np.bincount(twice // n, minlength=q)
    return common == adj.triangle_count[edge]


def _geometry(P, F, face_normal, x, k, n, max_normal_angle, min_quality):
    """Whether moving ``x`` onto ``k`` keeps every surviving star triangle unflipped and non-degenerate."""
    query_of = np.full(n, -1, dtype=np.int64)
    query_of[x] = np.arange(len(x))
    corner_query = query_of[F.ravel()]
    if 2 * len(x) > n:  # most vertices are queried: scan every corner
        c = None
        q = corner_query
        t = np.repeat(np.arange(len(F)), 3)
        a = F[:, [1, 2, 0]].ravel()
        b = F[:, [2, 0, 1]].ravel()
    else:
        c = np.flatnonzero(corner_query >= 0)
        q = corner_query[c]
        t = c // 3
        base = 3 * t
        p = c - base
        flat = F.ravel()
        a = flat[base + _NEXT[p]]
        b = flat[base + _PREV[p]]
    kk = k[np.maximum(q, 0)]
    survives = (q >= 0) & (a != kk) & (b != kk)
    t, a, b, kk, q = t[survives], a[survives], b[survives], kk[survives], q[survives]
    # component-wise arithmetic: much faster than np.cross on (N, 3) gathers
    X, Y, Z = (np.ascontiguousarray(P[:, i]) for i in range(3))
    kx, ky, kz = X[kk], Y[kk], Z[kk]
    ax, ay, az = X[a] - kx, Y[a] - ky, Z[a] - kz
    bx, by, bz = X[b] - kx, Y[b] - ky, Z[b] - kz
    nx = ay * bz - az * by
    ny = az * bx - ax * bz
    nz = ax * by - ay * bx
    o = face_normal[t]
    new_sq = nx * nx + ny * ny + nz * nz
    old_sq = np.einsum("ij,ij->i", o, o)
    dot = nx * o[:, 0] + ny * o[:, 1] + nz * o[:, 2]
    cos_max = np.cos(np.deg2rad(max_normal_angle))
    turned = (dot <= 0) | (dot * dot <= cos_max * cos_max * new_sq * old_sq)
    abx, aby, abz = bx - ax, by - ay, bz - az
    squared = ax * ax + ay * ay + az * az + bx * bx + by * by + bz * bz + abx * abx + aby * aby + abz * abz
    degenerate = new_sq <= (min_quality * squared) ** 2
    return np.bincount(q[turned | degenerate], minlength=len(x)) == 0


_NEXT = np.array([1, 2, 0])
_PREV = np.array([2, 0, 1])


def _select_independent(cost, candidate, target, adj: _Adjacency, max_rounds):
    """Greedy independent set of collapses in increasing ``(cost, index)`` order, by rounds of local minima.

    ``x`` and ``y`` conflict when ``y`` is in ``N(x)``, ``target[x]`` is in
    ``N(y)`` or ``target[y]`` is in ``N(x)`` (module docstring). A round takes
    every undecided candidate that precedes all its undecided conflicting
    candidates and drops those; run to the end, the rounds give the sequential
    greedy set.
    """
    n = len(cost)
    src, dst = adj.src, adj.dst
    cand = np.flatnonzero(candidate)
    # conflicts through adjacency (both directions are already listed)
    both = candidate[src] & candidate[dst]
    u1, v1 = src[both], dst[both]
    # conflicts through a target: y in N(target[x])
    t = target[cand]
    u2 = np.repeat(cand, adj.valence[t])
    v2 = adj.rings(t)
    keep = candidate[v2] & (v2 != u2)
    u2, v2 = u2[keep], v2[keep]
    u = np.concatenate([u1, u2, v2])
    v = np.concatenate([v1, v2, u2])
    # v precedes u in the greedy order
    before = (cost[v] < cost[u]) | ((cost[v] == cost[u]) & (v < u))
    u, v = u[before], v[before]

    state = np.zeros(n, dtype=np.int8)  # 0 undecided, 1 selected, 2 dropped
    state[~candidate] = 2
    undecided = cand
    for _ in range(max_rounds):
        if len(undecided) == 0:
            break
        blocked = np.zeros(n, dtype=bool)
        blocked[u] = True
        winners = undecided[~blocked[undecided]]
        state[winners] = 1
        # drop the later conflicting candidates of each winner
        lost = u[state[v] == 1]
        state[lost[state[lost] == 0]] = 2
        undecided = undecided[state[undecided] == 0]
        live = (state[u] == 0) & (state[v] == 0)
        u, v = u[live], v[live]
    return np.flatnonzero(state == 1)

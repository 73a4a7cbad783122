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
(the 1-ring of ``x``, ``k`` included) and nothing else, and its validity
reads only the neighbour sets of ``x`` and ``k`` and the positions of ``x``
and ``N(x)``, which no half-edge collapse moves. So a collapse ``y -> l``
stays valid after ``x -> k`` when ``y`` and ``l`` are not in the closed
1-ring ``N[x]``. Every level selects, greedily in increasing
``cost(x) = alpha * min_edge(x) + beta * max_edge(x)``, collapses that each
satisfy this against every one selected before it; each is validated on the
level's mesh, and all are applied at once, which gives the mesh of applying
them one by one in cost order (no triangle holds two removed vertices, so
none is changed twice).

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

Blocks and threads. The per-edge terms, the flip test, the link condition
and the follower lists of the selection are computed over blocks of vertex
rings, triangles or queries, which can run on a thread pool (numpy releases
the GIL in its loops); each block writes its own slice or returns its own
array, combined in block order, so the level is the same for any number of
threads and any block size.
"""

from __future__ import annotations

import itertools
from concurrent.futures import Executor
from dataclasses import dataclass

import numpy as np

from ..topology import _group, directed_edges

__all__ = ["LevelCollapse", "collapse_level"]

# Work goes by blocks of these many directed edges, triangles or link queries, so that the
# temporaries stay small: the allocator then reuses their memory, where every level-sized
# temporary costs fresh pages (which take the kernel longer to provide than the arithmetic on
# them), and the blocks can run on several threads (numpy releases the GIL in its loops).
_EDGE_BLOCK = 1 << 19
_TRIANGLE_BLOCK = 1 << 18
_QUERY_BLOCK = 1 << 17


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


def _map(executor, fn, items):
    """``[fn(*item) for item in items]``, on ``executor``'s threads when given (results in order).

    ``fn`` only writes to disjoint slices of shared arrays or returns new ones,
    so the result does not depend on the number of threads.
    """
    if executor is None or len(items) < 2:
        return [fn(*item) for item in items]
    return list(executor.map(lambda item: fn(*item), items))


def _vertex_blocks(indptr: np.ndarray, size: int) -> list[tuple[int, int]]:
    """Ranges ``(v0, v1)`` of whole vertex rings holding about ``size`` directed edges each."""
    n = len(indptr) - 1
    cuts = np.unique(np.searchsorted(indptr, np.arange(0, int(indptr[-1]), size), side="right") - 1)
    return [(int(v0), int(v1)) for v0, v1 in zip(cuts, np.append(cuts[1:], n))]


def _ranges(begin: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Concatenated ``arange(b, b + c)`` for every pair, vectorized."""
    total = int(counts.sum())
    offsets = _offsets(counts)
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

    def __init__(self, triangles: np.ndarray, n: int, executor=None):
        self.src, self.dst, self.triangle_count = directed_edges(triangles, n, executor=executor)
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
    max_rounds: int | None = None,
    max_tries: int = 3,
    executor: Executor | None = None,
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
    max_rounds : int, optional
        Rounds of the parallel greedy selection; vertices still undecided wait
        for the next level. ``None`` runs the rounds until every candidate is
        decided, which gives the sequential greedy set.
    max_tries : int
        Targets tried per vertex, in increasing volume, before it waits for the
        next level.
    executor : concurrent.futures.Executor, optional
        Thread pool on which the blocks of the level's work run (the result is
        the same with or without it).

    Returns
    -------
    LevelCollapse or None
        ``None`` when no valid collapse remains.
    """
    n = len(vertices)
    F = triangles
    adj = _Adjacency(F, n, executor)
    src, dst, valence, indptr = adj.src, adj.dst, adj.valence, adj.indptr
    # component arrays: contiguous gathers and no (N, 3) temporaries
    X, Y, Z = (np.ascontiguousarray(vertices[:, i], dtype=np.float64) for i in range(3))

    # triangle edge vectors and normals (for the cone volumes and the flip test)
    columns = np.ascontiguousarray(F.T)

    def edge_vectors(coordinate):
        base = coordinate.take(columns[0])
        u = coordinate.take(columns[1])
        u -= base
        v = coordinate.take(columns[2])
        v -= base
        return u, v

    (ux, vx), (uy, vy), (uz, vz) = _map(executor, edge_vectors, [(X,), (Y,), (Z,)])
    normal = (uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx)
    edges = ((ux, uy, uz), (vx, vy, vz))
    del ux, uy, uz, vx, vy, vz

    # N_x of the module docstring: the summed normals of the triangles around each vertex
    def star_component(weights):
        total = np.bincount(columns[0], weights=weights, minlength=n)
        total += np.bincount(columns[1], weights=weights, minlength=n)
        total += np.bincount(columns[2], weights=weights, minlength=n)
        return total

    star = _map(executor, star_component, [(c,) for c in normal])
    cost, length, volume, ok, pick = _edge_terms(adj, X, Y, Z, star, alpha, beta, executor)
    del star

    geometry = _Geometry(X, Y, Z, F, edges, normal, n, max_normal_angle, min_quality, executor)
    del edges
    target = np.full(n, -1, dtype=np.int64)
    # every vertex is offered its best target; later tries only revisit the
    # vertices whose pick failed, on their own edges
    for attempt in range(max_tries):
        if len(pick) == 0:
            break
        x, k = src[pick], dst[pick]
        # the geometry fails far more often than the link condition: test the link on its survivors
        good = geometry(x, k)
        good[good] = _link_condition(adj, x[good], k[good], pick[good], executor)
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
    del volume, length, ok, geometry

    candidate = target >= 0
    if not candidate.any():
        return None
    selected = _select_independent(cost, candidate, target, adj, max_rounds, executor)
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


def _edge_terms(adj: _Adjacency, X, Y, Z, star, alpha, beta, executor=None):
    """Per directed edge: length, cone volume ``|N_x . (x_k - x)|``, the per-edge rules (module
    docstring); per vertex: the cost of section 4.1 and the edge of its best pick.

    Computed over blocks of whole vertex rings (``_EDGE_BLOCK``), on ``executor`` when given.
    """
    n, src, dst, valence, indptr = adj.n, adj.src, adj.dst, adj.valence, adj.indptr
    total = len(dst)
    length = np.empty(total)
    volume = np.empty(total)
    ok = np.empty(total, dtype=bool)
    min_edge = np.zeros(n)
    max_edge = np.zeros(n)

    def run(v0, v1):
        e0, e1 = int(indptr[v0]), int(indptr[v1])
        if e0 == e1:
            return np.zeros(0, dtype=np.int64)
        d = dst[e0:e1]
        ring = valence[v0:v1]
        has = ring > 0
        seg = indptr[v0:v1][has] - e0
        dx = X[d]
        dx -= np.repeat(X[v0:v1], ring)
        dy = Y[d]
        dy -= np.repeat(Y[v0:v1], ring)
        dz = Z[d]
        dz -= np.repeat(Z[v0:v1], ring)
        # (x + z) + y: the summation order of np.einsum("ij,ij->i"), which the
        # levels were first defined with, so that results stay bit-identical
        part = length[e0:e1]
        np.multiply(dx, dx, out=part)
        part += dz * dz
        part += dy * dy
        np.sqrt(part, out=part)
        min_edge[v0:v1][has] = np.minimum.reduceat(part, seg)
        max_edge[v0:v1][has] = np.maximum.reduceat(part, seg)
        cone = volume[e0:e1]
        np.multiply(np.repeat(star[0][v0:v1], ring), dx, out=cone)
        for c, delta in ((2, dz), (1, dy)):  # einsum's order again
            delta *= np.repeat(star[c][v0:v1], ring)
            cone += delta
        np.abs(cone, out=cone)
        del dx, dy, dz
        # a boundary vertex collapses along a boundary edge, an interior one along an interior
        # edge; no closed tetrahedron, no isolated triangle
        src_boundary = np.repeat(adj.on_boundary[v0:v1], ring)
        dst_boundary = adj.on_boundary[d]
        src_valence = np.repeat(ring, ring)
        dst_valence = valence[d]
        boundary_edge = adj.boundary_edge[e0:e1]
        allowed = ok[e0:e1]
        np.copyto(allowed, np.where(src_boundary, boundary_edge, ~boundary_edge))
        allowed &= ~(~src_boundary & ~dst_boundary & (src_valence == 3) & (dst_valence == 3))
        allowed &= ~(src_boundary & dst_boundary & (src_valence == 2) & (dst_valence == 2))
        return _best_targets(cone, part, allowed, src[e0:e1], seg) + e0

    picks = _map(executor, run, _vertex_blocks(indptr, _EDGE_BLOCK))
    cost = alpha * min_edge + beta * max_edge
    return cost, length, volume, ok, np.concatenate(picks) if picks else np.zeros(0, dtype=np.int64)


def _best_targets(volume, length, ok, src, seg):
    """Edge position of each vertex's valid target of least volume (ties: shortest edge, then first).

    The edges are grouped by vertex, ``seg`` holding the start of each group.
    """
    vol = np.where(ok, volume, np.inf)
    best = np.minimum.reduceat(vol, seg)
    best *= 1.0 + 1e-9
    near = vol <= np.repeat(best, np.diff(np.append(seg, len(vol))))
    near &= ok
    hits = np.flatnonzero(near)
    if len(hits) == 0:
        return hits
    owner = src[hits]
    shared = np.zeros(len(hits), dtype=bool)
    np.equal(owner[1:], owner[:-1], out=shared[1:])
    if not shared.any():
        return hits
    # a few vertices have several picks within the tolerance: the shortest edge, then the first
    shared[:-1] |= shared[1:]
    tied = np.flatnonzero(shared)
    order = tied[np.lexsort((length[hits[tied]], owner[tied]))]
    first = np.ones(len(order), dtype=bool)
    first[1:] = owner[order[1:]] != owner[order[:-1]]
    keep = ~shared
    keep[order[first]] = True
    return hits[keep]


def _link_condition(adj: _Adjacency, x: np.ndarray, k: np.ndarray, edge: np.ndarray, executor=None) -> np.ndarray:
    """Whether ``x`` and ``k`` share exactly the opposite vertices of the edge ``x -> k``.

    Common neighbours are counted by sorting ``(query, neighbour)`` keys of both
    rings together: a neighbour of both appears twice. Large queries go by
    blocks (``_QUERY_BLOCK``), on ``executor`` when given.
    """
    block = _QUERY_BLOCK
    if len(x) > block:
        return np.concatenate(_map(executor, lambda i: _link_condition(
            adj, x[i:i + block], k[i:i + block], edge[i:i + block]
        ), [(i,) for i in range(0, len(x), block)]))
    shift = np.int64(max(1, int(adj.n - 1).bit_length()))
    q = len(x)
    query = np.arange(q, dtype=np.int64) << shift
    if q == adj.n and q == len(adj.valence) and adj.valence.all():
        # every vertex asks (x is sorted): its rings are the whole CSR
        ring_x = np.repeat(query, adj.valence)
        ring_x |= adj.dst
    else:
        ring_x = np.repeat(query, adj.valence[x])
        ring_x |= adj.rings(x)
    ring_k = np.repeat(query, adj.valence[k])
    ring_k |= adj.rings(k)
    keys = np.concatenate([ring_x, ring_k])
    del ring_x, ring_k
    keys.sort(kind="stable")  # two sorted runs (query-major, rings sorted): a merge
    twice = keys[1:][keys[1:] == keys[:-1]]
    twice >>= shift
    common = np.bincount(twice, minlength=q)
    return common == adj.triangle_count[edge]


class _Geometry:
    """Whether moving ``x`` onto ``k`` keeps every surviving star triangle unflipped and non-degenerate."""

    def __init__(self, X, Y, Z, F, edges, normal, n, max_normal_angle, min_quality, executor=None):
        self.X, self.Y, self.Z, self.F, self.n = X, Y, Z, F, n
        self.executor = executor
        self.edges = edges  # (u, v): corner 1 - corner 0 and corner 2 - corner 0 of every triangle, by component
        self.normal = normal
        ox, oy, oz = normal
        self.old_sq = ox * ox + oz * oz + oy * oy  # einsum's order
        self.cos_sq = np.cos(np.deg2rad(max_normal_angle)) ** 2
        self.min_quality = min_quality

    def _bad(self, ax, ay, az, bx, by, bz, ox, oy, oz, old_sq, opposite_sq=None):
        """Flipped or degenerate new triangles ``(k, a, b)``, from ``a - k`` and ``b - k`` (overwritten).

        ``opposite_sq`` is ``|b - a|^2`` when known (the edge the move leaves alone).
        """
        # in place throughout: these run over every corner of the level, and fresh temporaries
        # cost as much as the arithmetic
        nx = ay * bz
        nx -= az * by
        ny = az * bx
        ny -= ax * bz
        nz = ax * by
        nz -= ay * bx
        dot = nx * ox
        dot += ny * oy
        dot += nz * oz
        nx *= nx
        ny *= ny
        nx += ny
        nz *= nz
        nx += nz
        new_sq = nx
        del ny, nz
        bad = dot <= 0
        dot *= dot
        bound = new_sq * self.cos_sq
        bound *= old_sq
        bad |= dot <= bound
        del dot, bound
        # squared edge lengths |a|^2 + |b|^2 + |b - a|^2, summed left to right
        squared = ax * ax
        squared += ay * ay
        squared += az * az
        squared += bx * bx
        squared += by * by
        squared += bz * bz
        if opposite_sq is not None:
            squared += opposite_sq
        else:
            bx -= ax
            by -= ay
            bz -= az
            bx *= bx
            squared += bx
            by *= by
            squared += by
            bz *= bz
            squared += bz
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
        ox, oy, oz = self.normal

        def run(r0, r1):
            flat = F[r0:r1].ravel()
            c = np.flatnonzero(query_of[flat] >= 0)
            q = query_of[flat[c]]
            t = c // 3
            p = c - 3 * t
            a = flat[3 * t + _NEXT[p]]
            b = flat[3 * t + _PREV[p]]
            kk = k[q]
            survives = (a != kk) & (b != kk)
            t, a, b, kk, q = t[survives], a[survives], b[survives], kk[survives], q[survives]
            t += r0
            kx, ky, kz = X[kk], Y[kk], Z[kk]
            bad = self._bad(X[a] - kx, Y[a] - ky, Z[a] - kz, X[b] - kx, Y[b] - ky, Z[b] - kz,
                            ox[t], oy[t], oz[t], self.old_sq[t])
            return q[bad]

        block = _TRIANGLE_BLOCK
        bad_queries = _map(self.executor, run, [(r0, min(r0 + block, len(F))) for r0 in range(0, len(F), block)])
        return np.bincount(np.concatenate(bad_queries), minlength=len(x)) == 0

    def _opposite_sq(self, p, rows):
        """Squared length of the edge opposite corner ``p`` of triangles ``rows``: ``v - u``, ``v``, ``u``."""
        (ux, uy, uz), (vx, vy, vz) = self.edges
        if p == 0:
            dx, dy, dz = vx[rows] - ux[rows], vy[rows] - uy[rows], vz[rows] - uz[rows]
            dx *= dx
            dy *= dy
            dz *= dz
        else:
            ex, ey, ez = (vx, vy, vz) if p == 1 else (ux, uy, uz)
            dx, dy, dz = ex[rows] * ex[rows], ey[rows] * ey[rows], ez[rows] * ez[rows]
        dx += dy
        dx += dz
        return dx

    def _all_corners(self, query_of, k, q):
        """Most vertices are queried: go triangle by triangle, one corner column at a time.

        The new triangle of corner ``x`` is ``(k, a, b)``, and ``a - k = (a - x) - d``,
        ``b - k = (b - x) - d`` with ``d = k - x``: the triangle's own edge vectors and one
        gather of ``d`` per corner, instead of gathering coordinates and normals row by row.
        """
        F, n = self.F, self.n
        ox, oy, oz = self.normal
        (ux, uy, uz), (vx, vy, vz) = self.edges
        target_of = np.full(n, -1, dtype=np.int64)
        asked = np.flatnonzero(query_of >= 0)
        target_of[asked] = k[query_of[asked]]
        kk = target_of[asked]
        shift = []
        for coordinate in (self.X, self.Y, self.Z):
            d = np.zeros(n)
            d[asked] = coordinate[kk]
            d[asked] -= coordinate[asked]
            shift.append(d)
        del kk

        def run(p, r0, r1):
            rows = slice(r0, r1)
            corner = F[rows, p]
            kk = target_of[corner]
            live = kk >= 0
            live &= F[rows, _NEXT[p]] != kk
            live &= F[rows, _PREV[p]] != kk
            del kk
            dx, dy, dz = (d[corner] for d in shift)
            # a - x and b - x: (u, v) at corner 0, (v - u, -u) at corner 1, (-v, u - v) at corner 2
            if p == 0:
                ax, ay, az = ux[rows] - dx, uy[rows] - dy, uz[rows] - dz
                bx, by, bz = vx[rows] - dx, vy[rows] - dy, vz[rows] - dz
            elif p == 1:
                ax, ay, az = vx[rows] - ux[rows], vy[rows] - uy[rows], vz[rows] - uz[rows]
                ax -= dx
                ay -= dy
                az -= dz
                bx, by, bz = -ux[rows] - dx, -uy[rows] - dy, -uz[rows] - dz
            else:
                ax, ay, az = -vx[rows] - dx, -vy[rows] - dy, -vz[rows] - dz
                bx, by, bz = ux[rows] - vx[rows], uy[rows] - vy[rows], uz[rows] - vz[rows]
                bx -= dx
                by -= dy
                bz -= dz
            del dx, dy, dz
            bad = self._bad(ax, ay, az, bx, by, bz, ox[rows], oy[rows], oz[rows], self.old_sq[rows],
                            self._opposite_sq(p, rows))
            bad &= live
            return query_of[corner[bad]]

        block = _TRIANGLE_BLOCK
        tasks = [(p, r0, min(r0 + block, len(F))) for p in range(3) for r0 in range(0, len(F), block)]
        bad_queries = _map(self.executor, run, tasks)
        return np.bincount(np.concatenate(bad_queries), minlength=q) == 0


_NEXT = np.array([1, 2, 0])
_PREV = np.array([2, 0, 1])


def _select_independent(cost, candidate, target, adj: _Adjacency, max_rounds, executor=None):
    """Greedy independent set of collapses in increasing ``(cost, index)`` order, by rounds of local minima.

    A later ``y`` conflicts with an earlier ``x`` when ``y`` is in ``N(x)`` or
    ``target[y]`` is in ``N[x]`` (module docstring). A round takes
    every undecided candidate that precedes all its undecided conflicting
    candidates and drops those; run to the end, the rounds give the sequential
    greedy set.

    The conflicts are listed once, each under the candidate that comes first
    (its *followers*), and every candidate keeps the number of undecided
    conflicting candidates that precede it. A round's winners are those at
    zero; their undecided followers are dropped, and the followers of the
    dropped ones count one fewer. Every list is read about twice in all
    rounds together, however many rounds the cost order needs.
    """
    n = len(cost)
    cand = np.flatnonzero(candidate)
    none = np.int64(n)  # rank of non-candidates: after every candidate
    rank = np.full(n, none, dtype=np.int64)
    rank[cand[_stable_argsort(cost[cand])]] = np.arange(len(cand), dtype=np.int64)
    followers = _Followers(rank, none, cand, target, adj, executor)
    count = followers.preceding(n)

    state = np.zeros(n, dtype=np.int8)  # 0 undecided, 1 selected, 2 dropped
    state[~candidate] = 2
    undecided = cand
    rounds = itertools.count() if max_rounds is None else range(max_rounds)
    for _ in rounds:
        if len(undecided) == 0:
            break
        winners = undecided[count[undecided] == 0]
        if len(winners) == 0:  # cannot happen (the first undecided one is free): never spin
            break
        state[winners] = 1
        # every undecided conflicting candidate of a winner comes after it: drop it
        lost = followers(winners)
        lost = lost[state[lost] == 0]
        state[lost] = 2
        undecided = undecided[state[undecided] == 0]
        if len(undecided) == 0 or len(lost) == 0:
            continue
        lost.sort()
        lost = lost[np.append(True, lost[1:] != lost[:-1])]
        # the dropped ones no longer hold back the undecided ones after them
        released = followers(lost)
        np.subtract.at(count, released[state[released] == 0], 1)
    return np.flatnonzero(state == 1)


class _Followers:
    """Each candidate's conflicting candidates that come after it, as two CSR lists.

    The followers of ``x`` are its later neighbours and the later candidates
    ``y`` with ``target[y]`` in ``N(x)`` (``target[y] == x`` makes ``y`` a
    neighbour): the second are found from ``y``'s side, as the earlier
    candidates around ``target[y]``, and filed under them.
    """

    def __init__(self, rank, none, cand, target, adj: _Adjacency, executor=None):
        n = len(rank)
        dst, valence, indptr = adj.dst, adj.valence, adj.indptr
        self.parts = []
        # by blocks of vertex rings (see _EDGE_BLOCK)
        # neighbours: the edges x -> y with x before y (both candidates); already grouped by x
        counts = np.zeros(n, dtype=np.int64)

        def neighbours(v0, v1):
            e0, e1 = int(indptr[v0]), int(indptr[v1])
            if e0 == e1:
                return np.zeros(0, np.int64)
            ring = valence[v0:v1]
            has = ring > 0
            d = dst[e0:e1]
            rank_dst = rank[d]
            later = np.repeat(rank[v0:v1], ring) < rank_dst
            later &= rank_dst < none
            counts[v0:v1][has] = np.add.reduceat(later, indptr[v0:v1][has] - e0)
            return d[later]

        later_neighbours = _map(executor, neighbours, _vertex_blocks(indptr, _EDGE_BLOCK))
        self._add(counts, np.concatenate(later_neighbours) if later_neighbours else np.zeros(0, np.int64))
        del later_neighbours
        # through a target: y follows each earlier candidate w around target[y]

        def through_targets(i, j):
            y = cand[i:j]
            t = target[y]
            t_valence = valence[t]
            w = dst[_ranges(indptr[t], t_valence)]
            earlier = rank[w] < np.repeat(rank[y], t_valence)  # y == w has equal ranks: not in
            return w[earlier], np.repeat(y, t_valence)[earlier]

        step = max(1, _EDGE_BLOCK // 8)
        pairs = _map(executor, through_targets, [(i, i + step) for i in range(0, len(cand), step)])
        owners = [w for w, _ in pairs]
        followers = [y for _, y in pairs]
        del pairs
        w = np.concatenate(owners) if owners else np.zeros(0, np.int64)
        y = np.concatenate(followers) if followers else np.zeros(0, np.int64)
        del owners, followers
        order = _group_by(w, n)
        w, y = w[order], y[order]
        self._add(np.bincount(w, minlength=n), y)

    def _add(self, counts, follower):
        """File ``follower`` (grouped by owner, every vertex in order) with ``counts`` per vertex."""
        self.parts.append((_offsets(counts), counts, follower))

    def preceding(self, n):
        """Number of conflicting candidates before each vertex, with multiplicity, ``(n,) int64``."""
        count = np.zeros(n, dtype=np.int64)
        for _, _, follower in self.parts:
            count += np.bincount(follower, minlength=n)
        return count

    def __call__(self, vertices):
        """The followers of ``vertices``, concatenated (with repeats)."""
        return np.concatenate(
            [follower[_ranges(starts[vertices], counts[vertices])] for starts, counts, follower in self.parts]
        )


def _offsets(counts):
    """Start of each of consecutive groups of ``counts`` (exclusive cumulative sum)."""
    starts = np.cumsum(counts)
    starts -= counts
    return starts


def _group_by(values, bound):
    """Positions of ``values`` (ints in ``[0, bound)``) sorted by value, ties in position order."""
    return _group(values, bound, inverse=False)[0]


def _stable_argsort(values):
    """``np.argsort(values, kind="stable")``, by the much faster unstable sort when there are no ties."""
    order = np.argsort(values)
    ordered = values[order]
    if np.any(ordered[1:] == ordered[:-1]):
        return np.argsort(values, kind="stable")
    return order

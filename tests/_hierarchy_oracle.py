"""The volume-cost hierarchy level (Liu et al. 2001, section 4.1) as a plain-Python loop: the tests' oracle.

Written from the rules in the docstring of ``o3d_lsmesh/hierarchy/collapse.pyx``
with lists, dicts and floats only, and the same floating-point operations in
the same order as the compiled kernel, so that every level must be equal.
About 100 times slower than the kernel: for meshes of a few thousand vertices.
"""

from __future__ import annotations

import math

import numpy as np

from o3d_lsmesh.core.boundary import nonmanifold_edges, nonmanifold_vertices
from o3d_lsmesh.hierarchy.collapse import FAR, TIE
from o3d_lsmesh.hierarchy.hierarchy import ALPHA, BETA, MAX_NORMAL_ANGLE, MAX_TRIES, MIN_QUALITY


def locked_vertices(F: np.ndarray, n: int) -> np.ndarray:
    """Unreferenced vertices, vertices on an edge of more than two triangles, and several-fan vertices."""
    locked = np.ones(n, dtype=bool)
    locked[np.asarray(F).ravel()] = False
    locked[nonmanifold_vertices(F, n)] = True
    locked[nonmanifold_edges(F, n).ravel()] = True
    return locked


def _geometry_ok(V, corners, x, k, cos_sq, min_quality):
    px = V[x]
    pk = V[k]
    for a, b in corners:
        if a == k or b == k:
            continue
        pa, pb = V[a], V[b]
        ax, ay, az = pa[0] - px[0], pa[1] - px[1], pa[2] - px[2]
        bx, by, bz = pb[0] - px[0], pb[1] - px[1], pb[2] - px[2]
        ox = ay * bz - az * by
        oy = az * bx - ax * bz
        oz = ax * by - ay * bx
        ax, ay, az = pa[0] - pk[0], pa[1] - pk[1], pa[2] - pk[2]
        bx, by, bz = pb[0] - pk[0], pb[1] - pk[1], pb[2] - pk[2]
        nx = ay * bz - az * by
        ny = az * bx - ax * bz
        nz = ax * by - ay * bx
        dot = nx * ox + ny * oy + nz * oz
        if dot <= 0.0:
            return False
        new_sq = nx * nx + ny * ny + nz * nz
        old_sq = ox * ox + oy * oy + oz * oz
        if dot * dot <= new_sq * cos_sq * old_sq:
            return False
        ex, ey, ez = bx - ax, by - ay, bz - az
        squared = ax * ax + ay * ay + az * az  # the squared edge lengths, each summed first
        squared += bx * bx + by * by + bz * bz
        squared += ex * ex + ey * ey + ez * ez
        squared *= min_quality
        if new_sq <= squared * squared:
            return False
    return True


def collapse_level(
    V,
    F,
    locked,
    *,
    alpha=ALPHA,
    beta=BETA,
    max_removals=None,
    max_normal_angle=MAX_NORMAL_ANGLE,
    min_quality=MIN_QUALITY,
    max_tries=MAX_TRIES,
    first=None,
):
    """``(removed, targets, ring_offsets, ring, parent, triangles)`` of one level, or ``None``. ``first``: a dict
    holding the first level's mean candidate edge length and centroid (``"scale"``, ``"centre"``), filled
    from this level when empty."""
    n = len(V)
    first = {} if first is None else first
    first.setdefault("centre", np.asarray(V, dtype=float).mean(axis=0))
    centre = first["centre"]
    cos_sq = float(np.cos(np.deg2rad(max_normal_angle)) ** 2) if max_normal_angle < 90 else 0.0
    max_removals = n if max_removals is None else max_removals
    P = np.asarray(V, dtype=float).tolist()
    T = np.asarray(F).tolist()
    corners = [[] for _ in range(n)]
    for t in T:
        for c in range(3):
            corners[t[c]].append((t[(c + 1) % 3], t[(c + 2) % 3]))
    count = [{} for _ in range(n)]  # triangles on edge (v, u)
    for v in range(n):
        for a, b in corners[v]:
            count[v][a] = count[v].get(a, 0) + 1
            count[v][b] = count[v].get(b, 0) + 1
    ring = [sorted(c) for c in count]
    lock = [bool(locked[v]) or any(c > 2 for c in count[v].values()) for v in range(n)]
    boundary = [any(c == 1 for c in count[v].values()) for v in range(n)]

    def length(v, u):
        dx, dy, dz = P[u][0] - P[v][0], P[u][1] - P[v][1], P[u][2] - P[v][2]
        return math.sqrt(dx * dx + dy * dy + dz * dz)

    cost, spread, total, summed = {}, {}, 0.0, 0
    for v in range(n):
        if ring[v] and not lock[v]:
            lengths = [length(v, u) for u in ring[v]]
            cost[v] = alpha * min(lengths) + beta * max(lengths)
            spread[v] = 0.0
            for u in ring[v]:
                dx, dy, dz = P[u][0] - P[v][0], P[u][1] - P[v][1], P[u][2] - P[v][2]
                spread[v] += dx * dx + dy * dy + dz * dz
            for d in lengths:
                total, summed = total + d, summed + 1
    scale = first.setdefault("scale", total / summed if summed else 0.0)
    unit, square = scale * TIE, scale * scale * TIE
    candidates = sorted(cost)
    offset = np.asarray(V, dtype=float)[candidates] - centre
    far = dict(zip(candidates, (offset * offset).sum(axis=1).tolist()))
    # by cost, ring spread and distance to the centroid in TIE units, then index: the geometry's order
    order = sorted(
        candidates,
        key=lambda v: (
            round(cost[v] / unit),
            round(spread[v] / square),
            round(far[v] / (scale * scale * FAR)),
            v,
        ),
    )
    rank = {v: i for i, v in enumerate(order)}
    touched = [False] * n
    target = {}
    for x in order:
        if len(target) >= max_removals:
            break
        if touched[x]:
            continue
        sx = sy = sz = 0.0
        for a, b in corners[x]:
            ax, ay, az = P[a][0] - P[x][0], P[a][1] - P[x][1], P[a][2] - P[x][2]
            bx, by, bz = P[b][0] - P[x][0], P[b][1] - P[x][1], P[b][2] - P[x][2]
            sx += ay * bz - az * by
            sy += az * bx - ax * bz
            sz += ax * by - ay * bx
        height = math.sqrt(sx * sx + sy * sy + sz * sz) * unit
        height = height if height > 0.0 else 1.0
        options = []  # (volume, length, k) of the allowed edges in units, in ring order
        for k in ring[x]:
            c = count[x][k]
            if lock[k]:
                continue
            if boundary[x]:
                if c != 1 or (len(ring[x]) == 2 and len(ring[k]) == 2 and boundary[k]):
                    continue  # only along the boundary; not an isolated triangle
            elif c != 2 or (len(ring[x]) == 3 and len(ring[k]) == 3 and not boundary[k]):
                continue  # only along an interior edge; not a closed tetrahedron
            dx, dy, dz = P[k][0] - P[x][0], P[k][1] - P[x][1], P[k][2] - P[x][2]
            options.append((round(abs(sx * dx + sy * dy + sz * dz) / height), round(length(x, k) / unit), k))
        chosen = None
        for _ in range(max_tries):
            if not options:
                break
            least = min(o[0] for o in options)
            best = min((o for o in options if o[0] == least), key=lambda o: (o[1], rank[o[2]]))
            k = best[2]
            if touched[k]:
                break  # a touched target ends the search
            common = len(set(ring[x]) & set(ring[k]))
            if _geometry_ok(P, corners[x], x, k, cos_sq, min_quality) and common == count[x][k]:
                chosen = k
                break
            options.remove(best)
        if chosen is None:
            continue
        target[x] = chosen
        touched[x] = True
        for u in ring[x]:
            touched[u] = True
    if not target:
        return None
    removed = sorted(target)
    parent, j = [0] * n, 0
    for v in range(n):
        if v not in target:
            parent[v] = j
            j += 1
    for x in removed:
        parent[x] = parent[target[x]]
    offsets = [0]
    flat = []
    for x in removed:
        flat.extend(ring[x])
        offsets.append(len(flat))
    triangles = [[parent[v] for v in t] for t in T]
    triangles = [t for t in triangles if t[0] != t[1] and t[1] != t[2] and t[2] != t[0]]
    as_int = lambda values: np.array(values, dtype=np.int64)
    return (
        as_int(removed),
        as_int([target[x] for x in removed]),
        as_int(offsets),
        as_int(flat),
        as_int(parent),
        as_int(triangles).reshape(-1, 3),
    )


def hierarchy(V, F, *, min_vertices=100, max_levels=None, **options):
    """Every level's ``collapse_level`` tuple, the way ``build_hierarchy_arrays`` chains them."""
    V = np.asarray(V, dtype=float)
    F = np.asarray(F, dtype=np.int64)
    locked = locked_vertices(F, len(V))
    reps = np.arange(len(V))
    levels = []
    triangles, first = F, {}
    while (max_levels is None or len(levels) < max_levels) and len(reps) > min_vertices:
        level = collapse_level(
            V[reps], triangles, locked[reps], max_removals=len(reps) - min_vertices, first=first, **options
        )
        if level is None:
            break
        levels.append(level)
        keep = np.ones(len(reps), dtype=bool)
        keep[level[0]] = False
        reps = reps[keep]
        triangles = level[5]
    return levels


def boundary_loop_count(F: np.ndarray, n: int) -> int:
    """Boundary loops of any mesh: cycles of boundary edges, paired at each vertex within one fan.

    Corners of a vertex are in one fan when their triangles share an edge through
    it that has exactly two triangles; an edge of one triangle joins the fans
    of its two corners. Every open fan holds two such ends, so the joined fans
    form cycles, one per loop (two loops through a pinched vertex stay two).
    """
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    F = np.asarray(F, dtype=np.int64)
    m = len(F)
    corner = np.arange(3 * m).reshape(m, 3)  # corner (t, c) of vertex F[t, c]
    tail, head = F.ravel(), F[:, [1, 2, 0]].ravel()
    c_tail, c_head = corner.ravel(), corner[:, [1, 2, 0]].ravel()
    key = np.minimum(tail, head) * np.int64(n) + np.maximum(tail, head)
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    order = np.argsort(inverse, kind="stable")
    pairs = order[counts[inverse[order]] == 2].reshape(-1, 2)  # the two half-edges of each manifold edge
    h1, h2 = pairs[:, 0], pairs[:, 1]
    same = tail[h1] == tail[h2]
    # corners of the same vertex across the edge
    a = np.r_[c_tail[h1], c_head[h1]]
    b = np.r_[np.where(same, c_tail[h2], c_head[h2]), np.where(same, c_head[h2], c_tail[h2])]
    graph = sp.coo_matrix((np.ones(len(a)), (a, b)), shape=(3 * m, 3 * m))
    _, fan = connected_components(graph, directed=False)
    boundary = np.flatnonzero(counts[inverse] == 1)
    if len(boundary) == 0:
        return 0
    u, v = fan[c_tail[boundary]], fan[c_head[boundary]]
    nodes, local = np.unique(np.r_[u, v], return_inverse=True)
    loops = sp.coo_matrix(
        (np.ones(len(boundary)), (local[: len(u)], local[len(u) :])), shape=(len(nodes),) * 2
    )
    return int(connected_components(loops, directed=False)[0])


def topology(F: np.ndarray, n: int, representatives: np.ndarray) -> dict:
    """What every level must keep: Euler characteristic, components, boundary loops, and (in input
    indices) the non-manifold vertices and edges."""
    from o3d_lsmesh.core.connectivity import Connectivity

    F = np.asarray(F, dtype=np.int64)
    edges = Connectivity(F, n).edges
    bad_edges = representatives[nonmanifold_edges(F, n)]
    return {
        "euler": n - len(edges) + len(F),
        "components": Connectivity(F, n).components[0],
        "loops": boundary_loop_count(F, n),
        "nonmanifold_vertices": sorted(representatives[nonmanifold_vertices(F, n)].tolist()),
        "nonmanifold_edges": sorted(map(tuple, np.sort(bad_edges, axis=1).tolist())),
    }

"""Boundary of a triangle mesh: boundary half-edges, loops, chains between junctions, corner fans.

Functions of ``triangles (m, 3)`` and ``n`` that take the mesh's
:class:`~o3d_lsmesh.core.connectivity.Connectivity` (``conn=``) when the caller has one (one edge sort
per operation). Pinches, fins and the walk: ``docs/algorithms/connectivity.rst``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from .arrays import _runs
from .connectivity import Connectivity, halfedges

__all__ = [
    "BoundaryCurves",
    "boundary_chains",
    "boundary_curves",
    "boundary_halfedges",
    "boundary_loops",
    "boundary_rows",
    "corner_fans",
    "nonmanifold_edges",
    "nonmanifold_vertices",
]


def boundary_halfedges(triangles: np.ndarray, n: int | None = None) -> np.ndarray:
    """Half-edges ``(b, 2)`` on edges used by exactly one triangle, oriented as in that triangle."""
    es = Connectivity(triangles, n).edge_structure
    return halfedges(triangles)[es.counts[es.inverse] == 1]


def nonmanifold_edges(triangles: np.ndarray, n: int | None = None) -> np.ndarray:
    """Edges ``(k, 2)`` shared by more than two triangles."""
    es = Connectivity(triangles, n).edge_structure
    return es.edges[es.counts > 2].astype(np.int64)


def nonmanifold_vertices(triangles: np.ndarray, n: int) -> np.ndarray:
    """Vertices whose triangles do not form a single fan (linked through manifold edges), sorted."""
    tail = triangles.T.reshape(-1)
    fan_count, fan = corner_fans(triangles, n, Connectivity(triangles, n).edge_structure.runs)
    # links only join corners of one vertex, so every fan belongs to exactly one vertex
    vertex_of_fan = np.zeros(fan_count, dtype=np.int64)
    vertex_of_fan[fan] = tail
    return np.flatnonzero(np.bincount(vertex_of_fan, minlength=n) > 1)


def corner_fans(triangles: np.ndarray, n: int, runs, *, only: np.ndarray | None = None):
    """Fans of triangle corners: ``(count, label (3m,))``, corners linked across edges of two triangles.

    Corner ``p*m + t`` holds ``triangles[t, p]``; ``runs``: ``Connectivity.edge_structure.runs``.
    With a vertex mask ``only`` the other vertices' corners are labelled ``-1``.
    """
    m = len(triangles)
    corners = 3 * m
    order, starts, counts = runs
    # corner p*m + t holds triangles[t, p]; half-edge row q*m + t runs from corner q*m + t
    # to corner ((q + 1) % 3)*m + t, so every corner starts one half-edge and ends one
    tail = triangles.T.reshape(-1)
    interior = starts[counts == 2]
    a, b = order[interior], order[interior + 1]
    del interior
    same_direction = tail[a] == tail[b]
    # (a + m) mod 3m, without passing 4m: int32 runs hold up to 3m < 2**31
    end_a, end_b = a - 2 * m, b - 2 * m
    end_a[end_a < 0] += corners
    end_b[end_b < 0] += corners
    # every corner has at most two links, one through the half-edge it starts and one through the
    # one it ends, so the graph is written as CSR directly (a self-link where there is none)
    index = np.int32 if 2 * corners < np.iinfo(np.int32).max else np.int64
    link = np.empty((corners, 2), dtype=index)
    link[:, 0] = np.arange(corners, dtype=index)
    link[:, 1] = link[:, 0]
    link[a, 0] = np.where(same_direction, b, end_b)
    link[b, 0] = np.where(same_direction, a, end_a)
    link[end_a, 1] = np.where(same_direction, end_b, b)
    link[end_b, 1] = np.where(same_direction, end_a, a)
    del a, b, end_a, end_b, same_direction
    selected = None
    if only is not None:
        selected = np.flatnonzero(only[tail])
        renumber = np.full(corners, -1, dtype=index)
        renumber[selected] = np.arange(len(selected), dtype=index)
        link = renumber[link[selected]]  # links stay among the corners of one vertex
        corners = len(selected)
    first = np.minimum(link[:, 0], link[:, 1])
    np.maximum(link[:, 0], link[:, 1], out=link[:, 1])
    link[:, 0] = first
    del first
    graph = sp.csr_matrix(
        (
            np.ones(2 * corners, dtype=np.int8),
            link.reshape(-1),
            np.arange(0, 2 * corners + 1, 2, dtype=index),
        ),
        shape=(corners, corners),
    )
    graph.has_sorted_indices = True  # each row's two links were just ordered
    # a corner without a link (or linked twice to one corner) repeats an entry: merged in one linear
    # pass, since SciPy < 1.15's strong components never return on repeated entries
    graph.sum_duplicates()
    # the links are symmetric, so strong components are the components, and finding them
    # reads the graph alone (weak or undirected ones transpose it first)
    fan_count, fan = csgraph.connected_components(graph, directed=True, connection="strong")
    fan = fan.astype(np.int64)
    if selected is None:
        return int(fan_count), fan
    label = np.full(3 * m, -1, dtype=np.int64)
    label[selected] = fan
    return int(fan_count), label


@dataclass(frozen=True)
class BoundaryCurves:
    """The boundary of a mesh cut into simple curves at its junction vertices.

    Attributes
    ----------
    loops : list of (l,) int64
        Closed loops (``loop[-1]`` joins ``loop[0]``), starting at their smallest vertex.
    chains : list of (k + 1,) int64
        Open chains of ``k >= 1`` boundary edges from junction to junction.
    junctions : (j,) int64
        Sorted boundary vertices where the boundary is not a simple curve.

    Every boundary edge lies on one curve, oriented as most of its edges' triangles; curves are
    sorted by their first vertex.
    """

    loops: list
    chains: list
    junctions: np.ndarray

    def __len__(self) -> int:
        return len(self.loops) + len(self.chains)


def boundary_loops(
    triangles: np.ndarray, n: int, *, conn: Connectivity | None = None, join_fans: bool = False
) -> list[np.ndarray]:
    """Every closed boundary loop as an ordered ``(l,) int64`` array of vertices, on any mesh.

    At a pinch a loop continues along the rim of the same fan; a boundary edge whose fan ends at a
    fin is on no closed loop (:func:`boundary_curves` covers those). With ``join_fans`` (hole
    filling), at a pinch of two fans, each with one edge in and one out and neither a lone triangle
    (a flap), a loop crosses the gaps between the fans instead: each loop is one hole's rim, and
    filling the holes joins the fans.

    >>> [loop.tolist() for loop in boundary_loops(np.array([[0, 1, 2], [0, 3, 4]]), 5)]  # a bow-tie
    [[0, 1, 2], [0, 3, 4]]
    >>> wings = np.array([[0, 1, 2], [0, 2, 3], [0, 4, 5], [0, 5, 6]])  # fans of two triangles at 0
    >>> [loop.tolist() for loop in boundary_loops(wings, 7, join_fans=True)]  # both gaps: one region
    [[0, 1, 2, 3, 0, 4, 5, 6]]
    """
    runs = None if conn is None else conn.edge_structure.runs
    triangles = np.asarray(triangles, dtype=np.int64)
    return _boundary_walk(triangles, n, split_at_junctions=False, runs=runs, join_fans=join_fans)[0]


def boundary_chains(triangles: np.ndarray, n: int) -> BoundaryCurves:
    """The boundary cut into closed loops through no junction and open chains between junctions.

    >>> curves = boundary_chains(np.array([[0, 1, 2], [0, 3, 4]]), 5)
    >>> [c.tolist() for c in curves.chains], curves.loops, curves.junctions.tolist()
    ([[0, 1, 2, 0], [0, 3, 4, 0]], [], [0])
    """
    closed, open_, junctions, _ = _boundary_walk(
        np.asarray(triangles, dtype=np.int64), n, split_at_junctions=True
    )
    return BoundaryCurves(closed, open_, np.flatnonzero(junctions))


def boundary_curves(triangles: np.ndarray, n: int, *, conn: Connectivity | None = None) -> BoundaryCurves:
    """The loops of :func:`boundary_loops`, the open paths ending at fins, and the fins' boundary vertices.

    >>> curves = boundary_curves(np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]]), 5)  # a fin on (0, 1)
    >>> curves.loops, [c.tolist() for c in curves.chains], curves.junctions.tolist()
    ([], [[0, 3, 1], [1, 2, 0], [1, 4, 0]], [0, 1])
    """
    runs = None if conn is None else conn.edge_structure.runs
    closed, open_, _, fins = _boundary_walk(
        np.asarray(triangles, dtype=np.int64), n, split_at_junctions=False, runs=runs
    )
    return BoundaryCurves(closed, open_, np.flatnonzero(fins))


def boundary_rows(triangles: np.ndarray, n: int, runs):
    """Boundary half-edge rows (no self-edges), half-edge tails and heads, ``(n,) bool`` vertices on fins."""
    order, starts, counts = runs
    rows = order[starts[counts == 1]]
    tail = triangles.T.reshape(-1)
    head = triangles[:, [1, 2, 0]].T.reshape(-1)
    rows = np.sort(rows[tail[rows] != head[rows]])  # a repeated vertex is not an edge
    crowded = order[starts[counts > 2]]
    on_crowded = np.zeros(n, dtype=bool)
    on_crowded[tail[crowded]] = True
    on_crowded[head[crowded]] = True
    return rows, tail, head, on_crowded


def _boundary_walk(triangles: np.ndarray, n: int, *, split_at_junctions: bool, runs=None, join_fans=False):
    """Closed and open boundary curves, each a sorted list, and ``(n,) bool`` masks of the junctions and
    of the boundary vertices on fins (see ``docs/algorithms/connectivity.rst``).

    State ``2i`` runs boundary edge ``i`` forward, ``2i + 1`` backward; the next state is the
    partner of the end it leaves, ``partner[s ^ 1]``.
    """
    if len(triangles) == 0:
        return [], [], np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    if runs is None:
        runs = Connectivity(triangles, n).edge_structure.runs
    rows, tail, head, on_crowded = boundary_rows(triangles, n, runs)
    degree = np.bincount(tail[rows], minlength=n) + np.bincount(head[rows], minlength=n)
    special = (degree > 0) & ((degree != 2) | on_crowded)
    fins = np.zeros(n, dtype=bool)
    fins[tail[rows]] = True
    fins &= on_crowded
    b = len(rows)
    if b == 0:
        return [], [], special, fins
    m = len(triangles)
    end_vertex = np.empty(2 * b, dtype=np.int64)
    end_vertex[0::2], end_vertex[1::2] = tail[rows], head[rows]
    # pairing key of every end: its vertex at a plain vertex; at a junction its fan (or itself)
    key = end_vertex.copy()
    at_junction = special[end_vertex]
    if np.any(at_junction):
        ends = np.flatnonzero(at_junction)
        if split_at_junctions:
            key[ends] = n + np.arange(len(ends))  # unique: never paired
        else:
            fans, fan = corner_fans(triangles, n, runs, only=special)
            corner = np.empty(2 * b, dtype=np.int64)
            corner[0::2] = rows  # a half-edge's row is the corner it starts from
            q, t = np.divmod(rows, m)
            corner[1::2] = ((q + 1) % 3) * m + t  # ... and it ends at the next corner of its triangle
            fan = fan[corner[ends]]
            key[ends] = n + fan
            if join_fans:  # each fan's end in (odd) pairs with the other fan's end out, across a gap
                v, incoming = end_vertex[ends], ends & 1
                one_each = np.bincount(fan, incoming, fans) * np.bincount(fan, 1 - incoming, fans) == 1
                low = np.full(n, fans)
                np.minimum.at(low, v, fan)
                flap = np.bincount(rows % m, minlength=m) == 3  # a lone triangle keeps its own rim
                two = (degree[v] == 4) & one_each[fan] & ~flap[corner[ends] % m]
                two &= np.bincount(v, ~two, n)[v] == 0  # all four ends of a vertex, or none
                key[ends[two]] = n + fans + 2 * low[v[two]] + ((fan[two] == low[v[two]]) ^ incoming[two])
    order = np.argsort(key, kind="stable")
    _, run_start, run_length = _runs(key[order])
    pairs = run_start[run_length == 2]  # a fan or a plain vertex holds at most two boundary ends
    partner = np.full(2 * b, -1, dtype=np.int64)
    partner[order[pairs]] = order[pairs + 1]
    partner[order[pairs + 1]] = order[pairs]
    state = np.arange(2 * b, dtype=np.int64)
    succ = partner[state ^ 1]
    has = succ >= 0
    graph = sp.csr_matrix((np.ones(int(has.sum())), (state[has], succ[has])), shape=(2 * b, 2 * b))
    count, label = csgraph.connected_components(graph, directed=True, connection="weak")
    # keep, of the two directions of every curve, the one with more forward edges (ties: the
    # direction holding its smallest edge forward)
    forward = np.bincount(label[0::2], minlength=count)
    smallest = np.full(count, 2 * b, dtype=np.int64)
    np.minimum.at(smallest, label, state)
    twin = np.empty(count, dtype=np.int64)
    twin[label] = label[state ^ 1]
    keep_curve = (forward > forward[twin]) | ((forward == forward[twin]) & (smallest < smallest[twin]))
    kept = keep_curve[label]
    entry = end_vertex[state]  # state 2i enters at the tail, 2i + 1 at the head
    exit_ = end_vertex[state ^ 1]
    pred = np.where(partner >= 0, partner ^ 1, -1)  # state whose leaving end is paired with my entry
    is_open = np.zeros(count, dtype=bool)
    is_open[label[kept & (pred < 0)]] = True
    # start: the first state of an open curve; the state entering at the smallest vertex of a closed one
    first = np.where(is_open[label], pred < 0, True) & kept
    candidates = np.flatnonzero(first)
    candidates = candidates[np.lexsort((candidates, entry[candidates], label[candidates]))]
    lead = np.ones(len(candidates), dtype=bool)
    lead[1:] = label[candidates[1:]] != label[candidates[:-1]]
    start_state = candidates[lead]  # one per kept curve, in label order
    # cut every closed curve before its start, then rank by pointer jumping on predecessors
    back = np.where(kept, pred, -1)
    back[start_state] = -1
    rank = np.where(back >= 0, 1, 0).astype(np.int64)
    jump = back.copy()
    active = np.flatnonzero(jump >= 0)
    while len(active):
        target = jump[active]
        rank[active] += rank[target]
        jump[active] = jump[target]
        active = active[jump[active] >= 0]
    states = np.flatnonzero(kept)
    curve_of = label[states]
    sequence = states[np.lexsort((rank[states], curve_of))]
    lengths = np.bincount(curve_of, minlength=count)[label[start_state]]
    pieces = np.split(entry[sequence], np.cumsum(lengths)[:-1])
    last = np.split(sequence, np.cumsum(lengths)[:-1])
    closed, open_ = [], []
    for curve, piece, states_of in zip(label[start_state].tolist(), pieces, last):
        if is_open[curve]:
            open_.append(np.append(piece, exit_[states_of[-1]]))
        else:
            closed.append(np.ascontiguousarray(piece))
    return _sorted_curves(closed), _sorted_curves(open_), special, fins


def _sorted_curves(curves: list) -> list:
    # by first vertex, then second (two curves from one pinch start at the same vertex, never on the same edge)
    return sorted(curves, key=lambda c: (int(c[0]), int(c[1])))

import numpy as np
import pytest
from conftest import grid, load_mesh, triangle_soups
from hypothesis import given, settings

from o3d_lsmesh.core.boundary import (
    boundary_chains,
    boundary_curves,
    boundary_halfedges,
    boundary_loops,
    nonmanifold_vertices,
)
from o3d_lsmesh.core.connectivity import Connectivity


def grid_with_holes():
    V, F = grid(9, 9)
    # remove the two triangles of cell (2,2) and of cell (5,5): two square holes
    cells = [2 * 8 + 2, 5 * 8 + 5]
    drop = np.array(cells + [c + 64 for c in cells])
    keep = np.setdiff1d(np.arange(len(F)), drop)
    return V, F[keep]


def is_cycle_in_order(loop, triangles):
    """Every step loop[i] -> loop[i + 1] (cyclic) is a half-edge of some triangle."""
    return all_cycles_in_order([loop], triangles)


def all_cycles_in_order(loops, triangles):
    he = {
        tuple(e)
        for e in np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]).tolist()
    }
    return all(
        (a, b) in he for loop in loops for a, b in zip(np.asarray(loop).tolist(), np.roll(loop, -1).tolist())
    )


def test_boundary_loops_of_grid_with_two_holes():
    V, F = grid_with_holes()
    loops = boundary_loops(F, len(V))
    assert [len(l) for l in loops] == [32, 4, 4]
    assert loops[0][0] == 0
    assert set(loops[1].tolist()) == {2 * 9 + 2, 2 * 9 + 3, 3 * 9 + 2, 3 * 9 + 3}
    assert set(loops[2].tolist()) == {5 * 9 + 5, 5 * 9 + 6, 6 * 9 + 5, 6 * 9 + 6}
    for loop in loops:
        assert is_cycle_in_order(loop, F)


def test_boundary_loops_of_real_mesh_with_27_holes():
    mesh = load_mesh("plane_holes.ply")
    F = np.asarray(mesh.triangles).astype(np.int64)
    loops = boundary_loops(F, len(mesh.vertices))
    assert len(loops) == 27 and sum(map(len, loops)) == 341
    assert all_cycles_in_order(loops, F)


def test_closed_mesh_has_no_loops(sphere):
    assert boundary_loops(np.asarray(sphere.triangles).astype(np.int64), len(sphere.vertices)) == []


def test_edges_counts_and_each_halfedges_edge():
    F = np.array([[0, 1, 2], [0, 2, 3]])
    c = Connectivity(F, 4)
    edges, counts, inverse = c.edges, c.edge_triangles, c.halfedge_edge
    assert edges.tolist() == [[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]]
    assert counts.tolist() == [1, 2, 1, 1, 1]
    assert np.all(
        edges[inverse].min(1)
        == np.minimum(
            np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])[:, 0],
            np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])[:, 1],
        )
    )


def test_nonmanifold_vertices_match_open3d():
    mesh = load_mesh("bunny_scan.ply")
    F = np.asarray(mesh.triangles).astype(np.int64)
    ours = nonmanifold_vertices(F, len(mesh.vertices))
    assert sorted(ours.tolist()) == sorted(np.asarray(mesh.get_non_manifold_vertices()).tolist())


def _fans_reference(F, n):
    """Per vertex, the number of groups of its triangles linked through edges of exactly two triangles."""
    edge_triangles = {}
    for t, tri in enumerate(F.tolist()):
        for i in range(3):
            edge_triangles.setdefault(frozenset((tri[i], tri[(i + 1) % 3])), []).append(t)
    fans = np.zeros(n, dtype=int)
    for v in range(n):
        around = [t for t, tri in enumerate(F.tolist()) if v in tri]
        seen = set()
        for start in around:
            if start in seen:
                continue
            fans[v] += 1
            stack = [start]
            seen.add(start)
            while stack:
                t = stack.pop()
                for w in F[t].tolist():
                    shared = edge_triangles[frozenset((v, w))] if w != v else []
                    if len(shared) == 2:
                        for other in shared:
                            if other not in seen:
                                seen.add(other)
                                stack.append(other)
    return fans


@settings(max_examples=150, deadline=None)
@given(triangle_soups())
def test_nonmanifold_vertices_match_a_reference_walk(soup):
    n, triangles = soup
    F = np.array(triangles, dtype=np.int64)
    assert nonmanifold_vertices(F, n).tolist() == np.flatnonzero(_fans_reference(F, n) > 1).tolist()


def test_nonmanifold_vertices_finds_closed_fans_sharing_an_apex():
    # two closed cones (octahedron halves glued at the apex 0), each fan around 0 is a cycle, and one
    # of them has its triangles flipped: counting edges or boundary edges cannot see this
    cone = lambda ring: [[0, ring[i], ring[(i + 1) % 4]] for i in range(4)]
    caps = lambda ring, bottom: [[bottom, ring[(i + 1) % 4], ring[i]] for i in range(4)]
    first = cone([1, 2, 3, 4]) + caps([1, 2, 3, 4], 5)
    second = [t[::-1] for t in cone([6, 7, 8, 9]) + caps([6, 7, 8, 9], 10)]
    F = np.array(first + second)
    assert nonmanifold_vertices(F, 11).tolist() == [0]
    assert nonmanifold_vertices(np.array(first), 6).tolist() == []


def test_a_pinch_has_a_loop_per_fan():
    bowtie = np.array([[0, 1, 2], [0, 3, 4]])
    assert [loop.tolist() for loop in boundary_loops(bowtie, 5)] == [[0, 1, 2], [0, 3, 4]]  # a pinch is fine


def test_components_count_isolated_vertices():
    count, labels = Connectivity(np.array([[0, 1, 2], [3, 4, 5]]), 7).components
    assert count == 3 and labels[0] == labels[2] and labels[3] != labels[0]


@settings(max_examples=60, deadline=None)
@given(triangle_soups())
def test_edges_and_adjacency_match_a_plain_count(case):
    n, triangles = case
    F = np.array(triangles, dtype=np.int64)
    counts = {}
    for tri in triangles:
        for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
            counts[(a, b)] = counts.get((a, b), 0) + 1
            counts[(b, a)] = counts.get((b, a), 0) + 1
    c = Connectivity(F, n)
    undirected = sorted(key for key in counts if key[0] < key[1])
    assert c.edges.tolist() == [list(key) for key in undirected]
    assert c.edge_triangles.tolist() == [counts[key] for key in undirected]
    A = c.adjacency
    dense = np.zeros((n, n))
    for a, b in counts:
        dense[a, b] = 1.0
    assert np.array_equal(A.toarray(), dense) and A.has_canonical_format


def test_adjacency_refuses_vertex_counts_its_keys_cannot_hold():
    with pytest.raises(ValueError, match=r"fewer than 2\*\*31 vertices"):
        _ = Connectivity(np.array([[0, 1, 2]]), 2**40).adjacency


# --------------------------------------------------------------------------- boundaries of any mesh (issue 12)


def _reference_boundary(F, n, *, split, join=False):
    """Plain-Python boundary walk: closed curves and open curves as vertex lists.

    Boundary edges are edges of exactly one triangle. At every vertex the ends of its
    boundary edges are paired: a vertex on exactly two boundary edges and no edge of more
    than two triangles pairs them; otherwise (a junction) ends pair when their triangles are
    in the same fan (triangles linked through edges of exactly two triangles around the
    vertex), or never with ``split``. With ``join``, at a junction of two such fans, each with one
    end in and one out and neither a triangle of three boundary edges, each fan's end in pairs with the
    other's end out.
    """
    edge_triangles = {}
    for t, tri in enumerate(F.tolist()):
        for i in range(3):
            edge_triangles.setdefault(frozenset((tri[i], tri[(i + 1) % 3])), []).append(t)
    boundary = []  # (tail, head, triangle)
    for t, tri in enumerate(F.tolist()):
        for i in range(3):
            a, b = tri[i], tri[(i + 1) % 3]
            if len(edge_triangles[frozenset((a, b))]) == 1:
                boundary.append((a, b, t))
    degree, crowded = {}, set()
    for a, b, _ in boundary:
        degree[a] = degree.get(a, 0) + 1
        degree[b] = degree.get(b, 0) + 1
    for edge, ts in edge_triangles.items():
        if len(ts) > 2:
            crowded |= set(edge)

    def fan(v, t):  # smallest triangle of t's fan around v
        seen, stack = {t}, [t]
        while stack:
            s = stack.pop()
            for w in F[s].tolist():
                if w != v and len(edge_triangles[frozenset((v, w))]) == 2:
                    for o in edge_triangles[frozenset((v, w))]:
                        if o not in seen:
                            seen.add(o)
                            stack.append(o)
        return min(seen)

    ends = {}  # pairing key -> list of (edge index, side)
    for e, (a, b, t) in enumerate(boundary):
        for side, v in ((0, a), (1, b)):
            junction = degree[v] != 2 or v in crowded
            key = ("v", v) if not junction else (("x", e, side) if split else ("f", v, fan(v, t)))
            ends.setdefault(key, []).append((e, side))
    lone = [t for _, _, t in boundary]
    for v in {key[1] for key in ends if join and key[0] == "f"}:
        fans = [ends.pop(key) for key in list(ends) if key[:2] == ("f", v)]
        if len(fans) == 2 and all(sorted(s for _, s in g) == [0, 1] for g in fans):
            if not any(lone.count(boundary[e][2]) == 3 for g in fans for e, _ in g):
                (a_out, a_in), (b_out, b_in) = (sorted(g, key=lambda end: end[1]) for g in fans)
                fans = [[a_in, b_out], [b_in, a_out]]
        ends.update({("f", v, i): g for i, g in enumerate(fans)})
    partner = {}
    for group in ends.values():
        if len(group) == 2:
            partner[group[0]], partner[group[1]] = group[1], group[0]
    used, closed, open_ = set(), [], []
    for e in range(len(boundary)):
        if e in used:
            continue
        # walk backwards to the start of an open curve, if any
        start, side = e, 0  # enter e at its tail
        while (start, side) in partner:
            f, s = partner[(start, side)]
            if f == e:
                break
            start, side = f, 1 - s
        curve, cur, entry = [], start, side
        while True:
            used.add(cur)
            a, b, _ = boundary[cur]
            curve.append(a if entry == 0 else b)
            leave = (cur, 1 - entry)
            if leave not in partner:
                curve.append(b if entry == 0 else a)
                open_.append(curve)
                break
            cur, entry = partner[leave]
            if cur == start:
                closed.append(curve)
                break
    return closed, open_


def _canonical(curve, closed):
    """The curve up to its start and direction (rotations only for closed ones)."""
    curve = list(curve)
    if not closed:
        return min(tuple(curve), tuple(curve[::-1]))
    low = min(curve)
    options = []
    for seq in (curve, curve[::-1]):  # rotations starting at the smallest vertex (a pinch may repeat it)
        options += [tuple(seq[i:] + seq[:i]) for i, v in enumerate(seq) if v == low]
    return min(options)


def _assert_matches_reference(F, n):
    closed, open_ = _reference_boundary(F, n, split=False)
    loops = boundary_loops(F, n)
    assert sorted(_canonical(l.tolist(), True) for l in loops) == sorted(_canonical(c, True) for c in closed)
    curves = boundary_curves(F, n)
    assert sorted(_canonical(c.tolist(), False) for c in curves.chains) == sorted(
        _canonical(c, False) for c in open_
    )
    closed, open_ = _reference_boundary(F, n, split=True)
    chains = boundary_chains(F, n)
    assert sorted(_canonical(l.tolist(), True) for l in chains.loops) == sorted(
        _canonical(c, True) for c in closed
    )
    assert sorted(_canonical(c.tolist(), False) for c in chains.chains) == sorted(
        _canonical(c, False) for c in open_
    )
    # every boundary edge on exactly one curve, in both descriptions
    bhe = [tuple(sorted(e)) for e in boundary_halfedges(F, n).tolist() if e[0] != e[1]]
    for loops_, chains_ in ((curves.loops, curves.chains), (chains.loops, chains.chains)):
        walked = [tuple(sorted(p)) for l in loops_ for p in zip(l.tolist(), np.roll(l, -1).tolist())]
        walked += [tuple(sorted(p)) for c in chains_ for p in zip(c[:-1].tolist(), c[1:].tolist())]
        assert sorted(walked) == sorted(bhe)
    # chains end at junctions and pass through none; simple loops meet no junction
    junctions = set(chains.junctions.tolist())
    assert all(
        c[0] in junctions and c[-1] in junctions and not junctions & set(c[1:-1].tolist())
        for c in chains.chains
    )
    assert all(not junctions & set(l.tolist()) for l in chains.loops)
    # a loop follows its triangles where they agree (a consistently oriented mesh: every step)
    return loops


@settings(max_examples=120, deadline=None)
@given(triangle_soups())
def test_boundary_curves_match_a_plain_walk_on_any_soup(soup):
    n, triangles = soup
    _assert_matches_reference(np.array(triangles, dtype=np.int64), n)


def test_pinched_loops_of_bunny_scan_match_a_plain_walk():
    mesh = load_mesh("bunny_scan.ply")
    F = np.asarray(mesh.triangles).astype(np.int64)
    n = len(mesh.vertices)
    loops = boundary_loops(F, n)
    assert len(loops) == 131 and sum(map(len, loops)) == 2898
    assert all_cycles_in_order(loops, F)  # consistently oriented: every step a half-edge
    closed, open_ = _reference_boundary(F, n, split=False)
    assert not open_
    assert sorted(_canonical(l.tolist(), True) for l in loops) == sorted(_canonical(c, True) for c in closed)
    # 109 is the count of connected pieces of the boundary graph (the MANIFEST's "loops"): 22 pinches join
    # two loops, the 29 others sit on one loop that visits them twice
    chains = boundary_chains(F, n)
    assert len(chains.junctions) == 51 and len(chains.loops) + len(chains.chains) == 92 + 102


@settings(max_examples=120, deadline=None)
@given(triangle_soups())
def test_loops_joining_fans_match_a_plain_walk_on_any_soup(soup):
    n, triangles = soup
    F = np.array(triangles, dtype=np.int64)
    closed, _ = _reference_boundary(F, n, split=False, join=True)
    loops = boundary_loops(F, n, join_fans=True)
    assert sorted(_canonical(l.tolist(), True) for l in loops) == sorted(_canonical(c, True) for c in closed)


def test_loops_joining_fans_are_each_hole_of_a_grid_and_of_bunny_scan():
    # two cells of a grid touching at vertex 12: across the gaps between its two fans, one loop a cell
    _V, F = grid(5, 5)
    F = F[[not (set(t) <= {6, 7, 11, 12} or set(t) <= {12, 13, 17, 18}) for t in F.tolist()]]
    cells = [l.tolist() for l in boundary_loops(F, 25, join_fans=True)[1:]]
    assert cells == [[6, 11, 12, 7], [12, 17, 18, 13]]
    mesh = load_mesh("bunny_scan.ply")
    F, n = np.asarray(mesh.triangles).astype(np.int64), len(mesh.vertices)
    loops = boundary_loops(F, n, join_fans=True)
    closed, open_ = _reference_boundary(F, n, split=False, join=True)
    assert not open_ and all_cycles_in_order(loops, F)
    assert sorted(_canonical(l.tolist(), True) for l in loops) == sorted(_canonical(c, True) for c in closed)
    # every boundary edge on one loop, as without joining
    assert sum(map(len, loops)) == 2898


def test_pinch_continues_along_the_rim_of_its_fan():
    # two square holes of a 5x5 grid touching at vertex 12 (cells (1,1) and (2,2) removed): the
    # surface's rim around them is one loop through 12 twice; cut at 12 it is two chains 12 -> 12
    _V, F = grid(5, 5)
    F = F[[not (set(t) <= {6, 7, 11, 12} or set(t) <= {12, 13, 17, 18}) for t in F.tolist()]]
    loops = boundary_loops(F, 25)
    assert [len(l) for l in loops] == [16, 8]
    inner = loops[1]
    assert sorted(inner.tolist()) == [6, 7, 11, 12, 12, 13, 17, 18] and inner[0] == 6
    assert is_cycle_in_order(inner, F)
    chains = boundary_chains(F, 25)
    assert chains.junctions.tolist() == [12] and len(chains.loops) == 1
    assert sorted(sorted(c.tolist()) for c in chains.chains) == [[6, 7, 11, 12, 12], [12, 12, 13, 17, 18]]


def test_fin_boundary_is_open_chains_between_its_edge_ends():
    fin = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    assert boundary_loops(fin, 5) == []
    curves = boundary_curves(fin, 5)
    assert sorted(c.tolist() for c in curves.chains) == [[0, 3, 1], [1, 2, 0], [1, 4, 0]]
    assert curves.junctions.tolist() == [0, 1]


def test_boundary_loops_follow_the_majority_orientation_of_flipped_triangles():
    _V, F = grid(5, 5)
    F = F.copy()
    F[0] = F[0, ::-1]  # a corner triangle flipped: its boundary edges run against the loop
    loops = boundary_loops(F, 25)
    assert len(loops) == 1 and len(loops[0]) == 16
    he = {tuple(e) for e in np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]).tolist()}
    steps = list(zip(loops[0].tolist(), np.roll(loops[0], -1).tolist()))
    assert sum((a, b) in he for a, b in steps) == 15  # all but the flipped triangle's boundary edge


def test_empty_and_closed_meshes_have_no_curves(sphere):
    F = np.asarray(sphere.triangles).astype(np.int64)
    curves = boundary_chains(F, len(sphere.vertices))
    assert curves.loops == [] and curves.chains == [] and len(curves.junctions) == 0 and len(curves) == 0
    assert boundary_loops(np.zeros((0, 3), dtype=np.int64), 4) == []
    assert len(boundary_curves(np.zeros((0, 3), dtype=np.int64), 4)) == 0


@pytest.mark.parametrize("dtype", [np.int32, np.int64, np.uint32])
@pytest.mark.parametrize("length", [0, 5, (1 << 16) - 1, (1 << 16) + 1, 3 * (1 << 16) + 17])
def test_gather_equals_fancy_indexing(dtype, length):
    from o3d_lsmesh.core.arrays import gather

    rng = np.random.default_rng(length)
    values = rng.random(1000)
    index = rng.integers(0, len(values), size=(length, 2)).astype(dtype)
    column = index[:, 1]  # a strided view, as the gathers of triangle columns take
    np.testing.assert_array_equal(gather(values, column), values[column.astype(np.int64)])
    out = np.full(length, np.nan)
    assert gather(values, column, out=out) is out
    np.testing.assert_array_equal(out, values[column.astype(np.int64)])

import numpy as np
import pytest
from conftest import grid, load_mesh, triangle_soups
from hypothesis import given, settings

from o3d_lsmesh.topology import (
    adjacency_matrix,
    boundary_loops,
    check_manifold,
    connected_components,
    directed_edges,
    nonmanifold_vertices,
    unique_edges,
)


def grid_with_holes():
    V, F = grid(9, 9)
    # remove the two triangles of cell (2,2) and of cell (5,5): two square holes
    cells = [2 * 8 + 2, 5 * 8 + 5]
    drop = np.array(cells + [c + 64 for c in cells])
    keep = np.setdiff1d(np.arange(len(F)), drop)
    return V, F[keep]


def is_cycle_in_order(loop, triangles):
    he = {tuple(e) for e in np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]).tolist()}
    nxt = np.roll(loop, -1)
    return all((a, b) in he for a, b in zip(loop.tolist(), nxt.tolist()))


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
    assert all(is_cycle_in_order(l, F) for l in loops)


def test_closed_mesh_has_no_loops(sphere):
    assert boundary_loops(np.asarray(sphere.triangles).astype(np.int64), len(sphere.vertices)) == []


def test_unique_edges_counts():
    F = np.array([[0, 1, 2], [0, 2, 3]])
    edges, counts, inverse = unique_edges(F, 4)
    assert edges.tolist() == [[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]]
    assert counts.tolist() == [1, 2, 1, 1, 1]
    assert np.all(edges[inverse].min(1) == np.minimum(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])[:, 0], np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])[:, 1]))


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


def test_check_manifold_names_first_offender():
    bowtie = np.array([[0, 1, 2], [0, 3, 4]])
    with pytest.raises(ValueError, match="vertex-manifold, got vertex 0"):
        check_manifold(bowtie, 5)
    fin = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    with pytest.raises(ValueError, match=r"edge-manifold, got edge \(0, 1\)"):
        check_manifold(fin, 5)
    assert [loop.tolist() for loop in boundary_loops(bowtie, 5)] == [[0, 1, 2], [0, 3, 4]]  # a pinch is fine


def test_components_count_isolated_vertices():
    count, labels = connected_components(np.array([[0, 1, 2], [3, 4, 5]]), 7)
    assert count == 3 and labels[0] == labels[2] and labels[3] != labels[0]


@settings(max_examples=60, deadline=None)
@given(triangle_soups())
def test_directed_edges_and_adjacency_match_a_plain_count(case):
    n, triangles = case
    F = np.array(triangles, dtype=np.int64)
    counts = {}
    for tri in triangles:
        for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
            counts[(a, b)] = counts.get((a, b), 0) + 1
            counts[(b, a)] = counts.get((b, a), 0) + 1
    src, dst, triangle_count = directed_edges(F, n)
    assert list(zip(src.tolist(), dst.tolist())) == sorted(counts)
    assert triangle_count.tolist() == [counts[key] for key in sorted(counts)]
    A = adjacency_matrix(F, n)
    dense = np.zeros((n, n))
    for a, b in counts:
        dense[a, b] = 1.0
    assert np.array_equal(A.toarray(), dense) and A.has_canonical_format


@pytest.mark.parametrize("n", [40, 5000, 200_000])
def test_directed_edges_on_threads_match_one_sort(n):
    # the threaded path sorts two halves of the triangles and merges them split at one key: every
    # key must land on one side of the split, also when it repeats many times (small n)
    from concurrent.futures import ThreadPoolExecutor

    rng = np.random.default_rng(n)
    F = rng.integers(0, n, size=(80_000, 3))
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 2] != F[:, 0])]
    assert len(F) >= 1 << 16  # the size from which the threads are used
    expected = directed_edges(F, n)
    with ThreadPoolExecutor(2) as executor:
        got = directed_edges(F, n, executor=executor)
    for a, b in zip(got, expected):
        assert a.dtype == b.dtype and np.array_equal(a, b)


def test_directed_edges_refuses_vertex_counts_its_keys_cannot_hold():
    with pytest.raises(ValueError, match=r"n must be below 2\*\*31"):
        directed_edges(np.array([[0, 1, 2]]), 2**40)

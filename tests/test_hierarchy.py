"""Mesh hierarchy (issues 4, 12, 13): the compiled kernel against its oracle, the validity rules, sizes, independence, maps, refinement, topology of every level, pickling, errors."""

from __future__ import annotations

import pickle
import threading
from collections import namedtuple

import _hierarchy_oracle as oracle
import numpy as np
import open3d as o3d
import pytest
from conftest import grid, load_mesh, triangle_soups
from hypothesis import given, settings
from hypothesis import strategies as st

from o3d_lsmesh.core.boundary import (
    boundary_halfedges,
    boundary_loops,
    nonmanifold_edges,
    nonmanifold_vertices,
)
from o3d_lsmesh.core.connectivity import Connectivity
from o3d_lsmesh.hierarchy import build_hierarchy, from_fast_simplification
from o3d_lsmesh.hierarchy import hierarchy as tuning
from o3d_lsmesh.hierarchy.collapse import collapse_levels
from o3d_lsmesh.hierarchy.hierarchy import build_hierarchy_arrays


def euler_characteristic(F, n_vertices):
    """``V - E + F`` with ``V = n_vertices``, the edges counted by a unique of the sorted pairs' keys."""
    pairs = np.sort(np.asarray(F, dtype=np.int64)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    return n_vertices - len(np.unique(pairs[:, 0] * n_vertices + pairs[:, 1])) + len(F)


def _noisy_sphere(resolution=16, seed=0):
    sphere = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=resolution)
    V = np.asarray(sphere.vertices).copy()
    V *= 1 + 0.02 * np.random.default_rng(seed).standard_normal((len(V), 1))
    return V, np.asarray(sphere.triangles).astype(np.int64)


@pytest.fixture(scope="module")
def sphere_h():
    V, F = _noisy_sphere()
    return (V, F), build_hierarchy((V, F), min_vertices=30)


@pytest.fixture(scope="module")
def grid_h():
    V, F = grid(14, 11, z=lambda x, y: 0.1 * np.sin(3 * x) * np.cos(2 * y))
    return (V, F), build_hierarchy((V, F), min_vertices=20)


# the kernel's tuned options, as build_hierarchy passes them
TUNED = dict(
    alpha=tuning.ALPHA,
    beta=tuning.BETA,
    max_normal_angle=tuning.MAX_NORMAL_ANGLE,
    min_quality=tuning.MIN_QUALITY,
    max_tries=tuning.MAX_TRIES,
)
Level = namedtuple("Level", "removed targets ring_offsets ring parent triangles kept")


def collapse_level(V, F, *, max_removals=None, **options):
    """One level of the compiled loop, with at most ``max_removals`` collapses (None when there are none)."""
    limit = len(V) if max_removals is None else max_removals
    options = {**TUNED, **options}
    levels = collapse_levels(V, F, min_vertices=len(V) - limit, max_levels=1, **options)[1]
    return Level(*levels[0]) if levels else None


def _triangle_set(F):
    return {tuple(sorted(t)) for t in np.asarray(F).tolist()}


# ------------------------------------------------------------------ structure


@pytest.mark.parametrize("name", ["sphere_h", "grid_h"])
def test_level_sizes_strictly_decrease_to_min_vertices(name, request):
    _, h = request.getfixturevalue(name)
    counts = [h.vertex_count(i) for i in range(len(h))]
    assert len(h) > 5
    assert all(a > b for a, b in zip(counts, counts[1:]))
    assert counts[-1] >= (30 if name == "sphere_h" else 20)


@pytest.mark.parametrize("name", ["sphere_h", "grid_h"])
def test_removed_sets_are_independent_collapses(name, request):
    _, h = request.getfixturevalue(name)
    for i in range(1, len(h)):
        rec = h.collapses(i)
        removed, targets = rec["removed"], rec["targets"]
        A = Connectivity(h.triangles[i - 1], h.vertex_count(i - 1)).adjacency
        # no two removed vertices are neighbours ...
        assert A[removed][:, removed].nnz == 0
        # ... every target is a neighbour and is kept, and a removed vertex next to another one's target
        # comes after it in cost order (module docstring: the collapses apply one by one in that order)
        assert np.all(A[removed, targets] == 1) and not np.isin(targets, removed).any()
        hits = A[removed][:, targets].tocoo()
        other = hits.row != hits.col
        cost = _vertex_cost(*h.level_arrays(i - 1))[removed]
        assert np.all(cost[hits.col[other]] <= cost[hits.row[other]] + 1e-12)
        # the recorded 1-ring is the adjacency row at level i - 1
        for j in range(0, len(removed), 7):
            ring = rec["ring"][rec["ring_offsets"][j] : rec["ring_offsets"][j + 1]]
            row = A[removed[j]].indices
            assert sorted(ring.tolist()) == sorted(row.tolist())
            assert targets[j] in ring


@pytest.mark.parametrize("name", ["sphere_h", "grid_h"])
def test_vertex_maps_are_in_range_and_consistent_with_levels(name, request):
    (V, F), h = request.getfixturevalue(name)
    for i in range(len(h)):
        vmap = h.vertex_map(i)
        n_i = h.vertex_count(i)
        assert vmap.shape == (len(V),) and vmap.min() == 0 and vmap.max() == n_i - 1
        Vi, Fi = h.level_arrays(i)
        # level positions are input positions, and each level vertex represents itself
        assert np.array_equal(Vi, V[h.representatives[i]])
        assert np.array_equal(vmap[h.representatives[i]], np.arange(n_i))
        # the level's triangles are exactly the input triangles mapped down, minus collapsed ones
        mapped = vmap[F]
        keep = (
            (mapped[:, 0] != mapped[:, 1]) & (mapped[:, 1] != mapped[:, 2]) & (mapped[:, 0] != mapped[:, 2])
        )
        assert _triangle_set(mapped[keep]) == _triangle_set(Fi)
        assert len(_triangle_set(Fi)) == len(Fi)


def test_target_is_the_cone_volume_minimum(sphere_h):
    """Cone volume by the paper's ordered 1-ring formula (plain loop) against the enclosed-volume change."""
    (V, F), h = sphere_h
    rec = h.collapses(1)

    def signed_volume(P, T):
        return np.einsum("ij,ij->i", P[T[:, 0]], np.cross(P[T[:, 1]], P[T[:, 2]])).sum() / 6

    def ordered_ring(x):
        star = [t for t in F.tolist() if x in t]
        nxt = {}
        for t in star:
            p = t.index(x)
            nxt[t[(p + 1) % 3]] = t[(p + 2) % 3]
        ring = [next(iter(nxt))]
        while len(ring) < len(nxt):
            ring.append(nxt[ring[-1]])
        return ring

    def cone(x, k, ring):
        total = 0.0
        for j in range(len(ring)):
            a, b = V[ring[j]], V[ring[(j + 1) % len(ring)]]
            total += np.dot(np.cross(a - V[k], b - V[k]), V[x] - V[k])
        return abs(total)

    before = signed_volume(V, F)
    argmin_hits = 0
    sample = rec["removed"][:40]
    for x, k in zip(sample, rec["targets"][:40]):
        ring = ordered_ring(x)
        # one collapse alone changes the enclosed volume by exactly the cone volume / 6
        parent = np.arange(len(V))
        parent[x] = k
        T = parent[F]
        T = T[(T[:, 0] != T[:, 1]) & (T[:, 1] != T[:, 2]) & (T[:, 0] != T[:, 2])]
        assert abs(signed_volume(V, T) - before) == pytest.approx(cone(x, k, ring) / 6, rel=1e-9, abs=1e-15)
        argmin_hits += cone(x, k, ring) <= min(cone(x, j, ring) for j in ring) + 1e-15
    # the unconstrained minimum is nearly always valid on a smooth sphere
    assert argmin_hits >= 0.9 * len(sample)


def _vertex_cost(V, F, alpha=1.0, beta=0.01):
    """Section 4.1's cost by a plain loop over the edges."""
    lengths = [[] for _ in range(len(V))]
    for a, b in {tuple(sorted(e)) for t in F.tolist() for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}:
        d = float(np.linalg.norm(V[a] - V[b]))
        lengths[a].append(d)
        lengths[b].append(d)
    return np.array([alpha * min(ls) + beta * max(ls) for ls in lengths])


def test_cost_order_prefers_short_edges():
    # a grid refined in one half: when only a few vertices may go, they come from the fine half
    V, F = grid(21, 11)
    V[:, 0] = np.where(V[:, 0] < 0.5, V[:, 0] * 0.3, 0.15 + (V[:, 0] - 0.5) * 1.7)
    h = build_hierarchy((V, F), max_levels=1, min_vertices=len(V) - 15)
    x = V[h.collapses(1)["removed"], 0]
    assert len(x) == 15 and np.all(x <= 0.15 + 1e-12)  # 0.15: the seam column, also fine-spaced
    # without the limit both halves lose vertices, the fine half a larger share of its vertices
    h = build_hierarchy((V, F), max_levels=1, min_vertices=3)
    x = V[h.collapses(1)["removed"], 0]
    assert np.mean(x < 0.15) > 0.3


# ----------------------------------------------------------------- refinement


def _reference_refine(h, i, positions):
    """Plain-loop version of MeshHierarchy.refine for an independent set."""
    F = h.triangles[i - 1]
    n = h.vertex_count(i - 1)
    parent = h.parents[i]
    out = np.asarray(positions, dtype=float)[parent].copy()
    nbrs = [set() for _ in range(n)]
    for a, b, c in F.tolist():
        nbrs[a] |= {b, c}
        nbrs[b] |= {a, c}
        nbrs[c] |= {a, b}
    bnd = [set() for _ in range(n)]
    for a, b in boundary_halfedges(F, n).tolist():
        bnd[a].add(b)
        bnd[b].add(a)
    ring = [sorted(bnd[v]) if bnd[v] else sorted(nbrs[v]) for v in range(n)]
    removed = h.collapses(i)["removed"].tolist()
    for x in removed:
        out[x] = np.mean([out[j] for j in ring[x]], axis=0)
    U = np.array([np.mean([out[j] for j in ring[v]], axis=0) - out[v] for v in range(n)])
    result = out.copy()
    for x in removed:
        U2 = np.mean([U[j] for j in ring[x]], axis=0) - U[x]
        nu = 1 + sum((1 / len(ring[j])) * (x in ring[j]) for j in ring[x]) / len(ring[x])
        result[x] = out[x] - U2 / nu
    return result


@pytest.mark.parametrize("name", ["sphere_h", "grid_h"])
def test_refine_matches_reference_and_keeps_kept_vertices(name, request, rng):
    _, h = request.getfixturevalue(name)
    for i in (1, 3, len(h) - 1):
        Vi = h.level_arrays(i)[0] + 0.01 * rng.standard_normal((h.vertex_count(i), 3))
        fine = h.refine(i, Vi)
        assert fine.shape == (h.vertex_count(i - 1), 3)
        kept = np.setdiff1d(np.arange(h.vertex_count(i - 1)), h.collapses(i)["removed"])
        assert np.array_equal(fine[kept], Vi[h.parents[i][kept]])
        np.testing.assert_allclose(fine, _reference_refine(h, i, Vi), atol=1e-12)


@pytest.mark.parametrize("builder", ["volume", "fast"])
def test_splitting_a_flat_region_stays_on_the_plane(builder, rng):
    V, F = grid(15, 15)
    V[:, :2] += 0.02 * rng.standard_normal((len(V), 2))  # irregular in-plane spacing
    normal = np.array([1.0, 2.0, 2.0]) / 3.0
    frame = np.linalg.qr(np.stack([normal, [1.0, 0, 0], [0, 1.0, 0]], axis=1))[0]
    tilted = (V @ np.stack([frame[:, 1], frame[:, 2], frame[:, 0]])) + 0.5  # plane through (0.5, 0.5, 0.5)
    if builder == "volume":
        h = build_hierarchy((tilted, F), min_vertices=30)
    else:
        h = from_fast_simplification((tilted, F), levels=[150, 80, 40])
    for i in range(1, len(h)):
        Vi = h.level_arrays(i)[0]
        # move the coarse vertices within the plane: split vertices must follow it
        Vi = Vi + 0.05 * np.cross(normal, rng.standard_normal((len(Vi), 3)))
        fine = h.refine(i, Vi)
        offset = (fine - 0.5) @ normal
        assert np.abs(offset).max() < 1e-12
        assert np.abs(fine - h.level_arrays(i - 1)[0]).max() < 0.5


def test_refine_of_exact_level_positions_is_close_on_a_smooth_surface(sphere_h):
    (_V, _F), h = sphere_h
    Vi, _ = h.level_arrays(1)
    fine = h.refine(1, Vi)
    err = np.abs(np.linalg.norm(fine, axis=1) - 1).max()
    assert err < 0.15  # split vertices land near the sphere (noise is 2%)


# -------------------------------------------------- topology on real meshes


@pytest.mark.parametrize(
    "name, loops",
    [
        ("bunny.ply", 5),
        ("horse.ply", 0),
        ("camel.ply", 0),
        ("eight.ply", 0),
        ("venus.ply", 1),
        ("pig.ply", 7),
        ("maxplanck.ply", 1),
    ],
)
def test_every_level_is_manifold_with_input_topology(name, loops):
    mesh = load_mesh(name)
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.triangles).astype(np.int64)
    chi = euler_characteristic(F, len(V))
    h = build_hierarchy(mesh, min_vertices=20)
    assert h.vertex_count(len(h) - 1) <= max(60, 0.01 * len(V))
    for i in range(len(h)):
        Vi, Fi = h.level_arrays(i)
        n = len(Vi)
        assert len(np.unique(Fi)) == n
        assert euler_characteristic(Fi, n) == chi
        assert len(boundary_loops(Fi, n)) == loops
        assert len(nonmanifold_edges(Fi, n)) == 0
        assert len(nonmanifold_vertices(Fi, n)) == 0
        assert len(np.unique(np.sort(Fi, axis=1) @ np.array([n * n, n, 1]))) == len(
            Fi
        )  # no repeated triangle
    if name == "eight.ply":
        assert chi == -2  # genus 2


@pytest.mark.parametrize("seed", range(8))
def test_levels_of_noisy_generated_meshes_keep_topology(seed):
    # crumpled spheres, tori and open grids down to a few vertices: each level is many collapses
    # applied at once, so the independence rule is what keeps these valid
    rng = np.random.default_rng(seed)
    kind = seed % 3
    if kind == 0:
        mesh = o3d.geometry.TriangleMesh.create_sphere(resolution=int(rng.integers(5, 14)))
    elif kind == 1:
        mesh = o3d.geometry.TriangleMesh.create_torus(
            radial_resolution=int(rng.integers(8, 24)), tubular_resolution=int(rng.integers(5, 14))
        )
    else:
        V, F = grid(int(rng.integers(5, 16)), int(rng.integers(5, 16)))
        mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F))
    V = np.asarray(mesh.vertices) + rng.normal(scale=0.03, size=(len(mesh.vertices), 3))
    F = np.asarray(mesh.triangles).astype(np.int64)
    chi, loops = euler_characteristic(F, len(V)), len(boundary_loops(F, len(V)))
    h = build_hierarchy((V, F), min_vertices=8)
    assert len(h) > 3
    for i in range(len(h)):
        Vi, Fi = h.level_arrays(i)
        n = len(Vi)
        assert len(np.unique(Fi)) == n and len(_triangle_set(Fi)) == len(Fi)
        assert euler_characteristic(Fi, n) == chi and len(boundary_loops(Fi, n)) == loops
        assert len(nonmanifold_edges(Fi, n)) == 0 and len(nonmanifold_vertices(Fi, n)) == 0


def test_tetrahedron_and_single_triangle_are_not_collapsed():
    tet = o3d.geometry.TriangleMesh.create_tetrahedron()
    h = build_hierarchy(tet, min_vertices=0)
    assert len(h) == 1
    tri = (np.eye(3), np.array([[0, 1, 2]]))
    assert len(build_hierarchy(tri, min_vertices=0)) == 1
    octa = o3d.geometry.TriangleMesh.create_octahedron()
    h = build_hierarchy(octa, min_vertices=0)
    assert h.vertex_count(len(h) - 1) == 4
    assert euler_characteristic(h.triangles[-1], 4) == 2


# ------------------------------------------------------ kinds, pickling, threads


def test_level_returns_the_input_kind():
    sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=10)
    h = build_hierarchy(sphere, min_vertices=30)
    assert isinstance(h.level(2), o3d.geometry.TriangleMesh)
    assert len(h.level(2).vertices) == h.vertex_count(2)
    tensor = o3d.t.geometry.TriangleMesh.from_legacy(sphere)
    ht = build_hierarchy(tensor, min_vertices=30)
    level = ht.level(1)
    assert isinstance(level, o3d.t.geometry.TriangleMesh)
    assert level.vertex.positions.dtype == tensor.vertex.positions.dtype
    assert level.vertex.positions.shape[0] == ht.vertex_count(1)
    V, F = np.asarray(sphere.vertices), np.asarray(sphere.triangles)
    arrays = build_hierarchy((V, F), min_vertices=30).level(1)
    assert isinstance(arrays, tuple) and arrays[0].shape[1] == 3 and arrays[1].shape[1] == 3
    # the input is not modified
    assert np.array_equal(np.asarray(sphere.vertices), V)


def test_pickle_round_trip_equals_original(sphere_h):
    _, h = sphere_h
    copy = pickle.loads(pickle.dumps(h))
    assert copy == h and copy is not h
    assert np.array_equal(copy.refine(2, copy.level_arrays(2)[0]), h.refine(2, h.level_arrays(2)[0]))
    other = build_hierarchy(h.level(0), min_vertices=60)
    assert other != h


def test_arrays_are_read_only_and_concurrent_reads_agree(sphere_h):
    _, h = sphere_h
    with pytest.raises(ValueError, match="read-only"):
        h.triangles[1][0, 0] = 0
    expected = [h.refine(i, h.level_arrays(i)[0]) for i in range(1, len(h))]
    results = {}

    def work(k):
        results[k] = [h.refine(i, h.level_arrays(i)[0]) for i in range(1, len(h))]

    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for k in range(4):
        assert all(np.array_equal(a, b) for a, b in zip(results[k], expected))


def test_concurrent_builds_agree():
    V, F = _noisy_sphere(24)
    expected = build_hierarchy((V, F), min_vertices=30)
    results = {}

    def work(k):
        results[k] = build_hierarchy((V, F), min_vertices=30)

    threads = [threading.Thread(target=work, args=(k,)) for k in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert all(results[k] == expected for k in range(3))


def test_progress_bar_runs(capsys):
    h = build_hierarchy(o3d.geometry.TriangleMesh.create_sphere(resolution=8), min_vertices=20, progress=True)
    assert len(h) > 1
    assert "mesh hierarchy" in capsys.readouterr().err


def test_max_levels_limits_the_depth():
    V, F = _noisy_sphere()
    h = build_hierarchy((V, F), max_levels=3, min_vertices=0)
    assert len(h) == 4


# -------------------------------------------------------- fast-simplification


def test_from_fast_simplification_structure():
    V, F = _noisy_sphere(20)
    h = from_fast_simplification((V, F), levels=[500, 250, 120])
    assert h.method == "fast_simplification" and not h.independent
    assert [h.vertex_count(i) for i in range(len(h))] == [len(V), 500, 250, 120]
    for i in range(1, len(h)):
        vmap = h.vertex_map(i)
        assert vmap.min() == 0 and vmap.max() == h.vertex_count(i) - 1
        mapped = vmap[F]
        keep = (
            (mapped[:, 0] != mapped[:, 1]) & (mapped[:, 1] != mapped[:, 2]) & (mapped[:, 0] != mapped[:, 2])
        )
        assert _triangle_set(mapped[keep]) == _triangle_set(h.triangles[i])
        fine = h.refine(i, h.level_arrays(i)[0])
        kept = np.setdiff1d(np.arange(h.vertex_count(i - 1)), h.collapses(i)["removed"])
        assert np.array_equal(fine[kept], h.level_arrays(i)[0][h.parents[i][kept]])
        # harmonic fill then Kobbelt: split vertices stay near the sphere
        assert np.abs(np.linalg.norm(fine, axis=1) - 1).max() < 0.2
    geometric = from_fast_simplification((V, F), levels=4, min_vertices=60)
    counts = [geometric.vertex_count(i) for i in range(len(geometric))]
    assert len(counts) == 5 and all(a > b for a, b in zip(counts, counts[1:])) and counts[-1] <= 70


@pytest.mark.parametrize(("scale", "offset"), [(1e8, 0.0), (1e-8, 0.0), (1.0, 1e6)])
def test_from_fast_simplification_is_the_same_at_any_scale_and_place(scale, offset):
    # the extension's thresholds are absolute and its replay single precision: at 1e8 it made no level,
    # a million units away other levels
    V, F = _noisy_sphere(20)
    h = from_fast_simplification((V, F), levels=[500, 250, 120])
    moved = from_fast_simplification((V * scale + offset, F), levels=[500, 250, 120])
    assert len(moved) == len(h)
    for i in range(len(h)):
        np.testing.assert_array_equal(moved.triangles[i], h.triangles[i])


# ------------------------------------------------------------------- errors


def _nonmanifold():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]], dtype=float)
    return V, np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])


def test_bad_input_raises():
    V, F = _noisy_sphere(8)
    with pytest.raises(ValueError, match="three distinct vertices"):  # the arrays' one check
        build_hierarchy_arrays(V, np.vstack([F, [[0, 0, 1]]]))
    with pytest.raises(ValueError, match="a triangle of three distinct vertices, got 1 triangles"):
        build_hierarchy((V, np.array([[0, 0, 1]])))  # (a mesh's are left out: none is left)
    with pytest.raises(ValueError, match="vertices must be finite"):
        build_hierarchy((np.vstack([V, [[np.nan, 0, 0]]]), F))
    with pytest.raises(FutureWarning, match="workers is deprecated"):
        build_hierarchy((V, F), workers=2)
    with pytest.raises(FutureWarning, match="workers is deprecated"):
        build_hierarchy_arrays(V, F, workers=1)
    with pytest.raises(TypeError, match="mesh must be"):
        build_hierarchy("mesh.ply")
    with pytest.raises(ValueError, match="min_vertices must be >= 0"):
        build_hierarchy((V, F), min_vertices=-1)
    with pytest.raises(TypeError, match="min_vertices must be an integer"):
        build_hierarchy((V, F), min_vertices=2.5)
    with pytest.raises(ValueError, match="max_levels must be >= 0"):
        build_hierarchy((V, F), max_levels=-2)
    with pytest.raises(ValueError, match="alpha must be non-negative"):
        build_hierarchy((V, F), alpha=-1.0)
    with pytest.raises(ValueError, match="beta must be non-negative"):
        build_hierarchy((V, F), beta=float("nan"))
    with pytest.raises(TypeError, match="progress must be a bool"):
        build_hierarchy((V, F), progress="yes")
    with pytest.raises(ValueError, match="levels must be strictly decreasing"):
        from_fast_simplification((V, F), levels=[30, 40])
    with pytest.raises(ValueError, match="levels must be >= 1"):
        from_fast_simplification((V, F), levels=0)
    with pytest.raises(TypeError, match="levels must be an integer"):
        from_fast_simplification((V, F), levels=True)
    with pytest.raises(TypeError, match="levels must be an integer or a sequence of integer"):
        from_fast_simplification((V, F), levels=[30.5])
    with pytest.raises(ValueError, match="agg must be non-negative"):
        from_fast_simplification((V, F), agg=-1.0)
    with pytest.raises(TypeError, match="agg must be a number"):
        from_fast_simplification((V, F), agg="7")
    with pytest.raises(TypeError, match="progress must be a bool"):
        from_fast_simplification((V, F), progress=None)
    with pytest.raises(ValueError, match="min_vertices must be >= 4"):
        from_fast_simplification((V, F), min_vertices=2)
    # absurd level counts are refused by name before any array is sized by them
    with pytest.raises(ValueError, match=rf"levels must be <= {len(V)}, got 1000000000"):
        from_fast_simplification((V, F), levels=10**9)
    # one or two triangles: nothing coarser exists, said of the mesh (not of an internal target count)
    square = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]]), np.array([[0, 1, 2], [1, 3, 2]]))
    with pytest.raises(ValueError, match="mesh must have at least 5 vertices to be simplified, got 4"):
        from_fast_simplification(square)


def test_bad_level_queries_raise(sphere_h):
    _, h = sphere_h
    L = len(h)
    with pytest.raises(ValueError, match=f"i must be <= {L - 1}, got {L}"):
        h.level(L)
    with pytest.raises(ValueError, match="i must be >= 0"):
        h.vertex_map(-1)
    with pytest.raises(ValueError, match="i must be >= 1"):
        h.refine(0, h.level_arrays(0)[0])
    with pytest.raises(ValueError, match="i must be >= 1"):
        h.collapses(0)
    with pytest.raises(TypeError, match="i must be an integer"):
        h.vertex_count(1.0)
    with pytest.raises(ValueError, match=r"positions must have shape \("):
        h.refine(1, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="positions must be finite"):
        h.refine(1, np.full((h.vertex_count(1), 3), np.nan))


def test_array_core_leaves_the_callers_arrays_writeable():
    # the hierarchy holds read-only views; fast-simplification (nanobind) rejects read-only input
    V, F = _noisy_sphere(8)
    h = build_hierarchy_arrays(V, F, min_vertices=30)
    assert V.flags.writeable and F.flags.writeable
    assert not h.vertices.flags.writeable
    with pytest.raises(ValueError, match="read-only"):
        h.vertices[0, 0] = 1.0


def test_the_hierarchy_copies_the_callers_arrays():
    V, F = _noisy_sphere(8)
    V0, F0 = V.copy(), F.copy()
    h = build_hierarchy_arrays(V, F, min_vertices=30)
    expected = build_hierarchy_arrays(V0, F0, min_vertices=30)
    V += 1.0
    F[:, [0, 1]] = F[:, [1, 0]]
    assert h == expected
    assert np.array_equal(h.vertices, V0) and np.array_equal(h.triangles[0], F0)


# ------------------------------------------------- the compiled kernel and its oracle


def _generated(kind, seed):
    rng = np.random.default_rng(seed)
    if kind == "sphere":
        mesh = o3d.geometry.TriangleMesh.create_sphere(resolution=12)
    elif kind == "torus":
        mesh = o3d.geometry.TriangleMesh.create_torus(radial_resolution=24, tubular_resolution=10)
    elif kind == "thin torus":  # three vertices around the tube: collapses along it break the link condition
        mesh = o3d.geometry.TriangleMesh.create_torus(radial_resolution=30, tubular_resolution=3)
    if kind in ("sphere", "torus", "thin torus"):
        V, F = np.asarray(mesh.vertices).copy(), np.asarray(mesh.triangles).astype(np.int64)
    elif kind == "flat grid":  # every cone volume 0 and many equal lengths: ties decide everything
        V, F = grid(17, 13)
    elif kind == "grid":
        V, F = grid(17, 13, z=lambda x, y: 0.2 * np.sin(3 * x) * np.cos(2 * y))
    if seed:  # noisy versions
        V = V + rng.normal(scale=0.02 * seed, size=V.shape)
    return V, F


def _assert_levels_equal(h, levels):
    assert len(h) - 1 == len(levels)
    names = ("removed", "targets", "ring_offsets", "rings", "parents", "triangles")
    for i, level in enumerate(levels, 1):
        for name, expected in zip(names, level):
            assert np.array_equal(getattr(h, name)[i], expected), (i, name)


@pytest.mark.parametrize("kind", ["sphere", "torus", "thin torus", "flat grid", "grid"])
@pytest.mark.parametrize("seed", [0, 1, 3])
def test_every_level_equals_the_plain_python_oracle(kind, seed):
    V, F = _generated(kind, seed)
    h = build_hierarchy_arrays(V, F, min_vertices=6)
    assert len(h) > 4
    _assert_levels_equal(h, oracle.hierarchy(V, F, min_vertices=6))


@pytest.mark.parametrize("name", ["venus.ply", "eight.ply", "pig.ply"])
def test_every_level_of_small_real_meshes_equals_the_oracle(name):
    mesh = load_mesh(name)
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.triangles).astype(np.int64)
    _assert_levels_equal(
        build_hierarchy_arrays(V, F, min_vertices=20), oracle.hierarchy(V, F, min_vertices=20)
    )


def test_first_levels_of_the_bunny_equal_the_oracle():
    mesh = load_mesh("bunny.ply")
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.triangles).astype(np.int64)
    _assert_levels_equal(build_hierarchy_arrays(V, F, max_levels=1), oracle.hierarchy(V, F, max_levels=1))


@pytest.mark.parametrize(
    "options",
    [
        {"alpha": 0.0, "beta": 1.0},
        {"max_normal_angle": 20.0},
        {"min_quality": 0.2},
        {"max_tries": 1},
        {"max_removals": 7},
    ],
)
def test_options_reach_the_kernel_like_the_oracle(options):
    V, F = _generated("torus", 1)
    locked = np.zeros(len(V), dtype=bool)
    level = collapse_level(V, F, **options)
    expected = oracle.collapse_level(V, F, locked, **options)
    for got, want in zip(level[:6], expected):
        assert np.array_equal(got, want)


# ------------------------------------------------------------- validity rules


def _moved_triangles(V, F, level):
    """Every triangle of level i - 1 that survives, before and after its removed corner moved to its target."""
    moved = np.arange(len(V))
    moved[level.removed] = level.targets
    after = moved[F]
    alive = (after[:, 0] != after[:, 1]) & (after[:, 1] != after[:, 2]) & (after[:, 2] != after[:, 0])
    changed = alive & np.any(after != F, axis=1)
    return F[changed], after[changed]


def _normals(V, F):
    return np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])


@pytest.mark.parametrize("angle", [10.0, 30.0])
def test_no_surviving_triangle_turns_by_max_normal_angle(angle):
    V, F = _generated("sphere", 3)
    level = collapse_level(V, F, max_normal_angle=angle)
    before, after = _moved_triangles(V, F, level)
    a, b = _normals(V, before), _normals(V, after)
    cosine = np.einsum("ij,ij->i", a, b) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
    assert len(cosine) > 40 and np.all(cosine > np.cos(np.deg2rad(angle)))
    # without the bound, these noisy spheres do have such collapses: the rule is what stops them
    loose = collapse_level(V, F, max_normal_angle=89.0)
    before, after = _moved_triangles(V, F, loose)
    a, b = _normals(V, before), _normals(V, after)
    cosine = np.einsum("ij,ij->i", a, b) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
    assert np.any(cosine <= np.cos(np.deg2rad(angle)))


@pytest.mark.parametrize("quality", [0.1, 0.2])
def test_no_new_triangle_falls_to_min_quality(quality):
    V, F = _generated("flat grid", 0)
    V = V + np.c_[np.random.default_rng(2).normal(scale=0.02, size=(len(V), 2)), np.zeros(len(V))]

    def worst(level):
        _, after = _moved_triangles(V, F, level)
        assert len(after) > 20
        P = V[after]
        squared = sum(np.sum((P[:, i] - P[:, j]) ** 2, axis=1) for i, j in ((0, 1), (1, 2), (2, 0)))
        return np.min(np.linalg.norm(_normals(V, after), axis=1) / squared)

    assert worst(collapse_level(V, F, min_quality=quality)) > quality
    assert worst(collapse_level(V, F, min_quality=0.0)) <= quality  # the rule is what stops them


def test_no_collapse_flips_a_triangle():
    # a flat grid whose every collapse would keep the normals' direction or reverse it: no other rule applies
    V, F = _generated("flat grid", 0)
    V = V + np.c_[np.random.default_rng(4).normal(scale=0.02, size=(len(V), 2)), np.zeros(len(V))]
    level = collapse_level(V, F, max_normal_angle=179.0, min_quality=0.0)
    before, after = _moved_triangles(V, F, level)
    assert len(after) > 50
    assert np.all(np.sign(_normals(V, after)[:, 2]) == np.sign(_normals(V, before)[:, 2]))


def test_the_link_condition_keeps_a_thin_torus_a_torus():
    # with the geometric rules off, only the link condition stops collapses that pinch the tube
    V, F = _generated("thin torus", 1)
    reps = np.arange(len(V))
    for _ in range(6):
        level = collapse_level(V[reps], F, max_normal_angle=179.0, min_quality=0.0)
        if level is None:
            break
        keep = np.ones(len(reps), dtype=bool)
        keep[level.removed] = False
        reps, F = reps[keep], level.triangles
        n = len(reps)
        assert euler_characteristic(F, n) == 0
        assert len(nonmanifold_edges(F, n)) == 0 and len(nonmanifold_vertices(F, n)) == 0


def test_boundary_vertices_collapse_along_the_boundary_and_inner_ones_inside():
    V, F = _generated("grid", 1)
    for options in ({}, {"max_normal_angle": 179.0, "min_quality": 0.0}):
        level = collapse_level(V, F, **options)
        count = {}
        for t in F.tolist():
            for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
                key = (min(a, b), max(a, b))
                count[key] = count.get(key, 0) + 1
        on_boundary = {v for key, c in count.items() if c == 1 for v in key}
        kinds = set()
        for x, k in zip(level.removed.tolist(), level.targets.tolist()):
            edge = count[(min(x, k), max(x, k))]
            assert edge == (1 if x in on_boundary else 2)
            kinds.add(x in on_boundary)
        assert kinds == {True, False}
        assert oracle.boundary_loop_count(level.triangles, len(V) - len(level.removed)) == 1


# ---------------------------------------------------------- non-manifold input


def _bowtie_and_fin():
    """Two grids joined at one vertex (bow-tie), a fin of a third triangle on an interior edge,
    an isolated triangle, a pinched boundary and an unreferenced vertex."""
    V1, F1 = grid(9, 9, z=lambda x, y: 0.1 * np.sin(4 * x))
    V2, F2 = grid(9, 9, z=lambda x, y: 0.1 * np.cos(4 * y))
    V2 = V2 + [1.0, 1.0, 0.0]  # its corner 0 lands on the first grid's last corner
    n1 = len(V1)
    F2 = np.where(F2 == 0, n1 - 1, F2 + n1 - 1)
    V = np.vstack([V1, V2[1:]])
    F = np.vstack([F1, F2])
    n = len(V)
    inner = F1[40]  # a fin on an interior edge of the first grid
    V = np.vstack(
        [V, [[0.5, 0.5, 0.7]], [[3.0, 3.0, 0.0], [3.1, 3.0, 0.0], [3.0, 3.1, 0.0]], [[9.0, 9.0, 9.0]]]
    )
    F = np.vstack([F, [[inner[0], inner[1], n]], [[n + 1, n + 2, n + 3]]])
    return V, F.astype(np.int64)


def locked_vertices(F, n):
    """The kernel's locked vertices (never moved, never a collapse target): its answer at zero levels."""
    return collapse_levels(np.zeros((n, 3)), np.ascontiguousarray(F, dtype=np.int64), max_levels=0, **TUNED)[
        0
    ]


def test_locked_vertices_match_the_topology_module():
    V, F = _bowtie_and_fin()
    locked = locked_vertices(F, len(V))
    assert np.array_equal(locked, oracle.locked_vertices(F, len(V)))
    assert locked[-1] and locked.sum() >= 4


@pytest.mark.parametrize("seed", [0, 1])
def test_non_manifold_input_keeps_its_topology_at_every_level(seed):
    V, F = _bowtie_and_fin()
    V = V + np.random.default_rng(seed).normal(scale=0.005 * seed, size=V.shape)
    h = build_hierarchy((V, F), min_vertices=0)
    assert len(h) > 4 and h.vertex_count(len(h) - 1) < len(V) / 4
    expected = oracle.topology(F, len(V), np.arange(len(V)))
    assert expected["nonmanifold_vertices"] and expected["nonmanifold_edges"] and expected["loops"] >= 3
    locked = locked_vertices(F, len(V))
    for i in range(len(h)):
        assert oracle.topology(h.triangles[i], h.vertex_count(i), h.representatives[i]) == expected, i
        assert np.isin(np.flatnonzero(locked), h.representatives[i]).all()  # locked vertices stay
        vmap = h.vertex_map(i)
        assert np.array_equal(vmap[h.representatives[i]], np.arange(h.vertex_count(i)))
    _assert_levels_equal(h, oracle.hierarchy(V, F, min_vertices=0))


@settings(max_examples=60, deadline=None)
@given(triangle_soups(max_vertices=14, max_triangles=30), st.integers(0, 2**32 - 1))
def test_triangle_soups_keep_their_topology_and_equal_the_oracle(soup, seed):
    n, triangles = soup
    F = np.array(triangles, dtype=np.int64).reshape(-1, 3)
    V = np.random.default_rng(seed).normal(size=(n, 3))
    h = build_hierarchy_arrays(V, F, min_vertices=0)
    expected = oracle.topology(F, n, np.arange(n))
    for i in range(len(h)):
        assert oracle.topology(h.triangles[i], h.vertex_count(i), h.representatives[i]) == expected
    _assert_levels_equal(h, oracle.hierarchy(V, F, min_vertices=0))


@pytest.mark.parametrize("kind", ["legacy", "tensor"])
@pytest.mark.parametrize("builder", ["volume", "fast"])
def test_levels_warn_that_the_input_normals_are_dropped(kind, builder):
    import warnings

    from o3d_lsmesh import O3DLSMeshWarning

    if builder == "fast":
        pytest.importorskip("fast_simplification")
    sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=12)
    build = (
        (lambda m: build_hierarchy(m, min_vertices=30)) if builder == "volume" else from_fast_simplification
    )
    plain = sphere if kind == "legacy" else o3d.t.geometry.TriangleMesh.from_legacy(sphere)
    with warnings.catch_warnings():
        warnings.simplefilter("error", O3DLSMeshWarning)  # no normals: nothing to say
        build(plain)
    with_normals = o3d.geometry.TriangleMesh(sphere).compute_vertex_normals()
    if kind == "tensor":
        with_normals = o3d.t.geometry.TriangleMesh.from_legacy(with_normals)
    with pytest.warns(O3DLSMeshWarning, match="hierarchy levels have new connectivity: vertex normals"):
        levels = build(with_normals)
    coarse = levels.level(len(levels) - 1)
    assert not (coarse.has_vertex_normals() if kind == "legacy" else "normals" in coarse.vertex)

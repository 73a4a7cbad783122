from collections import deque

import numpy as np
import open3d as o3d
import pytest
from conftest import grid, load_mesh, welded_surface
from hypothesis import given, settings
from hypothesis import strategies as st
from selection_reference import greedy_dense

from o3d_lsmesh import ls_mesh
from o3d_lsmesh.core.connectivity import Connectivity
from o3d_lsmesh.lsmesh.selection import (
    approximate,
    forbid_around,
    select_control_points,
    start_vertices,
)


def noisy_sphere(resolution=8, seed=0):
    """A sphere with random radial noise: no two vertices tie in error."""
    mesh = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=resolution)
    V = np.asarray(mesh.vertices)
    rng = np.random.default_rng(seed)
    V = V * (1.0 + 0.15 * rng.random((len(V), 1)))
    return V, np.asarray(mesh.triangles).astype(np.int64)


def two_spheres():
    V, F = noisy_sphere(6, seed=1)
    V2, F2 = noisy_sphere(5, seed=2)
    return np.concatenate([V, V2 + 5.0]), np.concatenate([F, F2 + len(V)])


def errors_of(V, F, selection, weight=1.0):
    """Squared error of every vertex in the LS mesh of ``selection`` (a fresh solve)."""
    X = ls_mesh((V, F), selection, weights=weight)[0]
    return ((X - V) ** 2).sum(axis=1)


def reference_forbid(adjacency, errors, forbidden, vertex):
    """Plain queue BFS: the paper's walk, one vertex at a time."""
    forbidden[vertex] = True
    queue = deque([vertex])
    while queue:
        w = queue.popleft()
        for u in adjacency.indices[adjacency.indptr[w] : adjacency.indptr[w + 1]]:
            if not forbidden[u] and errors[u] < errors[w]:
                forbidden[u] = True
                queue.append(u)


def test_random_is_reproducible_and_valid():
    V, F = two_spheres()
    a = select_control_points((V, F), 40, method="random", seed=7)
    b = select_control_points((V, F), 40, method="random", seed=7)
    c = select_control_points((V, F), 40, method="random", seed=8)
    gen = select_control_points((V, F), 40, method="random", seed=np.random.default_rng(7))
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, gen)
    assert not np.array_equal(a, c)
    assert len(np.unique(a)) == 40 and a.min() >= 0 and a.max() < len(V)
    n1 = len(noisy_sphere(6)[0])
    # the first two picks are one per component
    assert (a[0] < n1) != (a[1] < n1)


def test_random_full_count_is_a_permutation():
    V, F = noisy_sphere(5)
    a = select_control_points((V, F), len(V), method="random", seed=0)
    np.testing.assert_array_equal(np.sort(a), np.arange(len(V)))


def test_start_vertex_is_farthest_from_component_centroid():
    V, F = two_spheres()
    start = start_vertices(V, F)
    n1 = len(noisy_sphere(6)[0])
    assert len(start) == 2
    for vertex, part in zip(start, [np.arange(n1), np.arange(n1, len(V))]):
        d = np.linalg.norm(V[part] - V[part].mean(axis=0), axis=1)
        assert vertex == part[np.argmax(d)]


def test_greedy_picks_the_true_maximum_at_each_step():
    V, F = noisy_sphere(8)
    selection = select_control_points((V, F), 30, method="greedy")
    start = start_vertices(V, F)
    np.testing.assert_array_equal(selection[:1], start)
    for k in range(1, 30):
        err = errors_of(V, F, selection[:k])
        err[selection[:k]] = -1.0
        assert selection[k] == np.argmax(err), f"step {k}"
        # a clear winner: the comparison above is not decided by round-off
        top2 = np.sort(err)[-2:]
        assert top2[1] - top2[0] > 1e-9


def test_greedy_equals_a_plain_loop_of_dense_solves():
    V, F = noisy_sphere(12, seed=3)
    updated = select_control_points((V, F), 80, method="greedy", weights=1.0)
    np.testing.assert_array_equal(updated, greedy_dense(V, F, 80, 1.0))


def test_greedy_equals_dense_solves_at_the_encoding_weight():
    V, F = noisy_sphere(10, seed=4)
    omega = 10.0 * len(V)
    updated = select_control_points((V, F), 50, method="greedy", weights=omega)
    np.testing.assert_array_equal(updated, greedy_dense(V, F, 50, omega))


@pytest.mark.parametrize("batch", [1, 5, 31])
def test_combined_never_picks_a_forbidden_vertex(batch):
    V, F = noisy_sphere(12, seed=5)
    adjacency = Connectivity(F, len(V)).adjacency
    count = 70
    selection = select_control_points((V, F), count, method="combined", batch=batch)
    assert len(np.unique(selection)) == count
    checked = 0
    in_batch = batch  # forces a solve before the first pick
    forbidden = err = None  # set by that first solve
    for position in range(1, count):
        pick = selection[position]
        if forbidden is None or in_batch == batch or not np.isfinite(np.where(forbidden, -np.inf, err)).any():
            # a new batch: one solve with everything selected so far; a batch also ends
            # early once every vertex is selected or forbidden
            err = errors_of(V, F, selection[:position])
            forbidden = np.zeros(len(V), dtype=bool)
            forbidden[selection[:position]] = True
            in_batch = 0
        assert not forbidden[pick], f"pick {pick} was forbidden in its batch"
        allowed = np.where(forbidden, -np.inf, err)
        assert err[pick] == allowed.max()
        reference_forbid(adjacency, err, forbidden, pick)
        in_batch += 1
        checked += 1
    assert checked == count - 1


def test_combined_batch_of_one_is_greedy():
    V, F = noisy_sphere(8, seed=6)
    np.testing.assert_array_equal(
        select_control_points((V, F), 25, method="combined", batch=1),
        select_control_points((V, F), 25, method="greedy"),
    )


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(0, 99))
def test_vectorized_bfs_matches_queue_bfs(seed, start):
    V, F = grid(10, 10)
    adjacency = Connectivity(F, len(V)).adjacency
    rng = np.random.default_rng(seed)
    errors = rng.random(len(V))
    errors[rng.random(len(V)) < 0.2] = 0.5  # ties: equal errors must stop the walk
    pre = rng.random(len(V)) < 0.1
    pre[start] = False
    fast, slow = pre.copy(), pre.copy()
    forbid_around(adjacency.indptr.astype(np.int64), adjacency.indices.astype(np.int64), errors, fast, start)
    reference_forbid(adjacency, errors, slow, start)
    np.testing.assert_array_equal(fast, slow)


def test_error_decreases_as_anchors_are_added_on_a_real_mesh():
    mesh = load_mesh("camel.ply")
    V = np.asarray(mesh.vertices)
    selection = select_control_points(mesh, 200, method="greedy")
    linf = []
    for k in (25, 50, 100, 200):
        X = np.asarray(ls_mesh(mesh, selection[:k]).vertices)
        linf.append(np.linalg.norm(X - V, axis=1).max())
    assert all(b < a for a, b in zip(linf, linf[1:])), linf
    random = select_control_points(mesh, 200, method="random", seed=0)
    X = np.asarray(ls_mesh(mesh, random).vertices)
    # greedy targets the maximum error: it must beat random selection there
    assert linf[-1] < 0.5 * np.linalg.norm(X - V, axis=1).max()


def test_multiple_components_get_a_start_vertex_each():
    V, F = two_spheres()
    n1 = len(noisy_sphere(6)[0])
    for method in ("greedy", "combined"):
        selection = select_control_points((V, F), 2, method=method)
        assert sorted(selection < n1) == [False, True]
    approx, _idx = approximate((V, F), 10)
    assert np.isfinite(approx[0]).all()


def test_approximate_matches_ls_mesh_and_keeps_kind():
    V, F = noisy_sphere(8)
    legacy = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F.astype(np.int32))
    )
    before = np.asarray(legacy.vertices).copy()
    for method in ("greedy", "combined", "random"):
        out, idx = approximate(legacy, 20, method=method, seed=0 if method == "random" else None)
        assert isinstance(out, o3d.geometry.TriangleMesh)
        expected = np.asarray(ls_mesh(legacy, idx).vertices)
        np.testing.assert_allclose(np.asarray(out.vertices), expected, atol=1e-10)
    np.testing.assert_array_equal(np.asarray(legacy.vertices), before)
    tensor = o3d.t.geometry.TriangleMesh.from_legacy(legacy)
    out, _ = approximate(tensor, 20)
    assert isinstance(out, o3d.t.geometry.TriangleMesh)
    out, idx = approximate((V, F), 20, interpolate=True, weights=3.0)
    np.testing.assert_allclose(out[0][idx], V[idx], atol=1e-12)
    out, idx = approximate((V, F), 20, progress=True)
    assert out[0].shape == V.shape


def test_selection_errors():
    V, F = two_spheres()
    mesh = (V, F)
    with pytest.raises(ValueError, match="method must be one of"):
        select_control_points(mesh, 5, method="best")
    with pytest.raises(ValueError, match="count must be >= 1"):
        select_control_points(mesh, 0)
    with pytest.raises(ValueError, match=f"count must be <= {len(V)}"):
        select_control_points(mesh, len(V) + 1)
    with pytest.raises(TypeError, match="count must be an integer"):
        select_control_points(mesh, 5.0)
    with pytest.raises(ValueError, match=r"count must be at least the number of connected components \(2"):
        select_control_points(mesh, 1)
    with pytest.raises(ValueError, match="batch applies only to method='combined'"):
        select_control_points(mesh, 5, method="greedy", batch=4)
    with pytest.raises(
        ValueError, match="seed applies only to method='random', got seed=3 with method='combined'"
    ):
        select_control_points(mesh, 5, method="combined", seed=3)
    with pytest.raises(ValueError, match="batch must be >= 1"):
        select_control_points(mesh, 5, method="combined", batch=0)
    with pytest.raises(ValueError, match="weights must be positive"):
        select_control_points(mesh, 5, weights=0.0)
    with pytest.raises(TypeError, match="weights must be a number"):
        select_control_points(mesh, 5, weights=[1.0, 2.0])
    with pytest.raises(ValueError, match="seed must be non-negative"):
        select_control_points(mesh, 5, method="random", seed=-1)
    with pytest.raises(TypeError, match="seed must be None, an int or a numpy Generator"):
        select_control_points(mesh, 5, method="random", seed="x")
    with pytest.raises(TypeError, match="progress must be a bool"):
        select_control_points(mesh, 5, progress=1)
    with pytest.raises(TypeError, match="interpolate must be a bool"):
        approximate(mesh, 5, interpolate="yes")


def test_greedy_factors_once_and_updates_per_anchor(monkeypatch):
    from o3d_lsmesh.core.solve import SPDSolver, cholmod_available

    calls = {"factorize": 0, "ranks": []}
    factorize, update = SPDSolver._factorize, SPDSolver.update

    def counting_factorize(self, **kwargs):
        calls["factorize"] += 1
        return factorize(self, **kwargs)

    def counting_update(self, c):
        calls["ranks"].append(c.shape[1])
        return update(self, c)

    monkeypatch.setattr(SPDSolver, "_factorize", counting_factorize)
    monkeypatch.setattr(SPDSolver, "update", counting_update)
    V, F = noisy_sphere(8)
    select_control_points((V, F), 20, method="greedy")
    # CHOLMOD updates its factor; SciPy's LU is corrected by the updates (Woodbury) and refactored
    # only once the correction has cost as much as a factorization
    assert calls["ranks"] == [1] * 19
    assert calls["factorize"] == 1 if cholmod_available() else 1 < calls["factorize"] <= 1 + 19 // 4
    calls.update(factorize=0, ranks=[])
    select_control_points((V, F), 20, method="combined", batch=8)
    # one factorization, then one update of rank <= 8 per batch (batches end early on
    # this small sphere once every vertex is forbidden)
    assert calls["factorize"] == 1 if cholmod_available() else calls["factorize"] < 1 + len(calls["ranks"])
    assert sum(calls["ranks"]) == 19 and max(calls["ranks"]) == 8 and len(calls["ranks"]) >= 3


@pytest.mark.parametrize("method", ["greedy", "random", "combined"])
def test_scan_defects_seed_every_small_component(method):
    # isolated triangles, a valence-2 pillow, a sliver strip and unreferenced vertices: each is a component
    # and gets a control point, so the LS systems of approximate and encode_geometry are never singular
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parent))
    from defect_meshes import all_defects

    from o3d_lsmesh import SingularSystemError, decode_geometry, encode_geometry

    V, F, _ = all_defects()
    V = np.vstack([V, [[9.0, 9.0, 9.0], [9.5, 9.0, 9.0]]])  # two unreferenced vertices: components too
    # the components of the welded surface: coincident vertices merged (the duplicated seam's two parts
    # are one component), the zero-area needles that welding collapses left out
    to, welded = welded_surface(V, F)
    labels = Connectivity(welded, len(V)).components[1][to]  # each vertex's welded component
    components = set(labels.tolist())
    count = len(components)
    assert count == 15
    seed = 0 if method == "random" else None  # (the others draw nothing)
    for k in (count, count + 7):
        chosen = select_control_points((V, F), k, method=method, seed=seed)
        assert len(np.unique(chosen)) == k and set(labels[chosen].tolist()) == components
        approx, indices = approximate((V, F), k, method=method, seed=seed)
        assert np.isfinite(approx[0]).all() and set(labels[indices].tolist()) == components
    decoded = decode_geometry((V, F), encode_geometry((V, F), count + 7, method=method))
    assert np.isfinite(decoded[0]).all()
    # the user's own controls: a component without one is the user's singular system
    with pytest.raises(
        SingularSystemError, match="every connected component needs at least one control vertex"
    ):
        ls_mesh((V, F), np.flatnonzero(labels == labels[0]))
    with pytest.raises(
        ValueError, match=f"count must be at least the number of connected components \\({count}"
    ):
        select_control_points((V, F), count - 1, method=method)

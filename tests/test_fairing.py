"""Barycenter-constrained fairing (Liu et al. 2001, sections 3.1-3.3) against plain loops and invariants."""

from __future__ import annotations

import pickle

import numpy as np
import open3d as o3d
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from conftest import grid, load_mesh
from numpy.testing import assert_allclose

from o3d_lsmesh.core.boundary import boundary_halfedges
from o3d_lsmesh.core.connectivity import Connectivity
from o3d_lsmesh.core.liu import triangle_coefficients
from o3d_lsmesh.fairing import constrained_fairing, constrained_fairing_arrays, smooth_boundary_curves_arrays
from o3d_lsmesh.fairing.barycenter import local_operator
from o3d_lsmesh.metrics import signed_volume, surface_distance

TIGHT = 1e-12


def arrays(mesh):
    return np.asarray(mesh.vertices).copy(), np.asarray(mesh.triangles).astype(np.int64)


def noisy_sphere(resolution=8, sigma=0.03, seed=0):
    V, F = arrays(o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=resolution))
    return V + np.random.default_rng(seed).normal(0, sigma, V.shape), F


def neighbours(F, n):
    ring = [set() for _ in range(n)]
    for a, b, c in F.tolist():
        ring[a] |= {b, c}
        ring[b] |= {a, c}
        ring[c] |= {a, b}
    return ring


def eq7_reference_step(V, V0, F, use_triangle):
    """One local iteration written triangle by triangle from eq. 7 (A^-1 and the Lagrange formula)."""
    n = len(V)
    ring = neighbours(F, n)
    total, count = np.zeros((n, 3)), np.zeros(n)
    B = np.ones((1, 3))
    for t in F.tolist():
        if not use_triangle(t):
            continue
        A, Q = np.eye(3), np.zeros((3, 3))
        for a in range(3):
            n_a = len(ring[t[a]])
            for b in range(3):
                if b != a:
                    A[a, b] = -1.0 / n_a
            outside = [j for j in ring[t[a]] if j not in t]
            Q[a] = V[outside].sum(axis=0) / n_a
        Ai = np.linalg.inv(A)
        BAi = B @ Ai
        C = B @ V0[t]
        P = Ai @ Q + (Ai @ Ai.T @ B.T) @ (C - BAi @ Q) / (BAi @ BAi.T)
        total[t] += P
        count[t] += 1
    out = V.copy()
    has = count > 0
    out[has] = total[has] / count[has, None]
    return out


def test_one_local_iteration_equals_eq7_reference_loop():
    V, F = noisy_sphere(resolution=6)
    out = constrained_fairing_arrays(V, F, 1, method="local")
    assert_allclose(out, eq7_reference_step(V, V, F, lambda t: True), atol=TIGHT)


def test_three_local_iterations_keep_the_input_as_targets():
    V, F = noisy_sphere(resolution=5, seed=1)
    X = V
    for _ in range(3):
        X = eq7_reference_step(X, V, F, lambda t: True)
    assert_allclose(constrained_fairing_arrays(V, F, 3, method="local"), X, atol=TIGHT)


def test_open_mesh_iteration_uses_interior_triangles_and_the_curve_step():
    V, F = grid(7, 7)
    V = V + np.random.default_rng(2).normal(0, 0.03, V.shape)
    boundary = np.zeros(len(V), dtype=bool)
    boundary[boundary_halfedges(F).ravel()] = True
    reference = eq7_reference_step(V, V, F, lambda t: not boundary[t].any())
    reference[boundary] = smooth_boundary_curves_arrays(V, F, 1)[boundary]
    assert_allclose(constrained_fairing_arrays(V, F, 1, method="local"), reference, atol=TIGHT)
    fixed = constrained_fairing_arrays(V, F, 2, smooth_boundary=False, method="local")
    assert_allclose(fixed[boundary], V[boundary], atol=0)
    assert np.abs(fixed[~boundary] - V[~boundary]).max() > 1e-3


def test_triangle_coefficients_equal_eq7_and_handle_singular_A():
    valences = np.array([[6, 5, 7], [3, 3, 3], [12, 4, 6]])
    M, u = triangle_coefficients(valences)
    for row, (Mt, ut) in zip(valences, zip(M, u)):
        A = np.eye(3) - (1.0 / row)[:, None] * (1 - np.eye(3))
        Ai = np.linalg.inv(A)
        g = Ai.sum(axis=0)
        assert_allclose(ut, Ai @ g / (g @ g), atol=TIGHT)
        assert_allclose(Mt, Ai - np.outer(ut, g), atol=TIGHT)
    # all valences 2 (a two-triangle pillow): A is singular, the constrained minimizer is the centroid
    M2, u2 = triangle_coefficients(np.array([[2, 2, 2]]))
    assert_allclose(u2[0], np.full(3, 1 / 3), atol=TIGHT)
    assert_allclose(M2[0] @ np.ones(3), 0.0, atol=TIGHT)


def test_barycenters_move_far_less_than_vertices():
    # Each triangle's own relaxation holds its barycenter exactly; averaging the estimates moves it a
    # little (the paper: "the centers of the triangles may be slightly displaced"). Measured here:
    # barycenters move about 0.37 of the vertex displacement, against 0.64 for Open3D's Laplacian.
    V, F = noisy_sphere(resolution=12, sigma=0.04)

    def ratio(out):
        vertex_move = np.linalg.norm(out - V, axis=1).mean()
        return np.linalg.norm(out[F].mean(axis=1) - V[F].mean(axis=1), axis=1).mean() / vertex_move

    ours = constrained_fairing_arrays(V, F, 1, method="local")
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F.astype(np.int32))
    )
    laplacian = np.asarray(mesh.filter_smooth_laplacian(number_of_iterations=1).vertices)
    assert np.linalg.norm(ours - V, axis=1).mean() > 0.03
    assert ratio(ours) < 0.45
    assert ratio(ours) < 0.7 * ratio(laplacian)


def test_volume_is_kept_while_open3d_laplacian_shrinks():
    V, F = noisy_sphere(resolution=20, sigma=0.01, seed=4)
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F.astype(np.int32))
    )
    before = signed_volume(mesh)
    ours = signed_volume(constrained_fairing(mesh, 20, method="local"))
    laplacian = signed_volume(mesh.filter_smooth_laplacian(number_of_iterations=20))
    assert abs(ours / before - 1) < 0.005
    assert laplacian / before - 1 < -0.02  # Open3D's Laplacian loses more than 2%
    glob = signed_volume(constrained_fairing(mesh, 1, method="global"))
    assert abs(glob / before - 1) < 0.005


@pytest.mark.parametrize("method", ["local", "global"])
def test_translation_and_rotation_equivariance(method):
    V, F = grid(7, 7, z=lambda x, y: 0.2 * np.sin(3 * x) * y)
    V = V + np.random.default_rng(5).normal(0, 0.02, V.shape)
    rotation, _ = np.linalg.qr(np.random.default_rng(6).normal(size=(3, 3)))
    shift = np.array([3.0, -2.0, 10.0])
    out = constrained_fairing_arrays(V, F, 4, method=method)
    moved = constrained_fairing_arrays(V @ rotation.T + shift, F, 4, method=method)
    assert_allclose(moved, out @ rotation.T + shift, atol=1e-9)


@pytest.mark.parametrize("method", ["local", "global"])
def test_regular_flat_grid_is_a_fixed_point_and_stays_flat(method):
    V, F = grid(8, 8)
    assert_allclose(constrained_fairing_arrays(V, F, 5, method=method, smooth_boundary=False), V, atol=1e-12)
    jittered = V + np.random.default_rng(7).normal(0, 0.02, V.shape) * np.array([1, 1, 0])
    out = constrained_fairing_arrays(jittered, F, 5, method=method)
    assert np.array_equal(out[:, 2], np.zeros(len(V)))
    inside = ~np.isin(np.arange(len(V)), boundary_halfedges(F).ravel())
    assert np.abs(out - V)[inside].mean() < 0.8 * np.abs(jittered - V)[inside].mean()


def test_global_iteration_equals_direct_penalty_solve():
    V, F = noisy_sphere(resolution=6, seed=8)
    n = len(V)
    mu = 0.7
    pairs = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    A = sp.csr_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    adjacency = ((A + A.T) > 0).astype(float)
    K = sp.identity(n) - sp.diags(1.0 / np.asarray(adjacency.sum(axis=1)).ravel()) @ adjacency
    H = sp.csr_matrix((np.ones(3 * len(F)), (np.repeat(np.arange(len(F)), 3), F.ravel())), shape=(len(F), n))
    normal = (K.T @ K + mu * H.T @ H).tocsc()
    expected = spla.spsolve(normal, mu * (H.T @ (H @ V)))
    assert_allclose(constrained_fairing_arrays(V, F, 1, method="global", mu=mu), expected, atol=1e-10)
    # a second iteration re-takes the targets from the first result
    second = spla.spsolve(normal, mu * (H.T @ (H @ expected)))
    assert_allclose(constrained_fairing_arrays(V, F, 2, method="global", mu=mu), second, atol=1e-10)


def test_global_mu_trades_smoothing_for_fidelity():
    V, F = noisy_sphere(resolution=10, seed=9)
    moves = [
        np.linalg.norm(constrained_fairing_arrays(V, F, 1, method="global", mu=mu) - V, axis=1).mean()
        for mu in (0.01, 0.1, 1.0, 100.0)
    ]
    assert moves[0] > moves[1] > moves[2] > moves[3]
    assert moves[3] < 0.05 * moves[0]


def test_reimpose_every_one_equals_chained_single_iterations():
    V, F = grid(7, 7, z=lambda x, y: x * y)
    V = V + np.random.default_rng(10).normal(0, 0.02, V.shape)
    chained = V
    for _ in range(3):
        chained = constrained_fairing_arrays(chained, F, 1, method="local")
    assert_allclose(
        constrained_fairing_arrays(V, F, 3, method="local", reimpose_every=1), chained, atol=TIGHT
    )
    assert not np.allclose(constrained_fairing_arrays(V, F, 3, method="local"), chained, atol=1e-6)


def test_denoising_a_real_scan_lowers_distance_to_clean_mesh():
    clean = load_mesh("bunny.ply")
    V, F = arrays(clean)
    edge = np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1).mean()
    noisy = (V + np.random.default_rng(11).normal(0, 0.3 * edge, V.shape), F)
    before = surface_distance(noisy, clean, number_of_points=20_000)["mean"]
    for method in ("local", "global"):
        after = surface_distance(
            constrained_fairing(noisy, 10 if method == "local" else 1, method=method),
            clean,
            number_of_points=20_000,
        )["mean"]
        assert after < 0.75 * before, method


def test_components_are_faired_independently():
    V1, F1 = noisy_sphere(resolution=5, seed=12)
    V2, F2 = grid(5, 5)
    V2 = V2 + np.random.default_rng(13).normal(0, 0.02, V2.shape)
    V = np.vstack([V1, V2])
    F = np.vstack([F1, F2 + len(V1)])
    out = constrained_fairing_arrays(V, F, 3, method="local")
    assert_allclose(out[: len(V1)], constrained_fairing_arrays(V1, F1, 3, method="local"), atol=TIGHT)
    assert_allclose(out[len(V1) :], constrained_fairing_arrays(V2, F2, 3, method="local"), atol=TIGHT)


@pytest.mark.parametrize("method", ["local", "global"])
def test_awkward_inputs_give_finite_results(method):
    V, F = grid(5, 5)
    V = np.vstack([V, [[9.0, 9.0, 9.0]]])  # an isolated vertex
    V[6] = V[7]  # two coincident vertices: zero-area triangles
    pillow = np.array([[0, 0, 2.0], [1, 0, 2], [0, 1, 2]])  # closed, every valence 2
    lone = np.array([[5, 5, 5.0], [6, 5, 5], [5, 6, 5]])  # one triangle: every valence 2, on the boundary
    sliver = np.array([[0, 0, 4.0], [1, 0, 4], [2, 0, 4]])  # collinear
    V = np.vstack([V, pillow, lone, sliver])
    b = 26
    F = np.vstack(
        [F, [[b, b + 1, b + 2], [b, b + 2, b + 1]], [[b + 3, b + 4, b + 5]], [[b + 6, b + 7, b + 8]]]
    )
    out = constrained_fairing_arrays(V, F, 4, method=method)
    assert np.isfinite(out).all()
    assert_allclose(out[25], V[25], atol=0)  # the isolated vertex stays
    assert_allclose(out[b + 3 :], V[b + 3 :], atol=0)  # triangle loops are held fixed
    assert_allclose(
        out[b : b + 3].sum(axis=0), V[b : b + 3].sum(axis=0), atol=1e-12
    )  # pillow keeps its barycenter


def test_vertex_joining_two_closed_fans_follows_eq7_with_its_whole_ring():
    # two octahedra sharing one vertex: vertex-non-manifold, no boundary. Eq. 7 still holds triangle by
    # triangle, the joined vertex's valence counting both fans (8 neighbours), as in the reference loop.
    octa = o3d.geometry.TriangleMesh.create_octahedron()
    V, F = arrays(octa)
    V2 = V + np.array([0, 0, 2.0])  # vertex with z = 1 of the first equals z = -1 of the second after shift
    top = int(np.argmax(V[:, 2]))
    bottom = int(np.argmin(V2[:, 2]))
    index = np.arange(len(V)) + len(V)
    index[bottom] = top
    F2 = index[F]
    Vall, Fall = np.vstack([V, V2]), np.vstack([F, F2])
    noisy = Vall + np.random.default_rng(5).normal(0, 0.05, Vall.shape)
    out = constrained_fairing_arrays(noisy, Fall, 3, method="local")
    X = noisy
    for _ in range(3):
        X = eq7_reference_step(X, noisy, Fall, lambda t: True)
    assert_allclose(out, X, atol=TIGHT)
    assert np.abs(out[top] - noisy[top]).max() > 1e-3  # the joined vertex is faired, not held
    assert_allclose(out[len(V) + bottom], noisy[len(V) + bottom], atol=0)  # the vertex no triangle uses
    # the noiseless pair is symmetric under z -> 2 - z (the octahedra swap): so is its fairing
    faired = constrained_fairing_arrays(Vall, Fall, 3, method="local")
    used = np.unique(Fall)
    mirrored = Vall[used] * [1, 1, -1] + [0, 0, 2]
    image = used[np.argmin(np.linalg.norm(mirrored[:, None] - Vall[used][None], axis=2), axis=1)]
    assert_allclose(faired[image], faired[used] * [1, 1, -1] + [0, 0, 2], atol=1e-12)
    assert_allclose(faired[top, :2], 0.0, atol=1e-12)


def test_zero_iterations_returns_an_unchanged_copy_of_each_kind(sphere):
    out = constrained_fairing(sphere, 0)
    assert out is not sphere and isinstance(out, o3d.geometry.TriangleMesh)
    assert np.array_equal(np.asarray(out.vertices), np.asarray(sphere.vertices))
    V, F = arrays(sphere)
    tuple_out = constrained_fairing((V, F), 0)
    assert tuple_out[0] is not V and np.array_equal(tuple_out[0], V)
    tensor = o3d.t.geometry.TriangleMesh.from_legacy(sphere)
    tensor_out = constrained_fairing(tensor, 3, method="local")
    assert isinstance(tensor_out, o3d.t.geometry.TriangleMesh)
    local = constrained_fairing_arrays(V, F, 3, method="local")
    assert_allclose(tensor_out.vertex.positions.numpy(), local, atol=1e-6)


def test_input_is_not_modified_and_colors_are_kept(sphere):
    noisy = o3d.geometry.TriangleMesh(sphere)
    noisy.vertices = o3d.utility.Vector3dVector(noisy_sphere(12)[0])
    noisy.vertex_colors = o3d.utility.Vector3dVector(
        np.random.default_rng(0).random((len(noisy.vertices), 3))
    )
    before = np.asarray(noisy.vertices).copy()
    out = constrained_fairing(noisy, 3, progress=True)
    assert np.array_equal(np.asarray(noisy.vertices), before)
    assert np.array_equal(np.asarray(out.vertex_colors), np.asarray(noisy.vertex_colors))
    assert not np.allclose(np.asarray(out.vertices), before)


def test_local_operator_pickles():
    V, F = noisy_sphere(resolution=5)
    op = local_operator(Connectivity(F, len(V)))
    copy = pickle.loads(pickle.dumps(op))
    assert_allclose(copy.step(V, copy.constant(V)), op.step(V, op.constant(V)), atol=0)


def test_raises():
    V, F = grid(4, 4)
    mesh = (V, F)
    cases = [
        (ValueError, "number_of_iterations must be >= 0, got -1", dict(number_of_iterations=-1)),
        (TypeError, "number_of_iterations must be an integer, got 1.5", dict(number_of_iterations=1.5)),
        (TypeError, "number_of_iterations must be an integer, got True", dict(number_of_iterations=True)),
        (
            ValueError,
            r"method must be one of \[.*'global', 'features', 'auto'\], got 'cg'",
            dict(method="cg"),
        ),
        (TypeError, r"method must be one of \[.*'global', 'features', 'auto'\], got 3", dict(method=3)),
        (ValueError, "mu must be positive and finite, got 0.0", dict(method="global", mu=0.0)),
        (TypeError, "mu must be a number, got 'big'", dict(method="global", mu="big")),
        (ValueError, r"mu does not apply to method='local'", dict(method="local", mu=1.0)),
        (ValueError, "reimpose_every must be >= 1, got 0", dict(reimpose_every=0)),
        (TypeError, "reimpose_every must be an integer, got 2.0", dict(reimpose_every=2.0)),
        (
            ValueError,
            r"reimpose_every does not apply to method='global'",
            dict(method="global", reimpose_every=2),
        ),
        (TypeError, "smooth_boundary must be a bool, got int", dict(method="local", smooth_boundary=1)),
        (TypeError, "progress must be a bool, got str", dict(progress="yes")),
    ]
    for error, message, kwargs in cases:
        iterations = kwargs.pop("number_of_iterations", 2)
        with pytest.raises(error, match=message):
            constrained_fairing(mesh, iterations, **kwargs)
        with pytest.raises(error, match=message):
            constrained_fairing_arrays(V, F, iterations, **kwargs)
    with pytest.raises(TypeError, match="mesh must be an open3d"):
        constrained_fairing([V, F], 2)
    with pytest.raises(ValueError, match="mesh vertices must be finite"):
        constrained_fairing_arrays(np.full((3, 3), np.nan), [[0, 1, 2]], 1)
    # real-scan defects are handled, not refused (issue 12): a fin's vertices and a boundary pinch are held
    extra = np.vstack([V, [[0.5, -0.5, 0.3]]])
    nonmanifold = np.vstack([F, [[0, 1, 16], [1, 0, 16]]])
    out = constrained_fairing_arrays(extra, nonmanifold, 1, method="local")
    assert np.isfinite(out).all() and np.array_equal(out[[0, 1, 16]], extra[[0, 1, 16]])
    bow = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0.0]])
    bow_triangles = np.array([[0, 1, 2], [0, 3, 4]])
    assert_allclose(constrained_fairing_arrays(bow, bow_triangles, 1, method="local"), bow, atol=0)
    assert_allclose(
        constrained_fairing_arrays(bow, bow_triangles, 1, smooth_boundary=False, method="local"), bow, atol=0
    )


def _soup(seed):
    # an open, non-manifold mesh: a sphere with a hole, a fin (three triangles on one edge) and a
    # pinched corner, numbered at random
    V, F = noisy_sphere(resolution=10, seed=seed)
    F = F[5:]
    n = len(V)
    extra = np.array([[F[0, 0], F[0, 1], n], [F[1, 0], F[1, 1], n + 1], [F[2, 2], n + 2, n + 3]])
    V = np.vstack([V, np.random.default_rng(seed).normal(size=(4, 3))])
    perm = np.random.default_rng(seed).permutation(len(V))
    return V[np.argsort(perm)], perm[np.vstack([F, extra])]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_edge_structure_equals_a_stable_sort_of_the_edge_keys(seed):
    from o3d_lsmesh.core.connectivity import Connectivity, halfedges

    V, F = _soup(seed)
    n = len(V)
    es = Connectivity(F, n).edge_structure
    h = halfedges(F)
    keys = np.minimum(h[:, 0], h[:, 1]) * n + np.maximum(h[:, 0], h[:, 1])
    order = np.argsort(keys, kind="stable")  # the reference: numpy's stable sort
    distinct, starts, inverse, counts = np.unique(
        keys[order], return_index=True, return_inverse=True, return_counts=True
    )
    assert es.order.tolist() == order.tolist()
    assert es.starts.tolist() == starts.tolist() and es.counts.tolist() == counts.tolist()
    assert es.edges.tolist() == np.stack([distinct // n, distinct % n], axis=1).tolist()
    assert (es.inverse[order] == inverse).all()
    assert (es.counts > 2).any() and (es.counts == 1).any()  # the soup has a fin and a boundary


def _fin_and_isolated():
    # four triangles on edge (0, 1), a separate triangle, an isolated vertex (8)
    V = np.random.default_rng(5).normal(size=(9, 3))
    return V, np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4], [4, 1, 0], [2, 1, 5], [5, 6, 7]])


@pytest.mark.parametrize("case", ["soup0", "soup1", "soup2", "sphere", "grid", "fin"])
def test_vertex_rings_equal_plain_loops(case):
    # issue 16: local fairing's one pass over the corners against sets built triangle by triangle,
    # in blocks of 2 vertices (so that rows meet block ends) and in one block
    from o3d_lsmesh.core.connectivity import RING_COLUMN_SLOT, RING_ROW_SLOT, _vertex_rings

    if case.startswith("soup"):
        V, F = _soup(int(case[-1]))
    else:
        V, F = {"sphere": noisy_sphere(6), "grid": grid(5, 4), "fin": _fin_and_isolated()}[case]
    n, m = len(V), len(F)
    rings = _vertex_rings(F, n, 2 if case in ("soup1", "fin") else 1 << 14)
    ring = neighbours(F, n)
    on_edge = {}
    for t, tri in enumerate(F.tolist()):
        for d, (a, b) in enumerate(zip(RING_ROW_SLOT, RING_COLUMN_SLOT)):
            on_edge.setdefault((tri[a], tri[b]), []).append(d * m + t)
    for v in range(n):
        row = slice(rings.indptr[v], rings.indptr[v + 1])
        assert rings.indices[row].tolist() == sorted(ring[v] | {v})
        assert rings.indices[rings.diagonal[v]] == v and rings.valence[v] == len(ring[v])
        for slot in range(row.start, row.stop):
            w = int(rings.indices[slot])
            pair = rings.pairs[:, slot].tolist()
            if w == v:
                assert pair == [6 * m, 6 * m]
            elif len(on_edge[(v, w)]) == 2:
                assert sorted(pair) == sorted(on_edge[(v, w)])
            elif len(on_edge[(v, w)]) == 1:
                assert pair == on_edge[(v, w)] * 2
            else:
                assert pair[0] != pair[1] and set(pair) <= set(on_edge[(v, w)])
    counts = {}
    for tri in F.tolist():
        for a in range(3):
            key = tuple(sorted((tri[a], tri[(a + 1) % 3])))
            counts[key] = counts.get(key, 0) + 1
    boundary = np.zeros(n, dtype=bool)
    for (a, b), c in counts.items():
        if c != 2:
            boundary[[a, b]] = True
    assert rings.boundary.tolist() == boundary.tolist()


def test_local_operator_forms_the_constraint_part_during_assembly():
    V, F = _soup(1)
    kept = local_operator(Connectivity(F, len(V)), positions0=V)
    assert_allclose(kept.initial, kept.e3 @ V, rtol=TIGHT, atol=TIGHT)
    assert_allclose(kept.constant(V), kept.e3 @ V, rtol=TIGHT, atol=TIGHT)
    dropped = local_operator(Connectivity(F, len(V)), positions0=V, keep_constraint=False)
    assert dropped.e3 is None and np.array_equal(dropped.initial, kept.initial)
    with pytest.raises(ValueError, match="keep_constraint=False"):
        dropped.constant(V)
    for name in ("e1", "e2", "adjacency"):
        assert np.array_equal(getattr(dropped, name).toarray(), getattr(kept, name).toarray())


@pytest.mark.parametrize("iterations", [1, 2, 3])
def test_local_result_is_a_plain_array_of_the_reference(iterations):
    # the iterations swap two buffers: the result must still be the caller's own float64 array, equal
    # to the reference loop, for odd and even counts
    V, F = noisy_sphere(resolution=5, seed=2)
    X = V
    for _ in range(iterations):
        X = eq7_reference_step(X, V, F, lambda t: True)
    out = constrained_fairing_arrays(V, F, iterations, method="local")
    assert out.dtype == np.float64 and out.flags.owndata and out.flags.c_contiguous
    assert_allclose(out, X, atol=TIGHT)


def test_laplacian_from_the_edge_structure_equals_the_reference():
    from o3d_lsmesh.core.connectivity import Connectivity
    from o3d_lsmesh.core.operators import uniform_from_edges

    V, F = _soup(3)
    n = len(V) + 2  # two unreferenced vertices: zero rows
    L = uniform_from_edges(Connectivity(F, n).edges, n)
    ring = neighbours(F, n)
    reference = np.zeros((n, n))
    for i, js in enumerate(ring):
        if js:
            reference[i, i] = 1.0
            reference[i, sorted(js)] = -1.0 / len(js)
    assert_allclose(L.toarray(), reference, atol=TIGHT)
    assert L.has_canonical_format and (np.diff(L.indices[L.indptr[0] : L.indptr[1]]) > 0).all()


@pytest.mark.parametrize("method", ["scan", "local", "global", "features"])
def test_one_connectivity_per_fairing_call(monkeypatch, method):
    # every entry point builds the mesh's Connectivity once and passes it down: one object, its edges
    # grouped at most once and its rings at most once, open or closed, arrays or wrapper
    import o3d_lsmesh.core.connectivity as connectivity

    calls = []

    def counting(name, function):
        def wrapped(*args, **kwargs):
            calls.append(name)
            return function(*args, **kwargs)

        return wrapped

    init = connectivity.Connectivity.__init__
    monkeypatch.setattr(connectivity.Connectivity, "__init__", counting("Connectivity", init))
    monkeypatch.setattr(connectivity, "_edge_structure", counting("edges", connectivity._edge_structure))
    monkeypatch.setattr(connectivity, "_vertex_rings", counting("rings", connectivity._vertex_rings))
    V, F = grid(12, 12)
    open_ = (V + np.random.default_rng(0).normal(scale=0.01, size=V.shape), F)
    for mesh in (open_, noisy_sphere(resolution=6)):
        for call in (constrained_fairing_arrays, lambda V, F, *a, **k: constrained_fairing((V, F), *a, **k)):
            calls.clear()
            out = call(*mesh, 2 if method != "scan" else 1, method=method)
            assert calls.count("Connectivity") == 1, calls
            assert calls.count("edges") <= 1 and calls.count("rings") <= 1, calls
            assert np.isfinite(np.asarray(out if isinstance(out, np.ndarray) else out[0])).all()

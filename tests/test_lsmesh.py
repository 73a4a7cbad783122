import pickle

import numpy as np
import open3d as o3d
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from conftest import grid, load_mesh
from hypothesis import given, settings
from hypothesis import strategies as st
from threadpoolctl import threadpool_limits

from o3d_lsmesh import LSMeshSolver, SingularSystemError, laplacian, ls_mesh, reconstruct_geometry


def lsqr_reference(V, F, idx, positions, weights):
    """Independent solution: lsqr on the rectangular (n+k) x n system of eq. 3."""
    n = len(V)
    L = laplacian((V, F))
    rows = sp.csr_matrix((weights, (np.arange(len(idx)), idx)), shape=(len(idx), n))
    A = sp.vstack([L, rows]).tocsr()
    out = np.zeros((n, 3))
    for k in range(3):
        b = np.concatenate([np.zeros(n), weights * positions[:, k]])
        out[:, k] = spla.lsqr(A, b, atol=1e-14, btol=1e-14, conlim=1e12, iter_lim=200_000)[0]
    return out


def dense_reference(mesh, idx, positions, weights):
    """Independent solution: the normal equations ``(L^T L + W^2) X = W^2 C`` of eq. 3, dense."""
    L = laplacian(mesh).toarray()
    pinned = np.zeros(len(L))
    np.add.at(pinned, idx, np.broadcast_to(np.asarray(weights, dtype=float) ** 2, len(idx)))
    rhs = np.zeros((len(L), 3))
    np.add.at(rhs, idx, np.broadcast_to(np.asarray(weights, dtype=float) ** 2, len(idx))[:, None] * positions)
    return np.linalg.solve(L.T @ L + np.diag(pinned), rhs)


def arrays(mesh):
    return np.asarray(mesh.vertices).copy(), np.asarray(mesh.triangles).astype(np.int64)


@pytest.mark.parametrize("name", ["sphere", "torus", "venus.ply"])
def test_agrees_with_lsqr(name):
    if name == "sphere":
        mesh = o3d.geometry.TriangleMesh.create_sphere(resolution=10)
    elif name == "torus":
        mesh = o3d.geometry.TriangleMesh.create_torus(radial_resolution=20, tubular_resolution=10)
    else:
        mesh = load_mesh(name)
    V, F = arrays(mesh)
    rng = np.random.default_rng(1)
    idx = rng.choice(len(V), 25, replace=False)
    w = rng.uniform(0.5, 3.0, 25)
    out = np.asarray(ls_mesh(mesh, idx, weights=w).vertices)
    ref = lsqr_reference(V, F, idx, V[idx], w)
    np.testing.assert_allclose(out, ref, atol=1e-7 * np.abs(V).max())


def test_agrees_with_lsqr_on_real_scan():
    # a raw range scan (noise, holes, islands, bow-ties): a ball of it keeps lsqr quick
    mesh = load_mesh("bunny_scan.ply")
    V, F = arrays(mesh)
    centre = V[np.argmin(np.linalg.norm(V - V.mean(0), axis=1))]
    inside = np.linalg.norm(V - centre, axis=1) < 0.12 * np.ptp(V, axis=0).max()
    F = F[inside[F].all(axis=1)]
    used = np.unique(F)
    V, F = V[used], np.searchsorted(used, F)
    from o3d_lsmesh.core.connectivity import Connectivity

    _, labels = Connectivity(F, len(V)).components
    one_per_component = np.unique(labels, return_index=True)[1]
    idx = np.union1d(np.random.default_rng(2).choice(len(V), len(V) // 50, replace=False), one_per_component)
    w = np.full(len(idx), 2.0)
    out, _ = ls_mesh((V, F), idx, weights=w)
    ref = lsqr_reference(V, F, idx, V[idx], w)
    assert len(V) > 1500
    assert np.abs(out - ref).max() < 1e-7 * np.ptp(V, axis=0).max()


def test_interpolate_hits_constraints_and_soft_converges(sphere):
    V, _ = arrays(sphere)
    idx = np.array([0, 7, 40, 90, 120])
    target = V[idx] + 0.3
    hard = np.asarray(ls_mesh(sphere, idx, target, interpolate=True).vertices)
    assert np.array_equal(hard[idx], target)
    gaps = [
        np.abs(np.asarray(ls_mesh(sphere, idx, target, weights=w).vertices) - hard).max()
        for w in (1, 10, 100, 1000)
    ]
    assert all(b < a for a, b in zip(gaps, gaps[1:]))
    assert gaps[-1] < 1e-4


@settings(max_examples=15, deadline=None)
@given(
    angles=st.tuples(*[st.floats(-np.pi, np.pi) for _ in range(3)]),
    shift=st.tuples(*[st.floats(-10, 10) for _ in range(3)]),
    interpolate=st.booleans(),
)
def test_rigid_motion_equivariance(angles, shift, interpolate):
    mesh = o3d.geometry.TriangleMesh.create_sphere(resolution=8)
    V, _ = arrays(mesh)
    R = o3d.geometry.get_rotation_matrix_from_xyz(np.array(angles))
    idx = np.array([0, 3, 17, 30, 51])
    solver = LSMeshSolver(mesh, idx, weights=1.5, interpolate=interpolate)
    base = solver.solve(V[idx])
    moved = solver.solve(V[idx] @ R.T + np.array(shift))
    np.testing.assert_allclose(moved, base @ R.T + np.array(shift), atol=1e-9)


def test_all_vertices_constrained_reproduces_input(sphere):
    V, _ = arrays(sphere)
    for interpolate in (False, True):
        out = np.asarray(ls_mesh(sphere, np.arange(len(V)), interpolate=interpolate, weights=1e3).vertices)
        np.testing.assert_allclose(out, V, atol=1e-5)
    out = np.asarray(ls_mesh(sphere, np.arange(len(V)), interpolate=True).vertices)
    assert np.array_equal(out, V)


@pytest.mark.parametrize("interpolate", [False, True])
def test_add_anchors_equals_a_dense_solve(interpolate):
    mesh = o3d.geometry.TriangleMesh.create_torus(radial_resolution=24, tubular_resolution=12)
    V, _ = arrays(mesh)
    solver = LSMeshSolver(mesh, [0, 50, 100], weights=2.0, interpolate=interpolate)
    solver.add_anchors([10, 200], weights=[3.0, 0.5])
    solver.add_anchors([77], positions=[[1.0, 2.0, 3.0]], weights=7.0)
    got = solver.solve()
    positions = np.concatenate([V[[0, 50, 100, 10, 200]], [[1.0, 2.0, 3.0]]])
    if interpolate:
        # fresh reference: hard anchors eliminated, relaxed anchors as weighted rows
        L = laplacian(mesh).tocsc()
        hard = np.array([0, 50, 100])
        free = np.setdiff1d(np.arange(len(V)), hard)
        soft, w = np.array([10, 200, 77]), np.array([3.0, 0.5, 7.0])
        rows = sp.csr_matrix((w, (np.arange(3), np.searchsorted(free, soft))), shape=(3, len(free)))
        A = sp.vstack([L[:, free], rows]).tocsc()
        b = np.concatenate([-(L[:, hard] @ V[hard]), w[:, None] * positions[3:]])
        expected = V.copy()
        expected[free] = np.linalg.solve((A.T @ A).toarray(), A.T @ b)
    else:
        expected = dense_reference(mesh, [0, 50, 100, 10, 200, 77], positions, [2, 2, 2, 3.0, 0.5, 7.0])
    assert np.linalg.norm(got - expected) <= 1e-8 * np.linalg.norm(expected)


def test_solve_with_moved_constraints_equals_a_dense_solve(sphere):
    V, _ = arrays(sphere)
    idx = [0, 5, 40, 90]
    solver = LSMeshSolver(sphere, idx, weights=4.0)
    moved = V[idx] + np.array([0.0, 0.0, 0.5])
    np.testing.assert_allclose(solver.solve(moved), dense_reference(sphere, idx, moved, 4.0), atol=1e-10)
    assert np.asarray(solver.mesh(moved).triangles).shape == np.asarray(sphere.triangles).shape


def test_solver_pickles():
    mesh = o3d.geometry.TriangleMesh.create_sphere(resolution=8)
    solver = LSMeshSolver(mesh, [0, 9, 33])
    solver.add_anchors([20])
    clone = pickle.loads(pickle.dumps(solver))
    np.testing.assert_allclose(clone.solve(), solver.solve(), atol=1e-12)


def test_several_components_need_constraints():
    V1, F1 = grid(4, 4)
    V = np.concatenate([V1, V1 + 5])
    F = np.concatenate([F1, F1 + 16])
    with pytest.raises(SingularSystemError, match="1 of 2 components"):
        ls_mesh((V, F), [0, 3])
    out, _ = ls_mesh((V, F), [0, 16])
    assert np.all(np.isfinite(out))
    with pytest.raises(SingularSystemError, match="components"):
        reconstruct_geometry((V, F), np.arange(16, 32))


def test_reconstruct_equals_a_dense_least_squares_solve():
    mesh = load_mesh("camel.ply")
    V, _F = arrays(mesh)
    # the hump region: vertices within a ball around the highest vertex
    top = np.argmax(V[:, 1])
    unknown = np.flatnonzero(np.linalg.norm(V - V[top], axis=1) < 0.07 * np.ptp(V, axis=0).max())
    known = np.setdiff1d(np.arange(len(V)), unknown)
    scrambled = V.copy()
    scrambled[unknown] = 1e3  # the unknown positions must not matter
    mesh2 = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(scrambled), mesh.triangles)
    out = np.asarray(reconstruct_geometry(mesh2, unknown).vertices)
    # independent: min ||L[:, unknown] x + L[:, known] V_known||^2 by dense least squares (on the rows
    # touching an unknown vertex: the others are constants)
    L = laplacian(mesh).tocsr()
    rows = np.flatnonzero(np.abs(L[:, unknown]).sum(axis=1).A1)
    full = V.copy()
    with threadpool_limits(limits=1, user_api="blas"):  # a small dense solve: threads only wait
        full[unknown] = np.linalg.lstsq(
            L[rows][:, unknown].toarray(), -(L[rows][:, known] @ V[known]), rcond=None
        )[0]
    np.testing.assert_allclose(out, full, atol=1e-9)
    assert np.array_equal(out[known], V[known])
    soft = np.asarray(reconstruct_geometry(mesh, unknown, interpolate=False, weights=1e3).vertices)
    assert np.abs(soft - full).max() < 1e-2 * np.ptp(V)


@pytest.mark.parametrize("rim", [False, True])
def test_reconstruct_ignores_placeholder_positions_of_lone_unknown_vertices(rim):
    # unknown vertices given one placeholder position, some of them alone among known neighbours (or on
    # an open rim, sharing no triangle): the result is the one with the true positions (they merged into
    # one vertex before)
    mesh = o3d.geometry.TriangleMesh.create_sphere(resolution=20)
    V = np.asarray(mesh.vertices)
    if rim:  # the bottom cap cut away: its rim ring at z about -0.8
        mesh.remove_triangles_by_mask(V[np.asarray(mesh.triangles)].mean(axis=1)[:, 2] < -0.85)
        mesh.remove_unreferenced_vertices()
        V = np.asarray(mesh.vertices)
    band = np.flatnonzero(np.abs(V[:, 2] - (V[:, 2].min() if rim else 0.0)) < 0.05)
    lone = band[[0, 7, 14]]  # no two of them on a triangle, none near the cap
    region = np.concatenate([np.flatnonzero(V[:, 2] > 0.8), lone])
    blank = o3d.geometry.TriangleMesh(mesh)
    np.asarray(blank.vertices)[region] = 0.0
    expected = np.asarray(reconstruct_geometry(mesh, region).vertices)
    np.testing.assert_array_equal(np.asarray(reconstruct_geometry(blank, region).vertices), expected)
    # the lone ones stay three vertices, each near where it was
    assert (np.linalg.norm(expected[lone] - V[lone], axis=1) < 0.3).all()


def test_kinds_attributes_and_input_untouched(sphere):
    sphere.compute_vertex_normals()
    sphere.vertex_colors = o3d.utility.Vector3dVector(
        np.random.default_rng(0).random((len(sphere.vertices), 3))
    )
    before = np.asarray(sphere.vertices).copy()
    out = ls_mesh(sphere, [0, 5, 40], weights=1.0)
    assert np.array_equal(np.asarray(sphere.vertices), before)
    assert isinstance(out, o3d.geometry.TriangleMesh)
    assert np.array_equal(np.asarray(out.vertex_colors), np.asarray(sphere.vertex_colors))
    expected = o3d.geometry.TriangleMesh(out)
    expected.compute_vertex_normals()
    np.testing.assert_allclose(np.asarray(out.vertex_normals), np.asarray(expected.vertex_normals))
    tmesh = o3d.t.geometry.TriangleMesh.from_legacy(sphere)
    tmesh.vertex.positions = tmesh.vertex.positions.to(o3d.core.float32)
    tbefore = tmesh.vertex.positions.numpy().copy()
    tout = ls_mesh(tmesh, [0, 5, 40])
    assert isinstance(tout, o3d.t.geometry.TriangleMesh)
    assert tout.vertex.positions.dtype == o3d.core.float32
    assert "colors" in tout.vertex and "normals" in tout.vertex
    assert np.array_equal(tmesh.vertex.positions.numpy(), tbefore)
    np.testing.assert_allclose(tout.vertex.positions.numpy(), np.asarray(out.vertices), atol=1e-5)
    # ls_mesh drops its copy of the triangles while it factors and reads them again from the input
    assert np.array_equal(np.asarray(out.triangles), np.asarray(sphere.triangles))
    assert np.array_equal(tout.triangle.indices.numpy(), tmesh.triangle.indices.numpy())
    V, F = np.asarray(sphere.vertices), np.asarray(sphere.triangles).astype(np.int32)
    arrays_out = ls_mesh((V, F), [0, 5, 40])
    assert arrays_out[1].dtype == np.int64 and np.array_equal(arrays_out[1], F)
    np.testing.assert_allclose(arrays_out[0], np.asarray(out.vertices), atol=1e-12)
    rec = reconstruct_geometry(sphere, [1, 2, 3])
    assert np.array_equal(np.asarray(sphere.vertices), before) and isinstance(rec, o3d.geometry.TriangleMesh)


def test_constraint_errors(sphere):
    n = len(sphere.vertices)
    with pytest.raises(ValueError, match=r"constraint_vertex_indices must lie in \[0, "):
        ls_mesh(sphere, [0, n])
    with pytest.raises(ValueError, match="constraint_vertex_indices must lie in"):
        ls_mesh(sphere, [-1, 3])
    with pytest.raises(TypeError, match="integer dtype"):
        ls_mesh(sphere, [0.0, 3.0])
    with pytest.raises(TypeError, match="integer vertex indices"):
        ls_mesh(sphere, ["a"])
    with pytest.raises(ValueError, match="must not repeat an index, got 3"):
        ls_mesh(sphere, [3, 1, 3])
    with pytest.raises(ValueError, match="at least one vertex index"):
        ls_mesh(sphere, [])
    with pytest.raises(ValueError, match=r"constraint_vertex_positions must have shape \(2, 3\)"):
        ls_mesh(sphere, [0, 1], np.zeros((3, 3)))
    with pytest.raises(ValueError, match="constraint_vertex_positions must be finite"):
        ls_mesh(sphere, [0, 1], [[0, 0, 0], [np.nan, 0, 0]])
    with pytest.raises(ValueError, match="weights must be positive and finite, got 0.0"):
        ls_mesh(sphere, [0, 1], weights=0.0)
    with pytest.raises(ValueError, match="weights must be positive and finite, got inf"):
        ls_mesh(sphere, [0, 1], weights=[1.0, np.inf])
    with pytest.raises(ValueError, match=r"weights must be a scalar or have shape \(2,\)"):
        ls_mesh(sphere, [0, 1], weights=[1.0, 2.0, 3.0])
    with pytest.raises(TypeError, match="interpolate must be a bool"):
        ls_mesh(sphere, [0, 1], interpolate="yes")
    with pytest.raises(ValueError, match="laplacian must be one of"):
        ls_mesh(sphere, [0, 1], laplacian="robust")
    with pytest.raises(ValueError, match=r"unknown_vertex_indices must lie in \[0, "):
        reconstruct_geometry(sphere, [n + 5])
    solver = LSMeshSolver(sphere, [0, 1])
    with pytest.raises(ValueError, match="already be control vertices, got 1"):
        solver.add_anchors([5, 1])
    with pytest.raises(ValueError, match=r"constraint_vertex_positions must have shape \(2, 3\)"):
        solver.solve(np.zeros((1, 3)))


def test_mesh_errors():
    with pytest.raises(ValueError, match="mesh must have vertices"):
        ls_mesh(o3d.geometry.TriangleMesh(), [0])
    V, F = grid(3, 3)
    with pytest.raises(ValueError, match="mesh must have triangles"):
        ls_mesh((V, np.zeros((0, 3), dtype=int)), [0])
    bad = V.copy()
    bad[2, 1] = np.inf
    with pytest.raises(ValueError, match="mesh vertices must be finite"):
        ls_mesh((bad, F), [0])
    with pytest.raises(ValueError, match=r"triangle indices must lie in \[0, 9\)"):
        ls_mesh((V, np.array([[0, 1, 9]])), [0])
    with pytest.raises(ValueError, match=r"triangle indices must lie in \[0, 9\)"):
        ls_mesh((V, np.array([[0, 1, -1]])), [0])
    with pytest.raises(ValueError, match="a triangle of three distinct vertices, got 2 triangles"):
        ls_mesh((V, np.array([[0, 1, 1], [0, 2, 2]])), [0])
    with pytest.raises(SingularSystemError, match="components"):
        # vertex 3 is unreferenced: a component of its own without a control vertex
        ls_mesh((V[:4], np.array([[0, 1, 2]])), [0])
    with pytest.raises(TypeError, match="triangles must be an"):
        ls_mesh((V, F.astype(float)), [0])
    with pytest.raises(ValueError, match=r"vertices must have shape \(n, 3\)"):
        ls_mesh((V[:, :2], F), [0])


def test_add_anchors_with_paper_weight_is_refined_to_fresh_accuracy():
    mesh = load_mesh("camel.ply")
    V, _ = arrays(mesh)
    n = len(V)
    omega = 10.0 * n  # the bases paper's weight: updates alone lose accuracy here
    order = np.random.default_rng(3).choice(n, 300, replace=False)
    solver = LSMeshSolver(mesh, order[:10], weights=omega)
    for chunk in np.array_split(order[10:], 29):
        solver.add_anchors(chunk, weights=omega)
    fresh = LSMeshSolver(mesh, order, weights=omega).solve()
    refined = solver.solve()
    assert np.linalg.norm(refined - fresh) <= 1e-8 * np.linalg.norm(fresh)
    unrefined = solver.solve(refine=False)
    if solver.backend == "cholmod":  # SciPy refactors instead of updating: nothing to refine there
        assert np.linalg.norm(unrefined - fresh) > np.linalg.norm(refined - fresh)


def test_constrained_unreferenced_vertex_keeps_its_position():
    V, F = grid(4, 4)
    V = np.concatenate([V, [[7.0, 8.0, 9.0]]])  # vertex 16 is in no triangle
    out, _ = ls_mesh((V, F), [0, 16], weights=2.0)
    np.testing.assert_allclose(out[16], V[16])
    full, _ = ls_mesh((V[:16], F), [0], weights=2.0)
    np.testing.assert_allclose(out[:16], full, atol=1e-12)

"""The iterative solver path of the gateway: PCG with smoothed-aggregation AMG, and ``solver="auto"``'s choice.

References are independent: CHOLMOD's (or SuperLU's) direct solution of the same system.
"""

import io
import pickle

import numpy as np
import open3d as o3d
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from conftest import grid, load_mesh

from o3d_lsmesh import SPDSolver, _block_kernel, constrained_fairing, ls_mesh, reconstruct_geometry
from o3d_lsmesh.core import _iterative, tuning
from o3d_lsmesh.core._iterative import IncompleteCholesky, VCycle
from o3d_lsmesh.core.errors import ConvergenceError, SingularSystemError
from o3d_lsmesh.core.solve import Plan, cholmod_available, default_memory_budget, estimate_factor_bytes
from o3d_lsmesh.core.tuning import DEFAULT_TOLERANCE, IC_WORK
from o3d_lsmesh.laplacian import laplacian_matrix
from o3d_lsmesh.lsmesh import LSMeshSolver

MATCH = 1e-6  # the documented agreement with the direct solution, relative


def reference(matrix, b):
    """SciPy's general sparse LU (not the gateway): the independent reference solution."""
    return spla.spsolve(sp.csc_matrix(matrix), b)


def relative(a, b):
    return np.linalg.norm(np.asarray(a) - np.asarray(b)) / np.linalg.norm(np.asarray(b))


def vertices(mesh):
    return np.asarray(mesh.vertices)


def two_components_with_boundaries():
    # two open grids side by side: several components, each with a boundary
    V1, F1 = grid(30, 25, z=lambda x, y: 0.1 * np.sin(3 * x) * np.cos(2 * y))
    V2, F2 = grid(20, 20)
    V2 = V2 + [2.0, 0.0, 0.5]
    return np.vstack([V1, V2]), np.vstack([F1, F2 + len(V1)])


def test_converges_on_several_components_with_boundaries():
    V, F = two_components_with_boundaries()
    controls = np.array([0, 300, 749, 760, 1000, 1149])
    # reference: numpy's dense solve of the LS mesh's normal equations (uniform Laplacian, unit weights)
    L = laplacian_matrix(V, F).toarray()
    P = np.eye(len(V))[controls]
    K, b = np.vstack([L, P]), np.vstack([np.zeros((len(V), 3)), V[controls]])
    direct = np.linalg.solve(K.T @ K, K.T @ b)
    system = LSMeshSolver((V, F), controls, solver="iterative")
    assert system.backend == "iterative"
    assert relative(system.solve(), direct) < MATCH
    assert system._solver.residual <= DEFAULT_TOLERANCE


def test_auto_picks_direct_below_the_budget_and_iterative_above():
    V, F = grid(40, 40)
    controls = np.arange(0, 1600, 37)
    assert LSMeshSolver((V, F), controls)._solver.backend in ("cholmod", "scipy")
    tiny = LSMeshSolver((V, F), controls, solver="auto")
    assert tiny.backend != "iterative"
    A = sp.random(2000, 2000, density=0.002, random_state=0)
    matrix = (A @ A.T + sp.identity(2000)).tocsc()
    assert SPDSolver(matrix, _plan=Plan(memory_budget=10**12)).backend in ("cholmod", "scipy")
    small_budget = SPDSolver(matrix, _plan=Plan(memory_budget=1000))
    assert small_budget.backend == "iterative"
    assert small_budget.estimated_factor_bytes > 1000
    b = np.random.default_rng(1).normal(size=(2000, 3))
    assert relative(small_budget.solve(b), reference(matrix, b)) < MATCH


def test_memory_budget_from_the_environment(monkeypatch):
    monkeypatch.setenv("O3D_LSMESH_MEMORY_BUDGET", "2K")
    assert default_memory_budget() == 2048
    V, F = grid(40, 40)
    assert LSMeshSolver((V, F), np.arange(0, 1600, 37)).backend == "iterative"
    monkeypatch.setenv("O3D_LSMESH_MEMORY_BUDGET", "lots")
    with pytest.raises(ValueError, match="O3D_LSMESH_MEMORY_BUDGET must be a number"):
        default_memory_budget()
    monkeypatch.delenv("O3D_LSMESH_MEMORY_BUDGET")
    assert default_memory_budget() > 0


def test_factor_model_grows_like_n_log_n():
    small, large = estimate_factor_bytes(10**5, 19 * 10**5), estimate_factor_bytes(10**6, 19 * 10**6)
    assert 10 < large / small < 10 * np.log2(10**6) / np.log2(10**5) + 1e-9


def test_warm_start_needs_fewer_iterations_and_tolerance_is_honoured():
    V, F = grid(60, 60, z=lambda x, y: np.sin(4 * x) * y)
    controls = np.arange(0, 3600, 53)
    system = LSMeshSolver((V, F), controls, solver="iterative")
    x = system.solve()
    cold = system._solver.iterations
    rhs = np.zeros((3600, 3))
    rhs[controls] = V[controls]
    again = system._solver.solve(rhs, x0=x)
    assert system._solver.iterations < cold / 3
    assert relative(again, x) < MATCH
    loose = LSMeshSolver((V, F), controls, solver="iterative", tol=1e-3)
    loose.solve()
    assert 1e-4 < loose._solver.residual <= 1e-3 or loose._solver.iterations < cold
    matrix = system._solver.matrix
    residual = np.linalg.norm(rhs - matrix @ x, axis=0) / np.linalg.norm(rhs, axis=0)
    assert residual.max() <= DEFAULT_TOLERANCE * 1.0001


@pytest.mark.parametrize("preconditioner", ["amg", "ic0"])
def test_a_reduction_stops_each_column_at_a_fraction_of_its_starting_residual(preconditioner):
    # ||b_j - A x_j|| <= max(tol ||b_j||, reduction ||b_j - A x0_j||), checked with the matrix itself; the
    # columns start at different distances from the solution, so each stops at its own residual
    V, F = grid(60, 60, z=lambda x, y: np.sin(4 * x) * y)
    controls = np.arange(0, 3600, 53)
    matrix = LSMeshSolver((V, F), controls, solver="iterative")._solver.matrix
    rhs = np.zeros((3600, 3))
    rhs[controls] = V[controls]
    exact = reference(matrix, rhs)
    x0 = exact + np.random.default_rng(0).normal(0, 1.0, exact.shape) * [1.0, 1e-3, 0.0]
    start = np.linalg.norm(rhs - matrix @ x0, axis=0)
    plain = SPDSolver(matrix, backend="iterative", _plan=Plan(preconditioner=preconditioner))
    plain.solve(rhs, x0=x0)
    solver = SPDSolver(matrix, backend="iterative", _plan=Plan(preconditioner=preconditioner, reduction=1e-3))
    x = solver.solve(rhs, x0=x0)
    residual = np.linalg.norm(rhs - matrix @ x, axis=0)
    limit = np.maximum(DEFAULT_TOLERANCE * np.linalg.norm(rhs, axis=0), 1e-3 * start)
    assert (residual <= limit * 1.0001).all()
    # column 0 stopped at its reduction, long before the tolerance; column 1, a thousand times closer at the
    # start, within its own (1000 times smaller) limit
    assert residual[0] > 1e3 * DEFAULT_TOLERANCE * np.linalg.norm(rhs[:, 0])
    assert solver.iterations < plain.iterations
    copy = pickle.loads(pickle.dumps(solver))
    assert (copy.reduction, copy.preconditioner) == (1e-3, preconditioner)
    np.testing.assert_array_equal(copy.solve(rhs, x0=x0), x)
    # direct backends solve exactly and ignore it
    direct = SPDSolver(matrix, backend="scipy", _plan=Plan(reduction=0.5))
    np.testing.assert_array_equal(direct.solve(rhs, x0=x0), SPDSolver(matrix, backend="scipy").solve(rhs))
    for bad in (0, 1, -0.1, 2.0, np.nan):
        with pytest.raises(ValueError, match=r"reduction must be None or a number in \(0, 1\)"):
            SPDSolver(matrix, backend="iterative", _plan=Plan(reduction=bad))
    with pytest.raises(TypeError, match=r"reduction must be None or a number in \(0, 1\), got 'loose'"):
        SPDSolver(matrix, backend="iterative", _plan=Plan(reduction="loose"))
    with pytest.raises(ValueError, match=r"preconditioner must be one of \['amg', 'ic0'\], got 'ilu'"):
        SPDSolver(matrix, backend="iterative", _plan=Plan(preconditioner="ilu"))


def test_incomplete_cholesky_preconditioner_solves_to_the_tolerance_and_survives_a_breakdown(monkeypatch):
    # Kershaw's matrix (SPD, not an M-matrix): IC(0) meets a negative pivot; the gateway shifts the
    # diagonal until it factors, and CG with it still solves the matrix itself (against a dense solve)
    kershaw = np.array([[3.0, -2, 0, 2], [-2, 3, -2, 0], [0, -2, 3, -2], [2, 0, -2, 3]])
    assert np.linalg.eigvalsh(kershaw)[0] > 0
    A = sp.csr_matrix(kershaw)
    values, _, failed = _block_kernel.incomplete_cholesky(A.indptr, A.indices, A.data, 0.0)
    assert values is None and failed >= 0
    rhs = np.arange(12.0).reshape(4, 3)
    solver = SPDSolver(A, backend="iterative", _plan=Plan(preconditioner="ic0"))
    np.testing.assert_allclose(solver.solve(rhs), np.linalg.solve(kershaw, rhs), rtol=0, atol=1e-8 * 33)
    assert solver._factor.shift > 0
    # a larger mesh system: the same solution as the factor, in fewer iterations than the AMG V-cycle
    # needs here (the normal matrix of an LS mesh with 2% controls is a Laplacian-like system)
    V, F = grid(40, 40, z=lambda x, y: np.sin(3 * x) * y)
    matrix = LSMeshSolver((V, F), np.arange(0, 1600, 7), solver="iterative")._solver.matrix
    rhs = np.random.default_rng(1).normal(size=(1600, 3))
    ic = SPDSolver(matrix, backend="iterative", _plan=Plan(preconditioner="ic0"))
    np.testing.assert_allclose(ic.solve(rhs), reference(matrix, rhs), rtol=0, atol=1e-6)
    assert ic._factor.shift == 0.0
    assert isinstance(ic._factor, IncompleteCholesky)
    # a UV sphere's poles: IC(0)'s set-up grows like the valence cubed; past IC_WORK (lowered here so that
    # a small sphere's poles cross it) the V-cycle runs
    sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=40)
    V, F = np.asarray(sphere.vertices), np.asarray(sphere.triangles)
    matrix = LSMeshSolver((V, F), np.arange(0, len(V), 7), solver="iterative")._solver.matrix
    lengths = np.diff(matrix.indptr).astype(float)
    monkeypatch.setattr(tuning, "IC_WORK", 0.5 * (lengths**2).sum() / 4 / matrix.nnz)
    assert (lengths**2).sum() / 4 > tuning.IC_WORK * matrix.nnz
    assert (lengths**2).sum() / 4 <= IC_WORK * matrix.nnz  # at the tuned value this sphere factors
    poles = SPDSolver(matrix, backend="iterative", _plan=Plan(preconditioner="ic0"))
    rhs = np.random.default_rng(2).normal(size=(len(V), 3))
    np.testing.assert_allclose(poles.solve(rhs), reference(matrix, rhs), rtol=0, atol=1e-6)
    assert isinstance(poles._factor, VCycle)
    with pytest.raises(
        SingularSystemError, match="matrix must be symmetric positive definite: .*row 1 has none"
    ):
        SPDSolver(
            sp.csr_matrix([[1.0, 0.0], [0.0, 0.0]]), backend="iterative", _plan=Plan(preconditioner="ic0")
        ).solve(np.ones(2))
    with pytest.raises(
        SingularSystemError, match="matrix must be positive definite: its incomplete Cholesky"
    ):
        SPDSolver(
            sp.csr_matrix([[1.0, 2.0], [2.0, -1.0]]), backend="iterative", _plan=Plan(preconditioner="ic0")
        ).solve(np.ones(2))


@pytest.mark.parametrize("offset", [1e4, 1e6])
def test_a_mesh_far_from_the_origin_is_solved_as_accurately_as_at_it(offset):
    # a scan in world coordinates: every solve is translation-equivariant, so the iterative result of
    # the moved mesh, moved back, must equal the iterative result at the origin (CG's residual criterion
    # must not lose the digits a far translation takes)
    V, F = grid(50, 40, z=lambda x, y: 0.2 * np.sin(3 * x) * np.cos(2 * y))
    V = V + np.random.default_rng(8).normal(0, 0.01, V.shape)
    bound = 1e-8 * np.ptp(V)
    far = V + offset

    def coordinates(result):  # array input gives (vertices, triangles) back
        return np.asarray(result[0])

    def moved_back(result):
        return coordinates(result) - offset

    direct = coordinates(constrained_fairing((V, F), method="global", solver="iterative"))
    iterative = moved_back(constrained_fairing((far, F), method="global", solver="iterative"))
    np.testing.assert_allclose(iterative, direct, atol=bound)
    # the scan energy's CG stops at a fraction of its starting residual (an accuracy of the displacement,
    # bounded in test_scan_denoise): far away it must reach what it reaches at the origin
    near = coordinates(constrained_fairing((V, F), method="scan", solver="iterative"))
    iterative = moved_back(constrained_fairing((far, F), method="scan", solver="iterative"))
    np.testing.assert_allclose(iterative, near, atol=bound)
    controls = np.arange(0, len(V), 17)
    for interpolate in (False, True):
        direct = coordinates(ls_mesh((V, F), controls, interpolate=interpolate, solver="iterative"))
        iterative = moved_back(ls_mesh((far, F), controls, interpolate=interpolate, solver="iterative"))
        np.testing.assert_allclose(iterative, direct, atol=bound, err_msg=f"interpolate={interpolate}")
    unknown = np.arange(0, len(V), 5)
    direct = coordinates(reconstruct_geometry((V, F), unknown, solver="iterative"))
    iterative = moved_back(reconstruct_geometry((far, F), unknown, solver="iterative"))
    np.testing.assert_allclose(iterative, direct, atol=bound)


def test_a_start_worse_than_zero_is_dropped_per_column():
    V, F = grid(40, 40, z=lambda x, y: np.sin(4 * x) * y)
    controls = np.arange(0, 1600, 37)
    system = LSMeshSolver((V, F), controls, solver="iterative")
    rhs = np.zeros((1600, 3))
    rhs[controls] = V[controls]
    cold = system._solver.solve(rhs)
    cold_iterations = system._solver.iterations
    far = np.full((1600, 3), 1e6)  # farther from the solution than zero, in every column
    from_far = system._solver.solve(rhs, x0=far)
    assert system._solver.iterations == cold_iterations
    np.testing.assert_array_equal(from_far, cold)
    # one column far, the others at the solution: only that one restarts from zero, the others stay
    mixed = cold.copy()
    mixed[:, 1] = 1e6
    np.testing.assert_array_equal(system._solver.solve(rhs, x0=mixed), cold)
    assert system._solver.iterations == cold_iterations


def test_progress_bar_shows_the_residual(monkeypatch):
    import tqdm.auto

    stream = io.StringIO()
    original = tqdm.auto.tqdm
    monkeypatch.setattr(
        tqdm.auto, "tqdm", lambda *a, **k: original(*a, **{**k, "file": stream, "mininterval": 0})
    )
    V, F = grid(30, 30)
    ls_mesh((V, F), np.arange(0, 900, 31), solver="iterative", progress=True)
    assert "conjugate gradients" in stream.getvalue() and "residual=" in stream.getvalue()


def test_update_refactor_pickle_and_errors():
    rng = np.random.default_rng(2)
    A = sp.random(800, 800, density=0.01, random_state=2)
    matrix = (A @ A.T + sp.identity(800)).tocsc()
    b = rng.normal(size=(800, 2))
    solver = SPDSolver(matrix, backend="iterative")
    C = sp.csc_matrix((np.array([3.0, 2.0]), (np.array([4, 17]), np.array([0, 1]))), shape=(800, 2))
    solver.update(C)
    updated = (matrix + C @ C.T).tocsc()
    assert relative(solver.solve(b), reference(updated, b)) < MATCH
    solver.refactor(matrix * 2.0)
    assert relative(solver.solve(b[:, 0]), reference(matrix * 2.0, b[:, 0])) < MATCH
    clone = pickle.loads(pickle.dumps(solver))
    assert clone.backend == "iterative" and relative(clone.solve(b), solver.solve(b)) < MATCH
    assert np.all(solver.solve(np.zeros((800, 2))) == 0)
    with pytest.raises(ConvergenceError, match="raise max_iterations"):
        SPDSolver(matrix, backend="iterative", max_iterations=1, tol=1e-14).solve(b)
    with pytest.raises(ValueError, match="x0 must have the shape"):
        solver.solve(b, x0=np.zeros(3))
    with pytest.raises(ValueError, match="tol must be a number in"):
        SPDSolver(matrix, tol=0)
    with pytest.raises(ValueError, match="max_iterations must be a positive"):
        SPDSolver(matrix, max_iterations=0)
    with pytest.raises(ValueError, match="memory_budget must be"):
        SPDSolver(matrix, _plan=Plan(memory_budget=-1))
    with pytest.raises(ValueError, match="solver must be one of"):
        ls_mesh(load_mesh("camel.ply"), [0], solver="magic")


def _cholmod():
    return cholmod_available()


def _scrambled_system(n_side=60, seed=0):
    # a grid's LS-mesh-like normal matrix (L^T L + controls) with its unknowns numbered at random
    from o3d_lsmesh.laplacian import laplacian_matrix

    V, F = grid(n_side, n_side)
    order = np.random.default_rng(seed).permutation(len(V))
    inverse = np.argsort(order)
    V, F = V[order], inverse[F]
    L = laplacian_matrix(V, F).tocsr()
    weights = np.zeros(len(V))
    weights[::37] = 1.0
    return (L.T @ L + sp.diags(weights)).tocsc(), V, weights


def test_scattered_numbering_is_renumbered_and_solutions_keep_the_callers_order(monkeypatch):
    N, V, weights = _scrambled_system()
    span = np.abs(N.indices - np.repeat(np.arange(N.shape[0]), np.diff(N.indptr))).mean()  # plain measure
    monkeypatch.setattr(tuning, "LOCAL_SPAN", int(span / 4))  # this small system counts as scattered
    b = weights[:, None] * V
    direct = reference(N, b)
    solver = SPDSolver(N, backend="iterative")
    x = solver.solve(b, x0=V)
    assert solver._order is not None and sorted(solver._order) == list(range(N.shape[0]))
    stored = solver._matrix
    stored_span = np.abs(stored.indices - np.repeat(np.arange(N.shape[0]), np.diff(stored.indptr))).mean()
    assert stored_span < span / 4  # reverse Cuthill-McKee brought the entries close
    assert relative(x, direct) < MATCH
    # the caller sees the matrix in its own numbering; updates and pickles keep working
    assert abs(solver.matrix - N).max() == 0
    c = sp.csc_matrix((np.full(3, 2.0), ([5, 900, 2000], [0, 1, 2])), shape=(N.shape[0], 3))
    updated = (N + c @ c.T).tocsc()
    solver.update(c)
    assert relative(solver.solve(b), reference(updated, b)) < MATCH
    clone = pickle.loads(pickle.dumps(solver))
    assert abs(clone.matrix - updated).max() < 1e-15
    assert relative(clone.solve(b), solver.solve(b)) < MATCH
    solver.refactor(N)  # a new matrix in the caller's numbering: renumbered afresh at the next solve
    assert solver._order is None
    assert relative(solver.solve(b), direct) < MATCH


def test_locality_of_orders_by_the_sparser_graph_before_the_product(monkeypatch):
    N, V, weights = _scrambled_system()
    span = np.abs(N.indices - np.repeat(np.arange(N.shape[0]), np.diff(N.indptr))).mean()
    monkeypatch.setattr(tuning, "LOCAL_SPAN", int(span / 4))
    from o3d_lsmesh import _block_kernel
    from o3d_lsmesh.laplacian import laplacian_matrix

    _, F = grid(60, 60)
    inverse = np.argsort(np.random.default_rng(0).permutation(len(V)))  # _scrambled_system's numbering
    L = laplacian_matrix(V, inverse[F]).tocsr()
    A = sp.hstack([L.T, sp.diags(np.sqrt(weights))], format="csc")  # N = A A^T
    b = weights[:, None] * V
    direct = reference(N, b)
    solver = SPDSolver(backend="iterative", _plan=Plan(product_of=A, locality_of=L))
    # ordered at construction by the 1-ring's reverse Cuthill-McKee, the product formed renumbered
    assert solver._order is not None
    assert solver._order.tolist() == _block_kernel.level_order(L.indptr, L.indices).tolist()
    assert abs(solver.matrix - N).max() < 1e-12 * abs(N).max()
    assert relative(solver.solve(b), direct) < MATCH
    with pytest.raises(ValueError, match=r"locality_of must have shape \(3600, 3600\), got \(3, 3\)"):
        SPDSolver(N, backend="iterative", _plan=Plan(locality_of=sp.identity(3, format="csr")))
    with pytest.raises(TypeError, match="locality_of must be a scipy sparse matrix, got ndarray"):
        SPDSolver(N, backend="iterative", _plan=Plan(locality_of=np.eye(3)))


def test_local_numbering_is_kept():
    N, V, weights = _scrambled_system()
    ordered = SPDSolver(sp.csc_matrix(sp.diags(np.arange(1.0, 4001.0))), backend="iterative")
    ordered.solve(np.ones(4000))
    assert ordered._order is None  # a diagonal reaches nowhere
    scrambled = SPDSolver(N, backend="iterative")
    scrambled.solve(weights[:, None] * V)
    assert scrambled._order is None  # 3600 unknowns cannot reach farther than LOCAL_SPAN


def test_gram_matrix_takes_64_bit_indices_where_32_might_not_hold_the_product(monkeypatch):
    from o3d_lsmesh import _block_kernel

    A = sp.random(30, 40, density=0.2, random_state=1, format="csc")
    seen = []
    gram = _block_kernel.gram
    monkeypatch.setattr(_block_kernel, "gram", lambda *parts: seen.append(parts[0].dtype) or gram(*parts))
    small = _iterative.gram_matrix(A)
    assert seen[-1] == np.int32 and abs(small - A @ A.T).max() < 1e-14
    monkeypatch.setattr(_iterative, "INT32_ENTRIES", 10)  # as if 32 bits held ten entries
    wide = _iterative.gram_matrix(A)
    assert seen[-1] == np.int64 and abs(wide - A @ A.T).max() < 1e-14


@pytest.mark.parametrize("seed", range(3))
def test_gram_matrix_from_given_rows_is_the_dense_product(seed):
    # the caller's CSR form of A (scan_normal_matrix's mirrored K) stands for A's transpose pass
    A = sp.random(50, 35, density=0.15, random_state=seed, format="csc")
    product = _iterative.gram_matrix(A, rows=A.tocsr())
    np.testing.assert_allclose(product.toarray(), (A @ A.T).toarray(), rtol=1e-13, atol=1e-14)
    assert product.has_sorted_indices and (product != product.T).nnz == 0

import pickle
import sys
import threading

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from conftest import PACKAGE_HOME
from hypothesis import given, settings
from hypothesis import strategies as st

from o3d_lsmesh import SingularSystemError, SPDSolver
from o3d_lsmesh.core import _direct, tuning
from o3d_lsmesh.core import solve as solvers
from o3d_lsmesh.core.solve import Plan, cholmod_available


def spd(n=60, seed=0):
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=0.05, random_state=seed) + sp.identity(n)
    return (A.T @ A + sp.identity(n)).tocsc(), rng.normal(size=(n, 3))


BACKENDS = ["scipy"] + (["cholmod"] if cholmod_available() else [])


@pytest.mark.parametrize("backend", BACKENDS)
def test_batched_solve_equals_columnwise_spsolve(backend):
    A, b = spd()
    solver = SPDSolver(A, backend=backend)
    assert solver.backend == backend
    x = solver.solve(b)
    for k in range(3):
        np.testing.assert_allclose(x[:, k], spla.spsolve(A, b[:, k]), rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**16),
    blocks=st.lists(st.tuples(st.integers(1, 4), st.integers(1, 3)), min_size=1, max_size=5),
    scale=st.sampled_from([1.0, 1e4]),
)
def test_updates_equal_a_dense_solve(backend, seed, blocks, scale):
    # blocks of columns with one to three entries (rows may repeat across columns), solves between
    # them: the SciPy path's Woodbury correction against numpy's dense solve of the updated matrix;
    # large entries (an anchor's w = 10 n) one per column, as LSMeshSystem.add_anchors makes them
    A, _ = spd(40, seed % 7)
    rng = np.random.default_rng(seed)
    solver, dense = SPDSolver(A, backend=backend), A.toarray()
    for columns, entries in blocks:
        entries = 1 if scale > 1 else entries
        rows = rng.integers(0, 40, size=(entries, columns)).ravel()
        values = scale * rng.uniform(0.5, 2.0, size=entries * columns)
        C = sp.csc_matrix((values, (rows, np.tile(np.arange(columns), entries))), shape=(40, columns))
        solver.update(C)
        dense += (C @ C.T).toarray()
        b = rng.normal(size=(40, 2)) + dense @ rng.normal(size=(40, 2))  # large entries where C is
        x = solver.solve(b)
        # backward error (a stable solver's): the residual against the matrix's and the solution's size
        scale_ = np.abs(dense).sum(axis=1).max() * np.abs(x).max() + np.abs(b).max()
        assert np.abs(b - dense @ x).max() <= 1e-13 * scale_
        # forward error within what the conditioning allows
        expected = np.linalg.solve(dense, b)
        tolerance = 1e-14 * np.linalg.cond(dense) * np.abs(expected).max()
        np.testing.assert_allclose(x, expected, rtol=0, atol=tolerance)
        np.testing.assert_allclose(solver.solve(b[:, 0]), x[:, 0], rtol=0, atol=tolerance)


def test_scipy_updates_keep_the_lu_until_the_correction_costs_a_factorization():
    A, b = spd()
    solver, ranks, lus = SPDSolver(A, backend="scipy"), [], []
    for row in range(0, 60, 6):
        solver.update(sp.csc_matrix(([2.0], ([row], [0])), shape=(60, 1)))
        np.testing.assert_allclose(solver.solve(b), spla.spsolve(solver.matrix, b), rtol=1e-10)
        ranks.append(solver._factor._rank)
        lus.append(solver._factor._lu)
    refactors = sum(a is not b for a, b in zip(lus, lus[1:]))
    assert max(ranks) > 1 and 0 < refactors < len(ranks) - 1, (ranks, refactors)
    assert all(r == 0 or r == p + 1 for p, r in zip(ranks, ranks[1:]))  # grows by one, or a fresh LU


def test_scipy_solves_recycle_the_span_of_earlier_right_hand_sides():
    A, b = spd()

    class Counting:  # SuperLU's solve, counting the columns it is given
        def __init__(self, lu):
            self.lu, self.columns = lu, 0

        def solve(self, rhs):
            self.columns += rhs.shape[1]
            return self.lu.solve(rhs)

    solver = SPDSolver(A, backend="scipy")
    lu = solver._factor._lu = Counting(solver._factor._lu)
    solver.solve(b)
    assert lu.columns == 3
    within = b @ np.array([[2.0, -1.0], [0.5, 0.0], [0.0, 3.0]])  # in the span: no solve
    np.testing.assert_allclose(solver.solve(within), spla.spsolve(A, within), rtol=1e-10)
    assert lu.columns == 3
    beside = b[:, :2] + 1e-3 * np.random.default_rng(1).normal(size=(60, 2))  # a new direction: solved
    np.testing.assert_allclose(solver.solve(beside), spla.spsolve(A, beside), rtol=1e-10)
    assert lu.columns == 5
    np.testing.assert_allclose(solver.solve(beside[:, 0]), spla.spsolve(A, beside[:, 0]), rtol=1e-10)
    assert lu.columns == 5


def test_scipy_update_refactors_when_the_correction_fails(monkeypatch):

    A, b = spd()
    C = sp.csc_matrix((np.array([3.0]), (np.array([4]), np.array([0]))), shape=(A.shape[0], 1))
    solver = SPDSolver(A, backend="scipy")
    solver.update(C)

    def fail(self, new, z):
        raise np.linalg.LinAlgError("not positive definite")

    monkeypatch.setattr(_direct.Woodbury, "_extend", fail)
    np.testing.assert_allclose(solver.solve(b), spla.spsolve(A + C @ C.T, b), rtol=1e-10)
    assert solver._factor._rank == 0  # a fresh factor of A + C C^T, no correction


@pytest.mark.parametrize("backend", BACKENDS)
def test_refactor_same_pattern(backend):
    A, b = spd()
    solver = SPDSolver(A, backend=backend)
    solver.refactor(A * 2.0)
    np.testing.assert_allclose(solver.solve(b), spla.spsolve(A * 2.0, b), rtol=1e-10)
    with pytest.raises(ValueError, match="matrix must have shape"):
        solver.refactor(sp.identity(3, format="csc"))


def test_pickle_and_threads():
    A, b = spd()
    solver = SPDSolver(A)
    solver.update(sp.csc_matrix((np.array([1.0]), (np.array([3]), np.array([0]))), shape=(A.shape[0], 1)))
    clone = pickle.loads(pickle.dumps(solver))
    np.testing.assert_allclose(clone.solve(b), solver.solve(b), rtol=1e-12)
    results = [None] * 8

    def work(i):
        results[i] = solver.solve(b * (i + 1))

    threads = [threading.Thread(target=work, args=(i,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for i, x in enumerate(results):
        np.testing.assert_allclose(x, solver.solve(b) * (i + 1), rtol=1e-10)


@pytest.mark.parametrize("backend", BACKENDS)
def test_singular_matrix_raises(backend):
    singular = sp.csc_matrix(np.array([[1.0, -1.0], [-1.0, 1.0]]))
    with pytest.raises(SingularSystemError):
        SPDSolver(singular, backend=backend).solve(np.ones(2))
    # a path's Laplacian (free ends): the iterative backend's direct coarse solve said RuntimeError
    path = sp.diags([-np.ones(49), 2 * np.ones(50), -np.ones(49)], [-1, 0, 1]).tolil()
    path[0, 0] = path[-1, -1] = 1.0
    with pytest.raises(SingularSystemError):
        SPDSolver(path.tocsc(), backend=backend).solve(np.ones(50))


@pytest.mark.parametrize("backend", ["scipy", "iterative"])
def test_a_complex_or_empty_right_hand_side(backend):
    A, _ = spd(5)
    with pytest.raises(TypeError, match="rhs must be an array of real numbers, got dtype complex128"):
        SPDSolver(A, backend=backend).solve(np.full(5, 1j))  # (it was cast to its real part, 0)
    assert SPDSolver(A, backend=backend).solve(np.ones((5, 0))).shape == (5, 0)


def test_bad_arguments():
    A, _ = spd(5)
    with pytest.raises(TypeError, match="matrix must be a scipy sparse matrix"):
        SPDSolver(np.eye(3))
    with pytest.raises(ValueError, match="matrix must be square"):
        SPDSolver(sp.csc_matrix(np.ones((2, 3))))
    with pytest.raises(ValueError, match="backend must be one of"):
        SPDSolver(A, backend="magma")
    with pytest.raises(ValueError, match="rhs must have shape"):
        SPDSolver(A).solve(np.ones(4))
    with pytest.raises(ValueError, match="C must have 5 rows"):
        SPDSolver(A).update(sp.csc_matrix(np.ones((4, 1))))


def test_fallback_warns_without_scikit_sparse(monkeypatch):
    from o3d_lsmesh import O3DLSMeshWarning

    monkeypatch.setattr(solvers, "_cholmod", None)
    monkeypatch.setattr(solvers, "_fallback_warned", False)  # as in a fresh process
    monkeypatch.delenv(solvers.NO_CHOLMOD_ENV, raising=False)
    A, _b = spd()
    with pytest.warns(O3DLSMeshWarning, match="scikit-sparse is not importable"):
        solver = solvers.SPDSolver(A)
    assert solver.backend == "scipy"
    with pytest.raises(ImportError, match="needs scikit-sparse"):
        solvers.SPDSolver(A, backend="cholmod")


def test_bad_ordering():
    A, _ = spd(5)
    with pytest.raises(ValueError, match="ordering must be one of"):
        SPDSolver(A, ordering="random")


@pytest.mark.parametrize("backend", BACKENDS)
def test_lower_triangle_input_equals_whole_matrix(backend):
    A, b = spd()
    solver = SPDSolver(sp.tril(A, format="csc"), backend=backend, lower=True)
    np.testing.assert_allclose(solver.solve(b), spla.spsolve(A, b), rtol=1e-10)
    assert abs(solver.matrix - A).max() < 1e-14
    solver.refactor(sp.tril(A * 3.0), lower=True)
    np.testing.assert_allclose(solver.solve(b), spla.spsolve(A * 3.0, b), rtol=1e-10)
    clone = pickle.loads(pickle.dumps(solver))
    np.testing.assert_allclose(clone.solve(b), solver.solve(b), rtol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_product_mode_factors_a_at_without_forming_it(backend):
    # an LS problem's transposed rows: A (n, k) with k > n, int64 indices, non-canonical order
    rng = np.random.default_rng(3)
    n, k = 40, 90
    A = (
        sp.random(n, k, density=0.08, random_state=3) + sp.hstack([sp.identity(n), sp.csc_matrix((n, k - n))])
    ).tocoo()
    A = sp.csc_matrix((A.data[::-1], (A.row[::-1], A.col[::-1])), shape=(n, k))
    b = rng.normal(size=(n, 3))
    normal = (A @ A.T).tocsc()
    solver = SPDSolver(backend=backend, _plan=Plan(product_of=A))
    np.testing.assert_allclose(solver.solve(b), spla.spsolve(normal, b), rtol=1e-9, atol=1e-12)
    assert solver.shape == (n, n) and abs(solver.matrix - normal).max() < 1e-12
    C = sp.csc_matrix((np.array([2.0, 0.5]), (np.array([1, 30]), np.array([0, 1]))), shape=(n, 2))
    solver.update(C)
    updated = normal + C @ C.T
    np.testing.assert_allclose(solver.solve(b), spla.spsolve(updated.tocsc(), b), rtol=1e-9, atol=1e-12)
    clone = pickle.loads(pickle.dumps(solver))  # pickles as [A C], refactors on load
    np.testing.assert_allclose(clone.solve(b), solver.solve(b), rtol=1e-10)
    assert abs(clone.matrix - updated).max() < 1e-12
    with pytest.raises(TypeError, match="refactor takes a matrix"):
        solver.refactor(updated)


def test_product_mode_raises():
    A, _ = spd()
    with pytest.raises(TypeError, match="exactly one of matrix and product_of"):
        SPDSolver(A, _plan=Plan(product_of=A))
    with pytest.raises(TypeError, match="exactly one of matrix and product_of"):
        SPDSolver()
    with pytest.raises(TypeError, match="product_of must be a scipy sparse matrix, got ndarray"):
        SPDSolver(_plan=Plan(product_of=np.eye(3)))
    with pytest.raises(SingularSystemError):
        SPDSolver(_plan=Plan(product_of=sp.csc_matrix(np.array([[1.0, 0.0], [0.0, 0.0]])))).solve(np.ones(2))


# --- issue 12, classes 1 and 4: negligible or overflowing penalties raise, naming the parameter


def _translated_sphere():
    import open3d as o3d

    sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=12)
    moved = o3d.geometry.TriangleMesh(sphere)
    moved.translate((5.0, 5.0, 5.0))
    return sphere, moved


@pytest.mark.parametrize("weights", [1e-8, 1e-300, [1e-9, 1e-8, 1e-8]])
def test_negligible_ls_mesh_weights_raise_naming_weights(weights):
    from o3d_lsmesh import ls_mesh

    _, moved = _translated_sphere()
    with pytest.raises(ValueError, match="weights is too small.*increase weights"):
        ls_mesh(moved, [0, 5, 40], weights=weights)


def test_small_but_sufficient_weights_are_exact_up_to_translation():
    # L 1 = 0, so the LS mesh of a translated mesh is the translated LS mesh: an independent reference
    from o3d_lsmesh import ls_mesh

    sphere, moved = _translated_sphere()
    for weights in (1e-3, 1.0, 1e3):
        here = np.asarray(ls_mesh(sphere, [0, 5, 40], weights=weights).vertices)
        there = np.asarray(ls_mesh(moved, [0, 5, 40], weights=weights).vertices)
        np.testing.assert_allclose(there, here + 5.0, atol=1e-6)


def test_overflowing_weights_raise_naming_weights():
    from o3d_lsmesh import ls_mesh
    from o3d_lsmesh.lsmesh import LSMeshSolver

    _, moved = _translated_sphere()
    with pytest.raises(ValueError, match=r"weights must be small enough that weights\*\*2 is finite"):
        ls_mesh(moved, [0, 5, 40], weights=1e200)
    solver = LSMeshSolver(moved, [0, 5, 40], weights=1e150)
    # positions beyond the adapter's coordinate limit are refused by name before any product is formed
    with pytest.raises(
        ValueError, match="constraint_vertex_positions must have coordinates of magnitude at most"
    ):
        solver.solve(np.full((3, 3), 1e300))
    # within the limit, the weighted right-hand side (weights**2 * positions, about the controls'
    # centroid) overflows: named too
    with pytest.raises(ValueError, match="constraint_vertex_positions must be small enough"):
        solver.solve(1e29 * np.eye(3))
    # controls all at one point are that point's translation: the LS mesh is the point itself (L 1 = 0),
    # whatever the weights, with nothing to overflow
    np.testing.assert_array_equal(
        solver.solve(np.full((3, 3), 1e29)), np.full((len(moved.vertices), 3), 1e29)
    )


def test_encoding_weight_checked():
    from o3d_lsmesh.lsmesh.encoding import decode_geometry, encode_geometry

    _, moved = _translated_sphere()
    with pytest.raises(ValueError, match="weight is too small"):
        encode_geometry(moved, 20, weight=1e-300)
    with pytest.raises(ValueError, match=r"weight must be small enough that weight\*\*2"):
        encode_geometry(moved, 20, weight=1e200)
    decoded = np.asarray(decode_geometry(moved, encode_geometry(moved, 20, weight=1.0)).vertices)
    assert abs(decoded.mean(axis=0) - 5.0).max() < 0.1


def test_global_fairing_mu_checked():
    from o3d_lsmesh import constrained_fairing

    _, moved = _translated_sphere()
    for mu in (1e-300, 1e-12):
        with pytest.raises(ValueError, match="mu is too small"):
            constrained_fairing(moved, 2, method="global", mu=mu)
    with pytest.raises(ValueError, match=r"mu must be small enough that mu \* H\^T H is finite"):
        constrained_fairing(moved, 2, method="global", mu=1e308)
    # mu that pins the sphere keeps it where it is (the barycenters hold the centre)
    out = np.asarray(constrained_fairing(moved, 2, method="global", mu=1e-3).vertices)
    np.testing.assert_allclose(out.mean(axis=0), 5.0, atol=1e-6)
    # a mesh with a boundary is pinned by its boundary: tiny mu is well posed there
    from conftest import grid

    V, F = grid(8, 8, z=lambda x, y: x * y)
    V, _ = constrained_fairing((V, F), 1, method="global", mu=1e-300)
    assert np.isfinite(V).all()
    # a closed component beside an open one in the same mesh: only the closed one is loose, and it is
    # found as a component of its own (averaged with the pinned grid it would pass)
    sphere_v, sphere_f = (np.asarray(a) for a in (moved.vertices, moved.triangles))
    both_v, both_f = np.vstack([V, sphere_v]), np.vstack([F, sphere_f + len(V)])
    with pytest.raises(ValueError, match=rf"mu is too small.*\(the first with vertex {len(V)}\)"):
        constrained_fairing((both_v, both_f), 1, method="global", mu=1e-12)


def test_non_finite_inputs_to_the_gateway_raise():
    A, _b = spd(10)
    with pytest.raises(ValueError, match="rhs must be finite, got nan at row 1"):
        SPDSolver(A).solve(np.r_[1.0, np.nan, np.zeros(8)])
    bad = A.copy()
    bad.data[0] = np.inf
    with pytest.raises(ValueError, match="matrix must have finite entries"):
        SPDSolver(bad)
    with pytest.raises(ValueError, match="C must have finite entries"):
        SPDSolver(A).update(
            sp.csc_matrix((np.array([np.inf]), (np.array([0]), np.array([0]))), shape=(10, 1))
        )


def test_check_constant_modes_against_the_smallest_eigenvalue():
    # the quotient bounds the smallest eigenvalue from above: a system it rejects is truly near-singular
    from conftest import grid

    from o3d_lsmesh.core.solve import check_constant_modes, operator_scale
    from o3d_lsmesh.core.tuning import NEGLIGIBLE
    from o3d_lsmesh.laplacian import laplacian_matrix

    V, F = grid(6, 6)
    L = laplacian_matrix(V, F).tocsr()
    labels = np.zeros(len(V), dtype=np.int64)
    for w2 in (1e-20, 1e-2):
        N = (L.T @ L + sp.diags(np.r_[w2, np.zeros(len(V) - 1)])).toarray()
        smallest = np.linalg.eigvalsh(N)[0]
        quotient = w2 / len(V)
        assert smallest <= quotient * (1 + 1e-6) + 1e-15
        if quotient < NEGLIGIBLE * operator_scale(L):
            with pytest.raises(ValueError, match="w is too small"):
                check_constant_modes(N @ np.ones(len(V)), labels, scale=operator_scale(L), name="w", value=w2)
        else:
            check_constant_modes(N @ np.ones(len(V)), labels, scale=operator_scale(L), name="w", value=w2)
    assert operator_scale(L) == pytest.approx(np.max(np.diag((L.T @ L).toarray())))


# peak memory over the input mesh, bytes per vertex, at 200k vertices: twice the README's
# "Memory and scale" figures (benchmarks/results/scale_memory.md), which leaves room for allocator
# and library-version noise but not for an extra (n, n) matrix or a dense (m, 3, 3) array
MEMORY_BOUNDS = {
    "constrained_fairing(mesh, 10, method='local')": 880,  # README: 440
    "ls_mesh(mesh, controls)": 6000,
    "laplacian(mesh)": 1000,
}

_MEMORY_SCRIPT = """
import sys, numpy as np
from o3d_lsmesh import constrained_fairing, laplacian, ls_mesh

def torus(a, b):
    # a closed a x b grid torus: every vertex of valence 6, all sizes of scan order
    u, v = np.meshgrid(np.arange(a), np.arange(b), indexing="ij")
    s, t = 2 * np.pi * u.ravel() / a, 2 * np.pi * v.ravel() / b
    V = np.stack([(3 + np.cos(t)) * np.cos(s), (3 + np.cos(t)) * np.sin(s), np.sin(t)], axis=1)
    V += np.random.default_rng(0).normal(scale=1e-3, size=V.shape)
    i = (u * b + v).ravel(); r = (((u + 1) % a) * b + v).ravel(); d = (u * b + (v + 1) % b).ravel()
    rd = (((u + 1) % a) * b + (v + 1) % b).ravel()
    F = np.concatenate([np.stack([i, r, rd], 1), np.stack([i, rd, d], 1)]).astype(np.int64)
    return V, F

def high_water_kb():
    # VmHWM, not ru_maxrss: Linux keeps ru_maxrss across exec, so a child of a large pytest process
    # would start at the parent's peak
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1])

V, F = torus(450, 450)
mesh = (V, F)
controls = np.arange(0, len(V), 50)
base = high_water_kb()
out = eval(sys.argv[1])
print((high_water_kb() - base) * 1024 / len(V))
"""


@pytest.mark.parametrize("statement", sorted(MEMORY_BOUNDS))
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads VmHWM from /proc/self/status")
def test_peak_memory_per_vertex_at_200k(statement):
    # a subprocess, so that the peak (its VmHWM) is this operation's alone
    import os
    import subprocess

    home = PACKAGE_HOME  # the package this suite imports, with its compiled kernels
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([home, os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run(
        [sys.executable, "-c", _MEMORY_SCRIPT, statement],
        capture_output=True,
        text=True,
        env=env,
        cwd=home,  # `python -c` puts its working directory first on the path
        timeout=900,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    per_vertex = float(proc.stdout.strip().splitlines()[-1])
    assert 0 < per_vertex <= MEMORY_BOUNDS[statement], (statement, per_vertex)


@pytest.mark.parametrize("n", [5, 120, 121, 300])
def test_solve_spd_dense_and_sparse_paths_equal_spsolve(n, monkeypatch):
    # one-off systems: a dense Cholesky up to DENSE_UNKNOWNS unknowns, SPDSolver beyond; both paths on
    # both kinds of input against SciPy's spsolve, and each path forced on the other's sizes

    A, b = spd(n, seed=n)
    expected = spla.spsolve(A.tocsc(), b)
    for limit in (tuning.DENSE_UNKNOWNS, -1, 10**6):
        monkeypatch.setattr(tuning, "DENSE_UNKNOWNS", limit)
        for matrix in (A, A.toarray()):
            np.testing.assert_allclose(solvers.solve_spd(matrix, b), expected, rtol=1e-9, atol=1e-12)


def test_solve_spd_dense_path_raises_on_an_indefinite_matrix():
    from o3d_lsmesh.core.solve import solve_spd

    with pytest.raises(SingularSystemError, match="not positive definite"):
        solve_spd(-np.identity(4), np.ones(4))


@pytest.mark.parametrize("backend", [*BACKENDS, "iterative"])
def test_spd_solver_refuses_what_is_not_a_real_symmetric_matrix(backend):
    # CHOLMOD reads one triangle: an unsymmetric matrix gave the solution of another matrix without a word
    unsymmetric = sp.csc_matrix(np.array([[4.0, 1.0, 0.0], [0.5, 3.0, 0.0], [0.0, 0.0, 2.0]]))
    with pytest.raises(
        ValueError, match=r"matrix must be symmetric, got a\[0, 1\] = 1 against a\[1, 0\] = 0.5"
    ):
        SPDSolver(unsymmetric, backend=backend)
    other_pattern = sp.csc_matrix(np.array([[4.0, 1.0], [0.0, 3.0]]))
    with pytest.raises(
        ValueError, match=r"matrix must be symmetric, got a\[0, 1\] = 1 against a\[1, 0\] = 0"
    ):
        SPDSolver(other_pattern, backend=backend)
    with pytest.raises(ValueError, match="matrix must be symmetric"):
        SPDSolver(sp.identity(3, format="csc"), backend=backend).refactor(unsymmetric)
    # round-off asymmetry of an assembled product passes, and so does a lower triangle with lower=True
    A, b = spd(6)
    nearly = sp.csc_matrix(A.toarray() * (1.0 + 1e-14 * np.triu(np.ones(A.shape), 1)))
    np.testing.assert_allclose(SPDSolver(nearly, backend=backend).solve(b), SPDSolver(A).solve(b), rtol=1e-8)
    with pytest.raises(
        ValueError, match=r"matrix must hold only its lower triangle with lower=True, got \d+ entries above"
    ):
        SPDSolver(A, backend=backend, lower=True)
    with pytest.raises(TypeError, match="matrix must have real entries, got complex128"):
        SPDSolver(sp.csc_matrix(np.array([[4.0, 1j], [-1j, 3.0]])), backend=backend)
    with pytest.raises(TypeError, match="rhs must be an array of real numbers, got list"):
        SPDSolver(A, backend=backend).solve(["a"] * A.shape[0])
    with pytest.raises(TypeError, match="C must be a sparse matrix or an array of real numbers, got str"):
        SPDSolver(A, backend=backend).update("x")


@pytest.mark.parametrize("weight", [1.0, 1e2, 1e4, 1e6])
def test_iterative_stop_is_not_met_by_heavy_rows_alone(weight):
    # an LS mesh's system: L^T L + w^2 C^T C, started where the controls already are. Its heavy rows make
    # ||b|| large and hold a residual of 0 there, so a plain ||r|| <= tol ||b|| stopped at the start (the
    # mesh's own positions returned); the residual is weighed by the diagonal, as a step of each unknown
    rng = np.random.default_rng(5)
    path = sp.diags([-np.ones(19), 2 * np.ones(20), -np.ones(19)], [-1, 0, 1]).tolil()
    path[0, 0] = path[-1, -1] = 1.0  # a path's Laplacian (free ends); a 20 x 20 grid's below
    grid = sp.kron(path, sp.eye(20)) + sp.kron(sp.eye(20), path)
    heavy = np.zeros(400)
    heavy[[0, 137, 250, 399]] = weight**2
    matrix = (grid.T @ grid + sp.diags(heavy)).tocsc()
    start = rng.normal(size=(400, 3))
    rhs = heavy[:, None] * start  # the controls' targets: where the start already holds them
    want = spla.spsolve(matrix, rhs)
    solver = SPDSolver(matrix, backend="iterative")
    got = solver.solve(rhs, x0=start)
    np.testing.assert_allclose(got, want, atol=1e-6 * np.abs(want).max())


def test_a_solver_contradicting_the_backend_is_refused():
    # ls_mesh's solver='iterative' beside backend='cholmod' ran conjugate gradients without a word
    from conftest import grid

    from o3d_lsmesh import LSMeshSolver
    from o3d_lsmesh.core._direct import solver_backend

    V, F = grid(4, 4)
    with pytest.raises(ValueError, match="solver='iterative' contradicts backend='cholmod'") as info:
        LSMeshSolver((V, F), [0, 5], backend="cholmod", solver="iterative")
    assert info.value.param == "solver"
    with pytest.raises(ValueError, match="solver='cholmod' contradicts backend='iterative'"):
        solver_backend("cholmod", "iterative")
    # agreeing, or one of them "auto": the one asked for
    assert [
        solver_backend(*pair) for pair in [("iterative", "iterative"), ("auto", "scipy"), ("cholmod", "auto")]
    ] == [
        "iterative",
        "scipy",
        "cholmod",
    ]


@pytest.mark.parametrize("solver", ["cholmod", "iterative"])
def test_scan_fairing_mu_checked(solver):
    # only mu H^T W H holds a component of the scan energy in place: mu=1e-20 failed at a CHOLMOD pivot
    # naming nothing, or collapsed the mesh to a point under CG
    from o3d_lsmesh import constrained_fairing
    from o3d_lsmesh.core.solve import cholmod_available

    if solver == "cholmod" and not cholmod_available():
        pytest.skip("scikit-sparse (CHOLMOD) is not installed")
    _, moved = _translated_sphere()
    with pytest.raises(ValueError, match=r"mu is too small: mu H\^T W H must pin every connected component"):
        constrained_fairing(moved, method="scan", mu=1e-20, solver=solver)
    out = np.asarray(constrained_fairing(moved, method="scan", mu=1e-3, solver=solver).vertices)
    np.testing.assert_allclose(out.mean(axis=0), 5.0, atol=1e-3)  # pinned: it stays where it was

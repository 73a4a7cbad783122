import pickle
import threading

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from o3d_lsmesh import SingularSystemError, SPDSolver
from o3d_lsmesh._solvers import cholmod_available


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
def test_update_equals_fresh_factor(backend):
    A, b = spd()
    C = sp.csc_matrix((np.array([3.0, 2.0]), (np.array([4, 17]), np.array([0, 1]))), shape=(A.shape[0], 2))
    solver = SPDSolver(A, backend=backend)
    solver.update(C)
    fresh = SPDSolver(A + C @ C.T, backend=backend)
    np.testing.assert_allclose(solver.solve(b), fresh.solve(b), rtol=1e-10)
    assert abs(solver.matrix - (A + C @ C.T)).max() < 1e-12


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
    import o3d_lsmesh._solvers as solvers
    from o3d_lsmesh import O3DLSMeshWarning

    monkeypatch.setattr(solvers, "_cholmod", None)
    A, b = spd()
    with pytest.warns(O3DLSMeshWarning, match="scikit-sparse is not importable"):
        solver = solvers.SPDSolver(A)
    assert solver.backend == "scipy"
    with pytest.raises(ImportError, match="needs scikit-sparse"):
        solvers.SPDSolver(A, backend="cholmod")


@pytest.mark.skipif(not cholmod_available(), reason="scikit-sparse is not installed")
@pytest.mark.parametrize("ordering", ["nesdis", "amd", "natural"])
def test_orderings_agree(ordering):
    A, b = spd()
    solver = SPDSolver(A, ordering=ordering)
    solver.update(sp.csc_matrix((np.array([2.0]), (np.array([7]), np.array([0]))), shape=(A.shape[0], 1)))
    np.testing.assert_allclose(solver.solve(b), SPDSolver(solver.matrix).solve(b), rtol=1e-10)
    assert pickle.loads(pickle.dumps(solver)).ordering == ordering


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
    A = (sp.random(n, k, density=0.08, random_state=3) + sp.hstack([sp.identity(n), sp.csc_matrix((n, k - n))])).tocoo()
    A = sp.csc_matrix((A.data[::-1], (A.row[::-1], A.col[::-1])), shape=(n, k))
    b = rng.normal(size=(n, 3))
    normal = (A @ A.T).tocsc()
    solver = SPDSolver(product_of=A, backend=backend)
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
        SPDSolver(A, product_of=A)
    with pytest.raises(TypeError, match="exactly one of matrix and product_of"):
        SPDSolver()
    with pytest.raises(TypeError, match="product_of must be a scipy sparse matrix, got ndarray"):
        SPDSolver(product_of=np.eye(3))
    with pytest.raises(SingularSystemError):
        SPDSolver(product_of=sp.csc_matrix(np.array([[1.0, 0.0], [0.0, 0.0]]))).solve(np.ones(2))

"""The solve gateway against an independent reference: numpy's dense solve of the same matrix.

Every backend, preconditioner, ordering and plumbing option of :class:`SPDSolver`, its updates, and
:func:`solve_spd`'s dense and sparse paths; no backend is compared with another.
"""

import functools
import pickle
import warnings

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import grid

from o3d_lsmesh.core import tuning
from o3d_lsmesh.core.solve import ORDERINGS, Plan, SPDSolver, cholmod_available, solve_spd
from o3d_lsmesh.laplacian import laplacian_matrix

CHOLMOD = pytest.mark.skipif(not cholmod_available(), reason="scikit-sparse is not installed")


@functools.lru_cache
def system(nx=26, ny=22, seed=0):
    """An LS-mesh normal matrix ``N = K^T K`` (a grid's Laplacian over 3% soft controls), ``K^T``, ``L``,
    numbered at random (so that the iterative path's renumbering has work to do), and a right-hand side."""
    V, F = grid(nx, ny, z=lambda x, y: 0.3 * np.sin(3 * x) * np.cos(2 * y))
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(V))
    V, F = V[order], np.argsort(order)[F]
    L = laplacian_matrix(V, F).tocsr()
    controls = rng.choice(len(V), len(V) // 33, replace=False)
    P = sp.csr_matrix(
        (np.ones(len(controls)), (np.arange(len(controls)), controls)), shape=(len(controls), len(V))
    )
    K = sp.vstack([L, P]).tocsr()
    rhs = K.T @ np.vstack([np.zeros((len(V), 3)), V[controls]])
    return (K.T @ K).tocsc(), K.T.tocsc(), L, rhs


@functools.lru_cache
def _condition():
    """The condition number of :func:`system`'s matrix before its updates (computed once)."""
    eigenvalues = np.linalg.eigvalsh(system()[0].toarray())
    return eigenvalues[-1] / eigenvalues[0]


CASES = [
    pytest.param("cholmod", {}, id="cholmod", marks=CHOLMOD),
    *[pytest.param("cholmod", {"ordering": o}, id=f"cholmod-{o}", marks=CHOLMOD) for o in ORDERINGS[1:]],
    pytest.param("cholmod", {"lower": True}, id="cholmod-lower", marks=CHOLMOD),
    pytest.param("cholmod", {"plan": "product"}, id="cholmod-product_of", marks=CHOLMOD),
    pytest.param("cholmod", {"plan": "pattern"}, id="cholmod-pattern_of", marks=CHOLMOD),
    pytest.param("scipy", {}, id="scipy-splu"),
    pytest.param("scipy", {"lower": True}, id="scipy-lower"),
    pytest.param("scipy", {"plan": "product"}, id="scipy-product_of"),
    pytest.param("iterative", {"plan": "amg"}, id="iterative-amg"),
    pytest.param("iterative", {"plan": "ic0"}, id="iterative-ic0"),
    pytest.param("iterative", {"plan": "product"}, id="iterative-product_of-locality_of"),
    pytest.param("iterative", {"plan": "scattered"}, id="iterative-renumbered"),
]


@pytest.fixture
def one_blas_thread():
    """numpy's dense references on one BLAS thread: threads waiting on busy cores made them slow."""
    threadpoolctl = pytest.importorskip("threadpoolctl")
    with threadpoolctl.threadpool_limits(limits=1, user_api="blas"):
        yield


@pytest.mark.parametrize(("backend", "options"), CASES)
@pytest.mark.usefixtures("one_blas_thread")
def test_every_backend_equals_a_dense_solve(backend, options, monkeypatch):
    N, KT, L, rhs = system()
    dense = N.toarray()
    plan = options.get("plan")
    kwargs = {"backend": backend, "ordering": options.get("ordering", "default")}
    matrix = sp.tril(N, format="csc") if options.get("lower") else N
    if plan == "product":
        matrix, kwargs["_plan"] = None, Plan(product_of=KT, locality_of=L if backend == "iterative" else None)
    elif plan == "pattern":
        kwargs["_plan"] = Plan(pattern_of=KT)
    elif plan in ("amg", "ic0"):
        kwargs["_plan"] = Plan(preconditioner=plan)
    elif plan == "scattered":
        monkeypatch.setattr(tuning, "LOCAL_SPAN", 8)  # this small system counts as scattered
    iterative = backend == "iterative"
    solver = SPDSolver(matrix, lower=bool(options.get("lower")), tol=1e-13 if iterative else 1e-9, **kwargs)
    assert solver.backend == backend
    if plan == "scattered":
        solver.solve(rhs[:, 0])
        assert solver._order is not None
    # direct: a backward-stable solve, forward error within the condition number; CG: its tolerance
    limit = (1e-9 if iterative else 1e-12 * _condition()) * np.abs(np.linalg.solve(dense, rhs)).max()
    rng = np.random.default_rng(1)
    for step in range(3):  # the factor, then two updates A + C C^T (rows may repeat, large entries)
        expected = np.linalg.solve(dense, rhs)
        np.testing.assert_allclose(solver.solve(rhs), expected, rtol=0, atol=limit)
        np.testing.assert_allclose(solver.solve(rhs[:, 1]), expected[:, 1], rtol=0, atol=limit)
        rows = rng.choice(N.shape[0], 4)
        C = sp.csc_matrix(
            (rng.uniform(0.5, 3.0, 4) * 10.0**step, (rows, [0, 0, 1, 2])), shape=(N.shape[0], 3)
        )
        solver.update(C)
        dense = dense + (C @ C.T).toarray()
    np.testing.assert_allclose(solver.matrix.toarray(), dense, rtol=0, atol=1e-12 * np.abs(dense).max())
    copy = pickle.loads(pickle.dumps(solver))
    np.testing.assert_allclose(copy.solve(rhs), np.linalg.solve(dense, rhs), rtol=0, atol=10 * limit)


def test_solve_spd_isolates_the_blocks_holding_a_non_finite_entry():
    # three diagonal blocks: one with a NaN entry, one with an infinite right-hand side, one clean
    blocks = [np.array([[4.0, 1.0], [1.0, 3.0]]), np.array([[2.0, np.nan], [np.nan, 2.0]]), np.eye(2) * 5]
    matrix = sp.block_diag(blocks, format="csr")
    rhs = np.arange(12.0).reshape(6, 2)
    rhs[4, 1] = np.inf
    x = solve_spd(matrix, rhs, isolate_nonfinite=True)
    np.testing.assert_allclose(x[:2], np.linalg.solve(blocks[0], rhs[:2]), rtol=1e-14)
    assert np.isnan(x[2:]).all()
    finite = solve_spd(
        sp.block_diag([blocks[0], blocks[2]], format="csr"), rhs[[0, 1, 2, 3]], isolate_nonfinite=True
    )
    np.testing.assert_allclose(
        finite, np.linalg.solve(sp.block_diag([blocks[0], blocks[2]]).toarray(), rhs[:4])
    )
    none = solve_spd(matrix[2:4][:, 2:4], rhs[2:4], isolate_nonfinite=True)
    assert none.shape == (2, 2) and np.isnan(none).all()


def test_old_keywords_warn_from_outside_the_package_and_keep_working():
    N, KT, _, rhs = system(12, 12)
    expected = np.linalg.solve(N.toarray(), rhs)
    with pytest.warns(DeprecationWarning, match=r"SPDSolver\(product_of=\) is deprecated: pass _plan="):
        solver = SPDSolver(product_of=KT, backend="scipy")
    np.testing.assert_allclose(solver.solve(rhs), expected, rtol=1e-9)
    with pytest.warns(DeprecationWarning, match=r"preconditioner=, reduction="):
        SPDSolver(N, backend="iterative", preconditioner="ic0", reduction=0.5)
    with pytest.raises(TypeError, match="unexpected keyword argument 'pattern'"):
        SPDSolver(N, pattern=KT)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pickle.loads(pickle.dumps(SPDSolver(N, backend="scipy", _plan=Plan(memory_budget=10**9))))

"""The iterative solver's compiled block loops (``o3d_lsmesh/_block_kernel.pyx``) against SciPy, pyamg and NumPy."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from pyamg.relaxation.relaxation import gauss_seidel as pyamg_gauss_seidel

from o3d_lsmesh import _block_kernel
from o3d_lsmesh._solvers import COARSE_UNKNOWNS, _aggregation_levels, _block_times, _vcycle


def _random_csr(rows, cols, density, seed, index=np.int32):
    matrix = sp.random(rows, cols, density=density, random_state=seed, format="csr")
    matrix.indices = matrix.indices.astype(index)
    matrix.indptr = matrix.indptr.astype(index)
    return matrix


@settings(max_examples=40, deadline=None)
@given(
    rows=st.integers(1, 40),
    cols=st.integers(1, 40),
    k=st.sampled_from([1, 2, 3, 5]),
    seed=st.integers(0, 2**16),
    index=st.sampled_from([np.int32, np.int64]),
)
def test_block_product_is_scipys_product(rows, cols, k, seed, index):
    A = _random_csr(rows, cols, 0.3, seed, index)
    x = np.random.default_rng(seed).standard_normal((cols, k))
    out = np.full((rows, k), np.nan)  # every entry written, rows without entries too
    _block_kernel.block_product(A.indptr, A.indices, A.data, x, out)
    # the same products summed in the same order as one column at a time
    want = np.column_stack([A @ x[:, c] for c in range(k)])
    assert np.array_equal(out, want)


@pytest.mark.parametrize("k", [1, 3, 4])
@pytest.mark.parametrize("forward", [True, False])
def test_gauss_seidel_is_pyamgs_sweep_on_each_column(k, forward):
    n = 60
    A = _random_csr(n, n, 0.1, 3)
    A = (A + A.T + sp.diags(np.r_[np.zeros(3), np.full(n - 3, 4.0)])).tocsr()  # three zero diagonals
    A.sort_indices()
    rng = np.random.default_rng(1)
    b, x = rng.standard_normal((n, k)), rng.standard_normal((n, k))
    want = x.copy()
    for c in range(k):
        column = np.ascontiguousarray(want[:, c])
        pyamg_gauss_seidel(
            A, column, np.ascontiguousarray(b[:, c]), sweep="forward" if forward else "backward"
        )
        want[:, c] = column
    got = x.copy()
    _block_kernel.gauss_seidel(A.indptr, A.indices, A.data, got, b, forward)
    assert np.array_equal(got, want)
    assert np.array_equal(got[:3], x[:3])  # a row without a diagonal is left alone


def test_gauss_seidel_rejects_more_than_sixteen_columns():
    A = sp.identity(3, format="csr")
    with pytest.raises(ValueError, match="x must have at most 16 columns, got 17"):
        _block_kernel.gauss_seidel(A.indptr, A.indices, A.data, np.zeros((3, 17)), np.zeros((3, 17)), True)


def test_cg_step_is_the_numpy_update():
    rng = np.random.default_rng(2)
    x, r, p, q = (rng.standard_normal((50, 3)) for _ in range(4))
    alpha = rng.standard_normal(3)
    x_want, r_want = x + alpha * p, r - alpha * q
    squares = _block_kernel.cg_step(x, r, p, q, alpha)
    assert np.array_equal(x, x_want) and np.array_equal(r, r_want)
    assert np.allclose(squares, (r_want**2).sum(axis=0), rtol=1e-14)


def test_aggregation_vcycle_is_pyamgs_smoothed_aggregation_vcycle():
    pyamg = pytest.importorskip("pyamg")
    grid = pyamg.gallery.poisson((200, 200), format="csr")  # 40000 unknowns: four levels
    reference = pyamg.smoothed_aggregation_solver(
        grid,
        B=np.ones((grid.shape[0], 1)),
        symmetry="symmetric",
        strength=None,
        smooth=("jacobi", {"weighting": "local"}),
        presmoother=("gauss_seidel", {"sweep": "forward"}),
        postsmoother=("gauss_seidel", {"sweep": "backward"}),
        max_coarse=COARSE_UNKNOWNS,
        coarse_solver="splu",
    )
    levels, coarse = _aggregation_levels(grid)
    sizes = [A.shape[0] for A, _, _ in levels] + [coarse.shape[0]]
    assert sizes == [level.A.shape[0] for level in reference.levels] and len(sizes) == 4
    for (_, R, P), level in zip(levels, reference.levels):
        assert abs(P - level.P).max() < 1e-12 and abs(R - level.R).max() < 1e-12
    b = np.random.default_rng(4).standard_normal((grid.shape[0], 3))
    got = _vcycle(levels, coarse)(b)
    # pyamg's own V-cycle from a zero guess, one cycle, column by column
    want = np.column_stack([reference.solve(b[:, c], maxiter=1, tol=1e-300, cycle="V") for c in range(3)])
    assert np.allclose(got, want, rtol=1e-10, atol=1e-10 * np.abs(want).max())


def test_block_times_takes_csc_and_vectors():
    A = _random_csr(30, 30, 0.2, 5).tocsc()
    x = np.random.default_rng(6).standard_normal((30, 2))
    assert np.allclose(_block_times(A)(x), A @ x, rtol=1e-14, atol=1e-14)

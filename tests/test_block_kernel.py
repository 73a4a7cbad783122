"""The iterative solver's compiled block loops (``o3d_lsmesh/_block_kernel.pyx``) against SciPy, pyamg and NumPy."""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from pyamg.relaxation.relaxation import gauss_seidel as pyamg_gauss_seidel

from o3d_lsmesh import _block_kernel
from o3d_lsmesh.core._iterative import VCycle, aggregation_levels, csr_parts, sweep_blocks
from o3d_lsmesh.core.tuning import COARSE_UNKNOWNS, STRENGTH


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


@pytest.mark.parametrize("k", [1, 3, 5])
def test_block_product_residual_and_accumulation(k):
    A = _random_csr(30, 20, 0.3, 11)
    A.indptr[5:8] = A.indptr[5]  # ...with empty rows
    A = sp.csr_matrix((A.data[: A.indptr[-1]], A.indices[: A.indptr[-1]], A.indptr), shape=A.shape)
    rng = np.random.default_rng(12)
    x, b = rng.standard_normal((20, k)), rng.standard_normal((30, k))
    product = np.column_stack([A @ x[:, c] for c in range(k)])
    residual = np.full((30, k), np.nan)
    _block_kernel.block_product(A.indptr, A.indices, A.data, x, residual, -1.0, b)
    assert np.array_equal(residual, b - product)  # the same sums, then one subtraction
    total = b.copy()
    _block_kernel.block_product(A.indptr, A.indices, A.data, x, total, 1.0, total)  # out is its own offset
    assert np.array_equal(total, b + product)
    scaled = np.empty((30, k))
    _block_kernel.block_product(A.indptr, A.indices, A.data, x, scaled, 2.5)
    assert np.array_equal(scaled, 2.5 * product)
    with pytest.raises(ValueError, match=rf"offset must have the shape of out \(30, {k}\), got \(29, {k}\)"):
        _block_kernel.block_product(A.indptr, A.indices, A.data, x, scaled, 1.0, b[:29])


def test_block_product_on_threads_is_scipys_product_whatever_the_thread_count():
    from threadpoolctl import threadpool_limits

    # above the rows where the loops go parallel: a block of rows per thread, each row summed as on one
    rng = np.random.default_rng(21)
    indptr = np.r_[0, np.cumsum(rng.integers(0, 9, 100_000))].astype(np.int32)  # empty rows too
    A = sp.csr_matrix(
        (rng.standard_normal(indptr[-1]), rng.integers(0, 3000, indptr[-1]), indptr), shape=(100_000, 3000)
    )
    x, b = rng.standard_normal((2, 100_000, 3))
    want = b - np.column_stack([A @ x[:3000, c] for c in range(3)])
    for limit in (1, 2):
        with threadpool_limits(limits=limit, user_api="openmp"):
            out = np.full((100_000, 3), np.nan)
            _block_kernel.block_product(A.indptr, A.indices, A.data, x[:3000], out, -1.0, b)
            assert np.array_equal(out, want)


def test_cg_sums_do_not_depend_on_the_thread_count():
    from threadpoolctl import threadpool_limits

    # 200k rows: blocks side by side on every core, the same sums on one thread
    rng = np.random.default_rng(24)
    a, b, x, r = rng.standard_normal((4, 200_000, 3))
    alpha = np.array([0.3, -1.2, 2.0])
    w = rng.random(200_000)
    results = []
    for limit in (1, 2):
        with threadpool_limits(limits=limit, user_api="openmp"):
            x1, r1 = x.copy(), r.copy()
            results.append(
                (_block_kernel.column_dots(a, b), _block_kernel.cg_step(x1, r1, a, b, alpha, w), x1, r1)
            )
    assert all(np.array_equal(u, v) for u, v in zip(*results))
    dots, squares, x1, r1 = results[0]
    np.testing.assert_allclose(dots, np.einsum("ij,ij->j", a, b), rtol=1e-12)
    assert np.array_equal(x1, x + alpha * a) and np.array_equal(r1, r - alpha * b)
    np.testing.assert_allclose(squares, np.einsum("ij,ij->j", w[:, None] * r1, w[:, None] * r1), rtol=1e-12)


@pytest.mark.parametrize("k", [1, 3, 5])
def test_column_dots_and_cg_direction_are_numpys(k):
    rng = np.random.default_rng(13)
    a, b = rng.standard_normal((2, 300_000 if k == 3 else 50, k))  # k = 3 at this size runs threaded
    assert np.allclose(_block_kernel.column_dots(a, b), np.einsum("ij,ij->j", a, b), rtol=1e-12)
    beta = rng.standard_normal(k)
    p, want = a.copy(), b + beta * a
    _block_kernel.cg_direction(p, b, beta)
    assert np.array_equal(p, want)


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


@pytest.mark.parametrize("k", [1, 3, 5])
@pytest.mark.parametrize("forward", [True, False])
@pytest.mark.parametrize("blocks", [2, 5, 1000])
def test_blocked_gauss_seidel_is_the_hybrid_sweep_of_a_plain_loop(k, forward, blocks):
    n = 61
    A = _random_csr(n, n, 0.1, 7)
    A = (A + A.T + sp.diags(np.r_[np.zeros(2), np.full(n - 2, 4.0)])).tocsr()
    A.sort_indices()
    rng = np.random.default_rng(3)
    b, x = rng.standard_normal((n, k)), rng.standard_normal((n, k))
    dense, want, parts = A.toarray(), x.copy(), min(blocks, n)
    for block in range(parts):  # each block in turn, reading the other blocks' values from before
        start, stop = block * n // parts, (block + 1) * n // parts
        for i in range(start, stop) if forward else range(stop - 1, start - 1, -1):
            if dense[i, i] == 0:
                continue
            inside = [j for j in range(start, stop) if j != i]
            outside = [j for j in range(n) if not start <= j < stop]
            total = dense[i, inside] @ want[inside] + dense[i, outside] @ x[outside]
            want[i] = (b[i] - total) / dense[i, i]
    got = x.copy()
    _block_kernel.gauss_seidel(A.indptr, A.indices, A.data, got, b, forward, blocks)
    assert np.allclose(got, want, rtol=1e-12, atol=1e-12)
    single = x.copy()
    _block_kernel.gauss_seidel(A.indptr, A.indices, A.data, single, b, forward, 1)
    assert not np.allclose(got, single, rtol=1e-6)  # the blocks change the sweep


def test_blocked_vcycle_is_symmetric(monkeypatch):
    # forward blocked sweeps before the coarse correction, backward ones after: CG needs M^-1 symmetric
    from o3d_lsmesh.core import tuning

    pyamg = pytest.importorskip("pyamg")
    monkeypatch.setattr(tuning, "ROWS_PER_SWEEP_BLOCK", 700)
    grid = pyamg.gallery.poisson((70, 70), format="csr")
    assert sweep_blocks(grid) == 7
    cycle = VCycle(*aggregation_levels(grid))
    u, v = np.random.default_rng(5).standard_normal((2, grid.shape[0], 3))
    assert np.allclose(np.einsum("ij,ij->j", u, cycle(v)), np.einsum("ij,ij->j", v, cycle(u)), rtol=1e-10)


def test_gauss_seidel_rejects_more_than_sixteen_columns():
    A = sp.identity(3, format="csr")
    with pytest.raises(ValueError, match="x must have at most 16 columns, got 17"):
        _block_kernel.gauss_seidel(A.indptr, A.indices, A.data, np.zeros((3, 17)), np.zeros((3, 17)), True)


@pytest.mark.parametrize("n", [50, 300_000])  # one thread, and every core
def test_cg_step_is_the_numpy_update(n):
    rng = np.random.default_rng(2)
    x, r, p, q = (rng.standard_normal((n, 3)) for _ in range(4))
    alpha, w = rng.standard_normal(3), rng.random(n)  # w: a weight per row
    x_want, r_want = x + alpha * p, r - alpha * q
    squares = _block_kernel.cg_step(x, r, p, q, alpha, w)
    assert np.array_equal(x, x_want) and np.array_equal(r, r_want)
    assert np.allclose(squares, ((w[:, None] * r_want) ** 2).sum(axis=0), rtol=1e-12)


def test_aggregation_vcycle_is_pyamgs_smoothed_aggregation_vcycle():
    pyamg = pytest.importorskip("pyamg")
    from pyamg.multilevel import MultilevelSolver
    from pyamg.relaxation.smoothing import change_smoothers

    grid = pyamg.gallery.poisson((200, 200), format="csr")  # 40000 unknowns: four levels
    reference = pyamg.smoothed_aggregation_solver(
        grid,
        B=np.ones((grid.shape[0], 1)),
        symmetry="symmetric",
        strength=("symmetric", {"theta": STRENGTH}),
        smooth=("jacobi", {"weighting": "local"}),
        max_coarse=COARSE_UNKNOWNS,
        coarse_solver="splu",
    )
    levels, coarse = aggregation_levels(grid)
    # every entry of the grid is strong: the finest level has nothing to lump and is pyamg's
    (_, R, P), level = levels[0], reference.levels[0]
    assert abs(P - level.P).max() < 1e-12 and abs(R - level.R).max() < 1e-12
    assert len(levels) == 3 and levels[1][0].shape == reference.levels[1].A.shape
    # the V-cycle on our levels is pyamg's: forward Gauss-Seidel before, backward after, LU at the bottom
    ours = []
    for A, R, P in levels:
        ours.append(MultilevelSolver.Level())
        ours[-1].A, ours[-1].R, ours[-1].P = A, R, P
    ours.append(MultilevelSolver.Level())
    ours[-1].A = levels[-1][1] @ levels[-1][0] @ levels[-1][2]
    assert ours[-1].A.shape == coarse.shape
    ml = MultilevelSolver(ours, coarse_solver="splu")
    change_smoothers(ml, ("gauss_seidel", {"sweep": "forward"}), ("gauss_seidel", {"sweep": "backward"}))
    b = np.random.default_rng(4).standard_normal((grid.shape[0], 3))
    got = VCycle(levels, coarse)(b)
    want = np.column_stack([ml.solve(b[:, c], maxiter=1, tol=1e-300, cycle="V") for c in range(3)])
    assert np.allclose(got, want, rtol=1e-10, atol=1e-10 * np.abs(want).max())


def test_aggregation_smooths_the_prolongator_with_the_strong_part():
    # an LS mesh's normal matrix L^T L + W^2 (uniform L on a triangulated grid): a 1-ring of strong
    # entries and a 2-ring of weak ones, which must neither join the aggregates' graph nor widen P
    from o3d_lsmesh.laplacian import laplacian_matrix

    side = 60
    u, v = np.meshgrid(np.arange(side, dtype=float), np.arange(side, dtype=float))
    vertices = np.column_stack([u.ravel(), v.ravel(), np.zeros(side * side)])
    corner = (np.arange(side - 1)[:, None] * side + np.arange(side - 1)[None, :]).ravel()
    triangles = np.concatenate(
        [
            np.column_stack([corner, corner + 1, corner + side + 1]),
            np.column_stack([corner, corner + side + 1, corner + side]),
        ]
    )
    L = laplacian_matrix(vertices, triangles, "uniform").tocsr()
    N = (L.T @ L + sp.diags(np.where(np.arange(side * side) % 50 == 0, 1.0, 0.0))).tocsr()
    N.sort_indices()
    indptr, indices, data = _block_kernel.strong_part(N.indptr, N.indices, N.data, STRENGTH)
    strong = sp.csr_matrix((data, indices, indptr), shape=N.shape)
    mesh_graph = (abs(L) > 0).astype(int)
    # the strong part is the 1-ring (and a few second-ring entries at the grid's corners)
    assert (mesh_graph - mesh_graph.multiply(strong != 0)).nnz == 0 and strong.nnz <= 1.01 * mesh_graph.nnz
    mesh_graph = (strong != 0).astype(int)
    from pyamg.aggregation.aggregate import standard_aggregation

    P = aggregation_levels(N)[0][0][2]
    aggregates = standard_aggregation(mesh_graph.tocsr())[0]  # the strong graph's aggregates, by pyamg
    assert P.shape == aggregates.shape
    identity = sp.eye(len(vertices), dtype=int, format="csr")
    reach_strong = (((identity + mesh_graph) @ aggregates) != 0).astype(int)
    reach_whole = (((identity + (abs(N) > 0).astype(int)) @ aggregates) != 0).astype(int)
    pattern = (P != 0).astype(int)
    # P = (I - omega D^-1 A_F) T reaches one strong step from each aggregate, and fills that reach
    assert (pattern - pattern.multiply(reach_strong)).nnz == 0
    assert pattern.nnz >= 0.95 * reach_strong.nnz
    assert reach_whole.nnz > 1.3 * reach_strong.nnz  # smoothing with the whole stencil would reach farther


@pytest.mark.parametrize("index", [np.int32, np.int64])
def test_strong_part_is_pyamgs_symmetric_strength_with_the_weak_entries_lumped(index):
    pyamg = pytest.importorskip("pyamg")
    rng = np.random.default_rng(8)
    A = _random_csr(200, 200, 0.05, 9)
    A = (A + A.T + sp.diags(rng.uniform(0.5, 3.0, 200))).tocsr()  # mixed signs, every diagonal stored
    A.sort_indices()
    parts = (A.indptr.astype(index), A.indices.astype(index), A.data)
    indptr, indices, data = _block_kernel.strong_part(*parts, 0.25)
    assert indptr.dtype == indices.dtype == index
    # a plain loop over the entries with the definition |a_ij| >= theta sqrt(|a_ii a_jj|)
    dense, diagonal = A.toarray(), np.abs(A.diagonal())
    want = np.zeros_like(dense)
    for i, j in zip(*np.nonzero(dense)):
        strong = i == j or abs(dense[i, j]) >= 0.25 * np.sqrt(diagonal[i] * diagonal[j])
        want[i, j if strong else i] += dense[i, j]
    got = sp.csr_matrix((data, indices, indptr), shape=A.shape)
    assert np.allclose(got.toarray(), want, rtol=0, atol=1e-14)
    assert 0 < got.nnz < A.nnz  # the threshold splits this matrix
    # the pattern is pyamg's symmetric strength of connection
    Sp, Sj, Sx = np.empty_like(A.indptr), np.empty_like(A.indices), np.empty_like(A.data)
    pyamg.amg_core.symmetric_strength_of_connection(200, 0.25, A.indptr, A.indices, A.data, Sp, Sj, Sx)
    assert np.array_equal(indptr, Sp) and np.array_equal(indices, Sj[: Sp[-1]])


def test_block_product_takes_csc_through_csr_parts():
    A = _random_csr(30, 30, 0.2, 5).tocsc()
    x = np.random.default_rng(6).standard_normal((30, 2))
    out = np.empty((30, 2))
    _block_kernel.block_product(*csr_parts(A), x, out)
    assert np.allclose(out, A @ x, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("index", [np.int32, np.int64])
def test_permuted_is_scipys_fancy_indexing_and_row_span_a_plain_mean(index):
    A = _random_csr(400, 400, 0.03, 14)
    A = (A + A.T + sp.eye(400)).tocsr()
    A.sort_indices()
    order = np.random.default_rng(15).permutation(400).astype(np.int64)
    indptr, indices, data = _block_kernel.permuted(
        A.indptr.astype(index), A.indices.astype(index), A.data, order
    )
    B = sp.csr_matrix((data, indices, indptr), shape=A.shape)
    assert abs(B - A[order][:, order]).max() == 0
    assert all((np.diff(indices[indptr[r] : indptr[r + 1]]) > 0).all() for r in range(400))
    rows = np.repeat(np.arange(400), np.diff(A.indptr))
    span = _block_kernel.row_span(A.indptr.astype(index), A.indices.astype(index))
    assert span == pytest.approx(np.abs(A.indices - rows).mean(), rel=1e-12)
    with pytest.raises(ValueError, match="order must be a permutation of the rows"):
        _block_kernel.permuted(A.indptr, A.indices, A.data, np.zeros(400, dtype=np.int64))
    with pytest.raises(ValueError, match=r"order must have one entry per row \(400\), got 3"):
        _block_kernel.permuted(A.indptr, A.indices, A.data, np.arange(3, dtype=np.int64))


def _reference_rcm(A: sp.csr_matrix) -> list:
    """Reverse Cuthill-McKee as plain loops: per component (in order of its lowest vertex ``s``), a
    breadth-first search (new neighbours by increasing degree, ties in row order) from its vertex of
    least degree (ties: the first that such a search from ``s`` reaches), then the whole order reversed."""
    degree, order = np.diff(A.indptr), []

    def search(start: int) -> list:
        level, seen = [start], {start}
        for v in level:
            new = [w for w in A.indices[A.indptr[v] : A.indptr[v + 1]] if w not in seen]
            seen.update(new)
            level.extend(sorted(new, key=lambda w: degree[w]))  # stable: ties keep row order
        return level

    for s in range(A.shape[0]):
        if s not in order:
            reached = search(s)
            order.extend(search(min(reached, key=lambda v: (degree[v], reached.index(v)))))
    return [int(v) for v in order[::-1]]


@pytest.mark.parametrize("index", [np.int32, np.int64])
@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 60), density=st.floats(0.0, 0.2), seed=st.integers(0, 10**6))
def test_level_order_is_reverse_cuthill_mckee_as_a_plain_loop(index, n, density, seed):
    A = sp.random(n, n, density=density, random_state=seed, format="csr")
    A = (A + A.T + sp.identity(n)).tocsr()
    A.sort_indices()
    got = _block_kernel.level_order(A.indptr.astype(index), A.indices.astype(index))
    assert got.tolist() == _reference_rcm(A)


@pytest.mark.parametrize("index", [np.int32, np.int64])
@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 40), k=st.integers(1, 50), density=st.floats(0.0, 0.3), seed=st.integers(0, 10**6))
def test_gram_is_a_sorted_exactly_symmetric_a_at(index, n, k, density, seed):
    A = sp.random(n, k, density=density, random_state=seed, format="csc")
    rows = A.tocsr()
    indptr, indices, data = _block_kernel.gram(
        rows.indptr.astype(index), rows.indices.astype(index), rows.data,
        A.indptr.astype(index), A.indices.astype(index), A.data,
    )  # fmt: skip
    got = sp.csr_matrix((data, indices, indptr), shape=(n, n))
    want = A.toarray() @ A.toarray().T  # dense reference
    assert np.allclose(got.toarray(), want, rtol=1e-14, atol=1e-14)
    assert (got != got.T).nnz == 0  # bit for bit
    assert all((np.diff(indices[indptr[i] : indptr[i + 1]]) > 0).all() for i in range(n))
    # the pattern is exactly the structural product's (no stored zeros beyond it, none missing)
    pattern = (abs(A) @ abs(A).T).tocsr()
    assert got.nnz == pattern.nnz


def test_gram_on_threads_is_scipys_product_whatever_the_thread_count():
    from threadpoolctl import threadpool_limits

    # above the rows where the loops go parallel: a block of rows per thread, each with its own marker
    rng = np.random.default_rng(23)
    indptr = np.r_[0, np.cumsum(rng.integers(0, 4, 70_000))]
    A = sp.csr_matrix(
        (rng.standard_normal(indptr[-1]), rng.integers(0, 20_000, indptr[-1]), indptr), shape=(70_000, 20_000)
    )
    A.sum_duplicates()
    columns = A.tocsc()
    parts = (A.indptr, A.indices, A.data, columns.indptr, columns.indices, columns.data)
    results = []
    for limit in (1, 2):
        with threadpool_limits(limits=limit, user_api="openmp"):
            results.append(_block_kernel.gram(*parts))
    assert all(np.array_equal(a, b) for a, b in zip(*results))
    got = sp.csr_matrix(results[0][::-1], shape=(70_000, 70_000))
    assert abs(got - A @ A.T).max() < 1e-12 and got.nnz == (abs(A) @ abs(A).T).nnz


@pytest.mark.parametrize("n", [40, 150_000])  # one thread, and every core
def test_pair_product_is_offset_plus_two_scipy_products_on_one_pattern(n):
    rng = np.random.default_rng(9)
    indices = np.sort(rng.integers(0, n, (n, 7)), axis=1).ravel().astype(np.int32)  # 7 entries a row
    A = sp.csr_matrix(
        (rng.standard_normal(7 * n), indices, np.arange(0, 7 * n + 1, 7, dtype=np.int32)), (n, n)
    )
    B = A.copy()
    B.data = np.random.default_rng(10).standard_normal(B.nnz)
    xa, xb, offset = np.random.default_rng(11).standard_normal((3, n, 3))
    out = np.empty((n, 3))
    _block_kernel.pair_product(A.indptr, A.indices, A.data, xa, B.data, xb, offset, out)
    want = offset + A @ xa + B @ xb
    assert np.allclose(out, want, rtol=1e-13, atol=1e-13 * np.abs(want).max())
    _block_kernel.pair_product(A.indptr, A.indices, A.data, xa, B.data, xb, offset, offset)  # in place
    assert np.array_equal(offset, out)
    with pytest.raises(ValueError, match="xa must have 3 columns, got 2"):
        _block_kernel.pair_product(A.indptr, A.indices, A.data, xa[:, :2].copy(), B.data, xb, out, out)
    short = offset[: n - 1].copy()
    with pytest.raises(
        ValueError, match=rf"offset must have the shape of out \({n}, 3\), got \({n - 1}, 3\)"
    ):
        _block_kernel.pair_product(A.indptr, A.indices, A.data, xa, B.data, xb, short, out)


@pytest.mark.parametrize("n", [50, 150_000])
@pytest.mark.parametrize("index", [np.int32, np.int64])
def test_add_subset_equals_the_scipy_sum_where_the_pattern_holds_the_term(n, index):
    rng = np.random.default_rng(n)
    big = sp.random(n, n, density=min(8.0 / n, 0.5), format="csr", random_state=rng) + sp.identity(n)
    big.sort_indices()
    # the term: a random subset of big's entries, with values of its own
    keep = rng.random(big.nnz) < 0.4
    rows = np.repeat(np.arange(n), np.diff(big.indptr))
    term = sp.csr_matrix((rng.normal(size=keep.sum()), (rows[keep], big.indices[keep])), shape=(n, n))
    term.sort_indices()
    expected = (big + term).toarray() if n < 1000 else None
    data = big.data.copy()
    missing = _block_kernel.add_subset(
        big.indptr.astype(index),
        big.indices.astype(index),
        data,
        term.indptr.astype(index),
        term.indices.astype(index),
        term.data,
    )
    assert missing == 0
    got = sp.csr_matrix((data, big.indices, big.indptr), shape=(n, n))
    if expected is not None:
        np.testing.assert_array_equal(got.toarray(), expected)
    else:
        assert abs(got - (big + term)).max() == 0.0
    # an entry outside the pattern is counted and left out; the rest is still added
    row0 = set(big.indices[big.indptr[0] : big.indptr[1]].tolist())
    column = next(c for c in range(n) if c not in row0)
    outside = sp.csr_matrix(([5.0, 1.0], ([0, 1], [column, 1])), shape=(n, n))
    data = big.data.copy()
    parts = (big.indptr.astype(index), big.indices.astype(index), data)
    missing = _block_kernel.add_subset(
        *parts, outside.indptr.astype(index), outside.indices.astype(index), outside.data
    )
    assert missing == 1
    got = sp.csr_matrix((data, big.indices, big.indptr), shape=(n, n))
    assert got[1, 1] == big[1, 1] + 1.0 and abs(got - big).sum() == 1.0
    with pytest.raises(ValueError, match=rf"sub_indptr must have {n + 1} entries, got 3"):
        _block_kernel.add_subset(*parts, np.zeros(3, dtype=index), big.indices.astype(index), big.data)


def _grid_laplacian_plus_mass(nx, ny, seed, index):
    # an SPD matrix with a 2D mesh's pattern and fill outside it under Cholesky: random positive edge
    # weights w_ij, A = sum_ij w_ij (e_i - e_j)(e_i - e_j)^T + diag(c), c > 0
    rng = np.random.default_rng(seed)
    ids = np.arange(nx * ny).reshape(ny, nx)
    pairs = np.vstack(
        [
            np.c_[ids[:, :-1].ravel(), ids[:, 1:].ravel()],
            np.c_[ids[:-1, :].ravel(), ids[1:, :].ravel()],
            np.c_[ids[:-1, :-1].ravel(), ids[1:, 1:].ravel()],
        ]
    )
    w = rng.uniform(0.5, 2.0, len(pairs))
    n = nx * ny
    off = sp.coo_matrix((-w, (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    off = off + off.T
    A = (off - sp.diags(np.asarray(off.sum(axis=1)).ravel()) + sp.diags(rng.uniform(0.1, 1.0, n))).tocsr()
    A.sort_indices()
    A.indices, A.indptr = A.indices.astype(index), A.indptr.astype(index)
    return A


@pytest.mark.parametrize("index", [np.int32, np.int64])
@pytest.mark.parametrize("shift", [0.0, 0.25])
def test_incomplete_cholesky_reproduces_the_matrix_on_its_pattern(index, shift):
    # IC(0)'s defining property, checked densely: L lower triangular on A's pattern, (L L^T)_ij = a_ij on
    # the pattern (the diagonal times 1 + shift); the value at (j, i) is l_ij's mirror
    A = _grid_laplacian_plus_mass(7, 6, seed=3, index=index)
    values, diagonal, failed = _block_kernel.incomplete_cholesky(A.indptr, A.indices, A.data, shift)
    assert failed == -1
    n = A.shape[0]
    rows = np.repeat(np.arange(n), np.diff(A.indptr))
    lower = A.indices <= rows
    L = np.zeros((n, n))
    L[rows[lower], A.indices[lower]] = values[lower]
    mirrored = np.zeros((n, n))
    mirrored[A.indices[~lower], rows[~lower]] = values[~lower]
    np.testing.assert_array_equal(mirrored, np.tril(L, -1))
    np.testing.assert_array_equal(A.indices[diagonal], np.arange(n))
    dense = A.toarray() + shift * np.diag(A.diagonal())
    product = L @ L.T
    on = A.toarray() != 0
    np.testing.assert_allclose(product[on], dense[on], rtol=1e-12, atol=1e-12)
    assert np.abs(product[~on]).max() > 1e-3  # the fill IC(0) drops: L L^T is not A


def test_incomplete_cholesky_of_a_tridiagonal_matrix_is_its_cholesky_factor():
    n = 30
    rng = np.random.default_rng(5)
    off = -rng.uniform(0.1, 1.0, n - 1)
    dense = np.diag(off, 1) + np.diag(off, -1) + np.diag(2.5 + rng.uniform(0, 1, n))
    A = sp.csr_matrix(dense)
    values, diagonal, _ = _block_kernel.incomplete_cholesky(A.indptr, A.indices, A.data, 0.0)
    want = np.linalg.cholesky(dense)
    np.testing.assert_allclose(values[diagonal], np.diag(want), rtol=1e-13)
    np.testing.assert_allclose(values[diagonal[1:] - 1], np.diag(want, -1), rtol=1e-13)


@pytest.mark.parametrize("k", [1, 2, 3])
def test_incomplete_cholesky_solve_is_two_dense_triangular_solves(k):
    from scipy.linalg import solve_triangular

    A = _grid_laplacian_plus_mass(6, 5, seed=1, index=np.int32)
    values, diagonal, _ = _block_kernel.incomplete_cholesky(A.indptr, A.indices, A.data, 0.0)
    n = A.shape[0]
    rows = np.repeat(np.arange(n), np.diff(A.indptr))
    lower = A.indices <= rows
    L = np.zeros((n, n))
    L[rows[lower], A.indices[lower]] = values[lower]
    r = np.random.default_rng(k).standard_normal((n, k))
    z = np.full((n, k), np.nan)
    _block_kernel.incomplete_cholesky_solve(A.indptr, A.indices, values, diagonal, r, z)
    want = solve_triangular(L.T, solve_triangular(L, r, lower=True), lower=False)
    np.testing.assert_allclose(z, want, rtol=1e-12, atol=1e-12)


def test_incomplete_cholesky_refuses_a_missing_diagonal_and_an_unsymmetric_pattern():
    A = sp.csr_matrix(np.array([[2.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    with pytest.raises(ValueError, match="matrix must store every diagonal entry, row 1 has none"):
        _block_kernel.incomplete_cholesky(A.indptr, A.indices, A.data, 0.0)
    B = sp.csr_matrix(np.array([[2.0, 0.0, 0.0], [1.0, 2.0, 0.0], [0.0, 0.0, 1.0]]))
    with pytest.raises(ValueError, match="matrix must have a symmetric pattern, row 1"):
        _block_kernel.incomplete_cholesky(B.indptr, B.indices, B.data, 0.0)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the kernels link GCC's libgomp on Linux")
def test_openmp_threads_sleep_at_barriers_instead_of_spinning():
    # libgomp reads its wait policy when it loads: checked in a fresh interpreter, through OpenMP's own report
    import subprocess

    code = "import ctypes, o3d_lsmesh; ctypes.CDLL('libgomp.so.1').omp_display_env(1)"
    environ = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")}
    report = subprocess.run([sys.executable, "-c", code], env=environ, capture_output=True, text=True).stderr
    assert "GOMP_SPINCOUNT = '0'" in report, report
    # a policy the user chose is kept
    environ["OMP_WAIT_POLICY"] = "ACTIVE"
    report = subprocess.run([sys.executable, "-c", code], env=environ, capture_output=True, text=True).stderr
    assert "OMP_WAIT_POLICY = 'ACTIVE'" in report, report


@pytest.mark.parametrize("seed", range(4))
def test_symmetry_gap_is_the_dense_largest_difference_to_the_transpose(seed):
    A = sp.random(30, 30, density=0.15, random_state=seed, format="csc")
    A = (A + A.T * (seed % 2)).tocsc()  # odd seeds nearly symmetric in pattern, even ones not
    A.sort_indices()
    dense = A.toarray()
    gap, i, j, above = _block_kernel.symmetry_gap(A.indptr, A.indices, A.data)
    difference = np.abs(dense - dense.T)
    assert gap == difference.max() and (gap == 0 or (difference[i, j] == gap and dense[i, j] != 0))
    assert above == np.count_nonzero(np.triu(dense, 1))


@pytest.mark.parametrize("seed", range(3))
def test_symmetry_gap_on_a_mesh_sized_matrix_with_sparse_columns(seed):
    # long columns, empty ones, a lone entry above the diagonal: every mirror found or missed as dense says
    A = sp.random(300, 300, density=0.05, random_state=seed, format="csc")
    A = (A + A.T).tolil()
    A[5, 250], A[299, 0] = 1.0, 2.0
    A = A.tocsc()
    A.sort_indices()
    gap, _, _, above = _block_kernel.symmetry_gap(A.indptr, A.indices, A.data)
    dense = A.toarray()
    assert gap == np.abs(dense - dense.T).max() and above == np.count_nonzero(np.triu(dense, 1))


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(1, 12),
    m=st.integers(0, 20),
    seed=st.integers(0, 2**16),
    index=st.sampled_from([np.int32, np.int64]),
)
def test_area_normals_and_edge_sums_match_plain_loops(n, m, seed, index):
    rng = np.random.default_rng(seed)
    V, T = rng.normal(size=(n, 3)), rng.integers(0, n, size=(m, 3)).astype(index)  # repeats, unused vertices
    expected = np.zeros((n, 3))
    for a, b, c in T.tolist():
        face = np.cross(V[b] - V[a], V[c] - V[a])
        for v in (a, b, c):
            expected[v] += face
    np.testing.assert_allclose(_block_kernel.area_normals(V, T), expected, rtol=1e-12, atol=1e-12)
    edges, values = T[:, :2].copy(), rng.normal(size=(n, 2))
    sums = np.zeros((n, 2))
    for a, b in edges.tolist():
        sums[a] += values[b]
        sums[b] += values[a]
    np.testing.assert_allclose(_block_kernel.edge_sums(edges, values), sums, rtol=1e-12, atol=1e-12)


def test_mesh_loops_refuse_vertices_out_of_range():
    V = np.zeros((3, 3))
    with pytest.raises(ValueError, match="outside 0..2"):
        _block_kernel.area_normals(V, np.array([[0, 1, 3]]))
    with pytest.raises(ValueError, match="outside 0..2"):
        _block_kernel.edge_sums(np.array([[-1, 0]]), V)
    indptr, indices = np.array([0, 1, 2, 2]), np.array([1, 0])
    with pytest.raises(ValueError, match="rows must lie in 0..2"):
        _block_kernel.two_ring_sums(indptr, indices, np.array([3]), V)
    with pytest.raises(ValueError, match="values must have 3 rows"):
        _block_kernel.two_ring_sums(indptr, indices, np.array([0]), V[:2])


@pytest.mark.parametrize("size", [0, 1, 7, 511, 512, 513, 4096, 1 << 20])
def test_small_pages_arrays_hold_what_is_written(size):
    # any size: within a page, across pages, not starting on a page
    assert _block_kernel.empty_small_pages((size, 3), fill=1.5).sum() == 4.5 * size
    fresh = _block_kernel.empty_small_pages(size, np.int64)
    fresh[:] = np.arange(size)
    assert fresh.dtype == np.int64 and fresh.tolist() == list(range(size))


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the advice exists on Linux only")
def test_small_pages_arrays_advise_their_whole_pages():
    array = _block_kernel.empty_small_pages(1 << 22)  # 32 MiB
    inside = array.__array_interface__["data"][0] + 4096  # within its first whole page
    area = None
    with open("/proc/self/smaps") as smaps:
        for line in smaps:
            if line.startswith("VmFlags:") and area is not None and area[0] <= inside < area[1]:
                assert "nh" in line.split()  # the kernel's flag of MADV_NOHUGEPAGE
                return
            first = line.split()[0]
            if "-" in first and not first.endswith(":"):
                area = tuple(int(x, 16) for x in first.split("-"))
    pytest.fail("the array's pages are not in /proc/self/smaps")

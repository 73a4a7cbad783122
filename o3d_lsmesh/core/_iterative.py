"""The solve gateway's paths besides CHOLMOD: SuperLU with Woodbury updates, block conjugate gradients.

Private to :mod:`~o3d_lsmesh.core.solve`. CG's preconditioners: IC(0) (Manteuffel's shifted retry) and a
smoothed-aggregation AMG V-cycle on pyamg's aggregation; also the reverse Cuthill-McKee renumbering and
``A A^T`` assembly. The inner loops are in the compiled ``_block_kernel``. Figures: docs/algorithms/solvers.rst.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from . import tuning
from .errors import ConvergenceError, SingularSystemError
from .progress import Progress

#: Entries a 32-bit index array can address.
INT32_ENTRIES = int(np.iinfo(np.int32).max)


def splu_spd(matrix: sp.csc_matrix) -> Any:
    """SuperLU set for an SPD matrix: a symmetric ordering of ``A + A^T``, diagonal pivots (no pivoting
    needed; partial pivoting would abandon the fill-reducing ordering)."""
    return spla.splu(
        matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
    )


def gram_matrix(a: sp.csc_matrix, *, rows: sp.csr_matrix | None = None) -> sp.csc_matrix:
    """``A A^T`` for a CSC ``A``, sorted CSC, exactly symmetric (``_block_kernel.gram``, on every core).

    ``rows``: ``A`` as canonical CSR, where the caller has it (else ``a.tocsr()``, a transpose pass).
    """
    from .._block_kernel import gram

    rows = a.tocsr() if rows is None else rows
    index = np.result_type(rows.indptr, rows.indices, a.indptr, a.indices)
    # the product's entries are at most the sum of the columns' squared lengths: 64-bit indices where
    # 32 bits might not hold them
    if np.sum(np.diff(a.indptr).astype(np.int64) ** 2) >= INT32_ENTRIES:
        index = np.dtype(np.int64)
    indptr, indices, data = gram(
        rows.indptr.astype(index, copy=False),
        rows.indices.astype(index, copy=False),
        rows.data,
        a.indptr.astype(index, copy=False),
        a.indices.astype(index, copy=False),
        a.data,
    )
    del rows
    # a symmetric matrix's CSR arrays are also its CSC arrays
    product = sp.csc_matrix((data, indices, indptr), shape=(a.shape[0],) * 2)
    product.has_sorted_indices = True
    return product


def csr_view(symmetric: sp.spmatrix) -> sp.csr_matrix:
    """A symmetric matrix as CSR without a copy when it is CSC (its arrays are also its transpose's)."""
    return symmetric.T if sp.isspmatrix_csc(symmetric) else sp.csr_matrix(symmetric)


def csr_parts(matrix: sp.spmatrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(indptr, indices, data)`` of ``matrix`` as CSR (no copy when it is one), one index type."""
    csr = sp.csr_matrix(matrix, dtype=np.float64)
    index = np.result_type(csr.indptr, csr.indices)
    return csr.indptr.astype(index, copy=False), csr.indices.astype(index, copy=False), csr.data


def locality_order(symmetric: sp.spmatrix) -> np.ndarray | None:
    """A reverse Cuthill-McKee renumbering of a symmetric matrix's unknowns (new -> old), or None when
    its rows reach no farther than :data:`~o3d_lsmesh.core.tuning.LOCAL_SPAN` rows on average."""
    from .._block_kernel import level_order, row_span

    indptr, indices, _ = csr_parts(csr_view(symmetric))
    if row_span(indptr, indices) <= tuning.LOCAL_SPAN:
        return None
    return level_order(indptr, indices)


def renumbered(symmetric: sp.spmatrix, order: np.ndarray) -> sp.csc_matrix:
    """``B[r, s] = A[order[r], order[s]]`` for a symmetric ``A``, CSC (one copy, sorted indices)."""
    from .._block_kernel import permuted

    indptr, indices, data = permuted(*csr_parts(csr_view(symmetric)), order)
    # a symmetric matrix's CSR arrays are also its CSC arrays
    result = sp.csc_matrix((data, indices, indptr), shape=symmetric.shape)
    result.has_sorted_indices = True
    return result


def preconditioner(matrix: sp.spmatrix, kind: str) -> Any:
    """``"ic0"``: :class:`IncompleteCholesky` where its set-up is linear (:data:`~o3d_lsmesh.core.tuning.IC_WORK`),
    else (and for ``"amg"``) one AMG V-cycle (the exact LU of a matrix too small for a hierarchy)."""
    csr = csr_view(matrix)
    if kind == "ic0":
        # row i's lower part times its upper part bounds the products its column takes part in
        lengths = np.diff(csr.indptr).astype(np.float64)
        if float(np.square(lengths).sum()) / 4.0 <= tuning.IC_WORK * max(matrix.nnz, 1):
            return IncompleteCholesky(matrix)
    return VCycle(*aggregation_levels(csr))


class IncompleteCholesky:
    """``r -> (L L^T)^-1 r`` for the zero-fill incomplete Cholesky factor ``L`` of a symmetric matrix.

    A breakdown (a non-positive pivot, possible on an SPD matrix that is not an M-matrix) is retried on
    the diagonal scaled by ``1 + shift`` (Manteuffel 1980), the shift doubling from
    :data:`~o3d_lsmesh.core.tuning.FIRST_SHIFT`. Holds arrays only: threads may share it.
    """

    def __init__(self, matrix: sp.spmatrix) -> None:
        from .._block_kernel import incomplete_cholesky

        self._parts = csr_parts(csr_view(matrix))
        shifts = [0.0] + [tuning.FIRST_SHIFT * 2.0**i for i in range(tuning.MAX_SHIFTS)]
        try:
            for shift in shifts:
                values, diagonal, failed = incomplete_cholesky(*self._parts, shift)
                if values is not None:
                    break
        except ValueError as error:  # no diagonal entry, or an unsymmetric pattern
            raise SingularSystemError(f"matrix must be symmetric positive definite: {error}") from error
        if values is None or diagonal is None:
            raise SingularSystemError(
                f"matrix must be positive definite: its incomplete Cholesky factor breaks down at row {failed} "
                f"with the diagonal scaled by {1.0 + shift:.3g}"
            )
        self.shift = shift
        self._values, self._diagonal = values, diagonal

    def bound(self, k: int) -> Any:
        """``apply(r, out)`` on C-ordered ``(n, k)`` blocks (no work block to keep)."""
        from .._block_kernel import incomplete_cholesky_solve

        indptr, indices, _ = self._parts
        return lambda r, out: incomplete_cholesky_solve(indptr, indices, self._values, self._diagonal, r, out)


def aggregation_levels(
    A: sp.csr_matrix, *, max_levels: int = 10, omega: float = 4.0 / 3.0, theta: float | None = None
) -> tuple:
    """Smoothed-aggregation levels ``[(A, R, P), ...]`` and the coarsest level's LU.

    pyamg's aggregation and tentative prolongator with the constant as near-null space, improved by four
    symmetric Gauss-Seidel sweeps on ``A x = 0``; each level aggregates on ``A``'s strong entries
    (``|a_ij| >= theta sqrt(|a_ii a_jj|)``, the weak ones lumped onto the diagonal: ``A_F``) and smooths
    ``P = (I - omega D^-1 A_F) T`` with ``D`` the rows' absolute sums (a local Gershgorin bound).
    """
    from pyamg.aggregation.aggregate import standard_aggregation
    from pyamg.aggregation.tentative import fit_candidates

    from .._block_kernel import gauss_seidel, strong_part

    theta = tuning.STRENGTH if theta is None else theta
    candidate, zero, finest = np.ones((A.shape[0], 1)), np.zeros((A.shape[0], 1)), csr_parts(A)
    for _ in range(4):
        gauss_seidel(*finest, candidate, zero, True, sweep_blocks(A))
        gauss_seidel(*finest, candidate, zero, False, sweep_blocks(A))
    levels: list[tuple[sp.csr_matrix, sp.csr_matrix, sp.csr_matrix]] = []
    while len(levels) + 1 < max_levels and A.shape[0] > tuning.COARSE_UNKNOWNS:
        strong = sp.csr_matrix(strong_part(*csr_parts(A), theta)[::-1], shape=A.shape)
        aggregates = standard_aggregation(strong)[0]
        if aggregates.nnz == 0:  # no entry off the diagonal is strong: this level is the coarsest
            break
        tentative, candidate = fit_candidates(aggregates, candidate)
        counts = np.diff(strong.indptr)
        first = np.minimum(strong.indptr[:-1], max(strong.nnz - 1, 0))
        absolute = np.add.reduceat(np.abs(strong.data), first)
        absolute[counts == 0] = 0.0
        step = np.divide(omega, absolute, out=np.zeros(len(absolute)), where=absolute != 0)
        strong.data *= np.repeat(step, counts)  # omega D^-1 A_F, in the filtered copy's own values
        tentative = sp.csr_matrix(tentative)
        P = (tentative - strong @ tentative).tocsr()
        del strong
        R = P.T.tocsr()
        coarse = (R @ (A @ P)).tocsr()
        coarse.sort_indices()
        levels.append((A, R, P))
        A = coarse
    return levels, splu_spd(A.tocsc())


def sweep_blocks(A: sp.spmatrix) -> int:
    """Blocks of the hybrid Gauss-Seidel sweeps: set by the size alone, so results do not depend on threads."""
    return int(np.clip(A.shape[0] // tuning.ROWS_PER_SWEEP_BLOCK, 1, tuning.SWEEP_BLOCKS))


class VCycle:
    """One V-cycle of :func:`aggregation_levels` on a whole ``(n, k)`` block: a forward Gauss-Seidel sweep
    before the coarse correction, a backward one after (symmetric, as CG needs).

    ``cycle(r)`` returns a new block; :meth:`bound` gives ``apply(r, out)`` with the levels' work blocks
    allocated once for a solve's every iteration. The object holds no block: threads may share it.
    """

    def __init__(self, levels: list, coarse: Any) -> None:
        self._operators = [(csr_parts(A), sweep_blocks(A), csr_parts(R), csr_parts(P)) for A, R, P in levels]
        self._coarse = coarse

    def __call__(self, r: np.ndarray) -> np.ndarray:
        r = np.ascontiguousarray(r, dtype=np.float64)
        out = np.empty_like(r)
        self.bound(r.shape[1])(r, out)
        return out

    def bound(self, k: int) -> Any:
        """``apply(r, out)``: one cycle of C-ordered ``(n, k)`` ``r`` into ``out``, reusing its work blocks."""
        from .._block_kernel import block_product, gauss_seidel

        # per level: its residual, the next level's right-hand side and solution
        work = [
            (np.empty((len(A[0]) - 1, k)), np.empty((len(R[0]) - 1, k)), np.empty((len(R[0]) - 1, k)))
            for A, _, R, _ in self._operators
        ]

        def cycle(depth: int, b: np.ndarray, x: np.ndarray) -> None:
            if depth == len(self._operators):
                x[...] = self._coarse.solve(np.asfortranarray(b))
                return
            (A, blocks, R, P), (residual, coarse_b, coarse_x) = self._operators[depth], work[depth]
            x.fill(0.0)
            gauss_seidel(*A, x, b, True, blocks)
            block_product(*A, x, residual, -1.0, b)  # b - A x in one pass
            block_product(*R, residual, coarse_b)
            cycle(depth + 1, coarse_b, coarse_x)
            block_product(*P, coarse_x, x, 1.0, x)  # x += P correction in one pass
            gauss_seidel(*A, x, b, False, blocks)

        return lambda r, out: cycle(0, r, out)


def block_cg(
    matrix: sp.csr_matrix,
    b: np.ndarray,
    x0: np.ndarray | None,
    precondition: Any,
    *,
    tol: float,
    max_iterations: int,
    progress: bool,
    reduction: float | None = None,
) -> tuple[np.ndarray, int, float]:
    """Preconditioned conjugate gradients on every column of ``b`` at once (one sparse product per step).

    Column ``j`` stops when ``||D^-1 r_j|| <= max(tol ||D^-1 b_j||, reduction ||D^-1 r_j^0||)``, ``D`` the
    diagonal of ``matrix``: each row's residual as the step it asks of its unknown (Jacobi's), so that rows
    of large weight (an LS mesh's heavy controls) do not drown the others, which a plain ``||b||`` lets
    pass at the start. Returns the solution, the iteration count and the largest relative residual.
    """
    from .._block_kernel import block_product, cg_direction, cg_step, column_dots, empty_small_pages

    vector = b.ndim == 1
    B = np.ascontiguousarray(b[:, None] if vector else b, dtype=np.float64)

    # work blocks on small pages: huge-page faults cost more system time than they save (constrained_fairing.rst)
    def block(like: Any) -> np.ndarray:
        out = empty_small_pages(B.shape)
        np.copyto(out, like)
        return out

    X = block(0.0 if x0 is None else np.reshape(x0, B.shape))
    diagonal = matrix.diagonal()
    weight = 1.0 / np.where(diagonal > 0, diagonal, 1.0)  # (a diagonal not positive fails below)

    def norm(block: np.ndarray) -> np.ndarray:  # the columns' ||D^-1 .||, by the kernel's one pass
        weighted = np.ascontiguousarray(block * weight[:, None])
        return np.sqrt(column_dots(weighted, weighted))

    norms = norm(B)
    scale = np.where(norms > 0, norms, 1.0)
    parts = csr_parts(matrix)
    R = block(B)
    start = norms
    if x0 is not None:
        block_product(*parts, X, R, -1.0, B)  # B - A X in one pass
        start = norm(R)
        # a start farther from the solution than zero (e.g. controls moved far from the mesh) is dropped
        worse = start > norms
        if worse.any():
            X[:, worse] = 0.0
            R[:, worse] = B[:, worse]
            start = np.where(worse, norms, start)
    relative = start / scale
    relative[norms == 0] = 0.0
    # each column's stopping point as a relative residual
    limit = np.full(B.shape[1], tol) if reduction is None else np.maximum(tol, reduction * relative)
    if norms.size and not (norms > 0).any():
        return (np.zeros_like(b), 0, 0.0)
    # the bar counts the decades the worst column's residual falls to its stopping point
    bar = Progress(progress, "conjugate gradients").decades(float((relative / limit).max()))
    if hasattr(precondition, "bound"):  # work blocks allocated once for the solve
        apply = precondition.bound(B.shape[1])
    else:
        apply = lambda r, out: np.copyto(out, precondition(r))
    Z, Q = block(0.0), empty_small_pages(B.shape)
    apply(R, Z)
    P = block(Z)
    rz = column_dots(R, Z)
    iteration = 0
    try:
        while (relative > limit).any():
            if iteration >= max_iterations:
                raise ConvergenceError(
                    f"conjugate gradients reached relative residual {relative.max():.3g} after {iteration} "
                    f"iterations, tolerance {tol:g}: raise max_iterations or tol, or use solver='cholmod'"
                )
            block_product(*parts, P, Q)
            pq = column_dots(P, Q)
            active = relative > limit
            if (pq[active] <= 0).any():
                raise SingularSystemError(
                    "matrix must be positive definite: conjugate gradients met a direction of non-positive "
                    "curvature"
                )
            alpha = np.where(active, rz / np.where(active, pq, 1.0), 0.0)
            relative = np.sqrt(cg_step(X, R, P, Q, alpha, weight)) / scale  # one pass, no temporaries
            relative[norms == 0] = 0.0
            iteration += 1
            bar.reached(float((relative / limit).max()), f"residual={relative.max():.2e}, {iteration} it")
            apply(R, Z)
            rz_new = column_dots(R, Z)
            beta = np.where(active, rz_new / np.where(rz != 0, rz, 1.0), 0.0)
            cg_direction(P, Z, beta)
            rz = rz_new
        bar.finish()
    finally:
        bar.close()
    if not np.isfinite(X).all():
        raise SingularSystemError("conjugate gradients diverged: the matrix is not positive definite")
    return (X[:, 0] if vector else X), iteration, float(relative.max(initial=0.0))

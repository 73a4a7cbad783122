"""The solve gateway's options and direct-path helpers: :class:`Plan`, backends, SuperLU with Woodbury
updates, the checks of a system (finite, symmetric, constant modes pinned), the factor's memory model.

Private to :mod:`~o3d_lsmesh.core.solve`, which re-exports the public names. Constants:
:mod:`~o3d_lsmesh.core.tuning`.
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.linalg import cho_solve, solve_triangular
from scipy.sparse import csgraph

from . import tuning
from ._iterative import csr_parts
from .errors import InputError, InputTypeError
from .validate import as_choice, check_finite

ORDERINGS = ("default", "nesdis", "metis", "amd", "colamd", "natural")
#: What the public functions take as ``solver=`` (``constrained_fairing``, ``ls_mesh``, ...).
SOLVERS = ("auto", "cholmod", "iterative")
#: What :class:`SPDSolver` and the public functions take as ``backend=``.
BACKENDS = ("auto", "cholmod", "scipy", "iterative")
#: The iterative path's preconditioners (:attr:`Plan.preconditioner`).
PRECONDITIONERS = ("amg", "ic0")


def solver_backend(solver: Any, backend: str = "auto") -> str:
    """The :class:`SPDSolver` backend for a ``solver=`` option (``"auto"`` defers to ``backend``); a
    factorization asked of one and conjugate gradients of the other is refused, not settled silently."""
    solver = as_choice(solver, SOLVERS, name="solver")
    both = isinstance(backend, str) and "auto" not in (solver, backend)  # (backend checked by SPDSolver)
    if both and "iterative" in (solver, backend) and solver != backend:
        raise InputError(
            f"solver={solver!r} contradicts backend={backend!r}: give one of them", param="solver"
        )
    return backend if solver == "auto" else solver


@dataclass(frozen=True, eq=False)
class Plan:
    """How an :class:`SPDSolver` is built beyond its matrix: the package's own callers' plumbing (``_plan=``).

    ``product_of`` ``(n, k)``: factor ``A A^T`` for this ``A`` without forming it (``matrix=None``;
    updates append their columns to ``A``). ``pattern_of`` ``(n, k)``: CHOLMOD analyzes the pattern of
    ``A A^T`` for this ``A`` (it must hold the matrix's). ``locality_of`` ``(n, n)``: a sparser symmetric
    matrix with the same neighbourhoods, whose reverse Cuthill-McKee order the iterative path takes.
    ``preconditioner`` (:data:`PRECONDITIONERS`): the iterative path's (``"ic0"`` falls back to the
    V-cycle where its set-up would be superlinear). ``reduction``: CG also stops a column once its
    residual is this fraction of its residual at ``x0``. ``memory_budget``: bytes a direct factor may
    take under ``backend="auto"`` (default :func:`default_memory_budget`).
    """

    product_of: Any = None
    pattern_of: Any = None
    locality_of: Any = None
    preconditioner: str = "amg"
    reduction: float | None = None
    memory_budget: int | None = None


def single_threaded_blas() -> Any:
    """BLAS limited to one thread in a ``with`` block, if threadpoolctl is installed (memory-bound BLAS
    and SuperLU's many-column solves ran slower with threads on busy cores)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # optional: without it the BLAS keeps its own thread count
        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


class Woodbury:
    """A kept ``splu`` of ``B`` solving ``B + C C^T`` by Woodbury's identity (the SciPy path's updates)::

        (B + C C^T)^-1 b = y + Z (I + C^T Z)^-1 (d - C^T y),   y = B^-1 (b - C d),   Z = B^-1 C

    with ``d`` zeroing ``b - C d`` on each column's pivot row (docs/algorithms/solvers.rst); the
    capacitance's Cholesky factor grows a block per update. The owner refactors once :attr:`work` (the
    correction's multiply-adds) reaches :attr:`factor_work` (a factorization's).
    """

    def __init__(self, lu: Any) -> None:
        self._lu = lu
        self.factor_work = self._solve_work = 0.0  # counted at the first update (reading L copies it)
        n = lu.shape[0]
        self._columns = sp.csc_matrix((n, 0))
        self._pivots, self._entries, self._shares = np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0)
        self._z = np.empty((n, 0), order="F")  # capacity doubles: Z is its leading columns
        self._rank = 0  # columns with their Z and capacitance rows
        self._cholesky = np.empty((0, 0))
        self._basis, self._solved = np.zeros((n, 0)), np.zeros((n, 0))  # see _recycle
        self.work = 0.0

    def affords(self, columns: int) -> bool:
        """Whether ``columns`` more columns keep the correction's work below a refactorization's."""
        if not self.factor_work:
            lower = self._lu.L
            self.factor_work = float(np.sum(np.diff(lower.indptr).astype(np.float64) ** 2))
            self._solve_work = float(lower.nnz + self._lu.U.nnz)
        return self.work + columns * self._solve_work < self.factor_work

    def add(self, c: sp.csc_matrix) -> None:
        rows = np.asarray(abs(c).argmax(axis=0)).ravel()
        self._pivots = np.concatenate([self._pivots, rows])
        self._entries = np.concatenate([self._entries, np.asarray(c[rows, np.arange(c.shape[1])]).ravel()])
        # d_j = e_j b_r / sum of e^2 over the columns pivoting on row r (entries e_j at their pivot rows)
        squares = np.bincount(self._pivots, weights=self._entries**2)[self._pivots]
        self._shares = np.divide(self._entries, squares, out=np.zeros_like(squares), where=squares > 0)
        self._columns = sp.hstack([self._columns, c], format="csc")
        self.work += c.shape[1] * self._solve_work

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``(B + C C^T)^-1 b`` for an ``(n,)`` or ``(n, m)`` ``b``; ``numpy.linalg.LinAlgError`` if the
        capacitance is not numerically SPD (the owner refactors)."""
        with single_threaded_blas():  # SuperLU's small supernodal BLAS calls, Z's thin products
            return self._solve(b)

    def _solve(self, b: np.ndarray) -> np.ndarray:
        vector = b.ndim == 1
        b = b[:, None] if vector else b
        k, m, C = self._rank, b.shape[1], self._columns
        d = self._shares[:, None] * b[self._pivots]
        rest = b - C @ d
        # only the part of rest outside the span of the right-hand sides solved before needs a solve
        coefficients = self._basis.T @ rest
        residual = rest - self._basis @ coefficients
        fresh = np.linalg.norm(residual, axis=0) > tuning.RECYCLE_TOLERANCE * np.linalg.norm(rest, axis=0)
        new, f = C[:, k:], int(fresh.sum())
        rhs = np.empty((len(b), f + new.shape[1]), order="F")
        rhs[:, :f] = residual[:, fresh]
        rhs[:, f:] = new.toarray()
        solved = self._lu.solve(rhs)
        y = self._solved @ coefficients
        y[:, fresh] += solved[:, :f]
        self._recycle(rhs[:, :f], solved[:, :f])
        if new.shape[1]:
            self._extend(new, solved[:, f:])
        if self._rank:
            self.work += m * self._rank * (y.shape[0] + self._rank)
            y = y + self._z[:, : self._rank] @ cho_solve((self._cholesky, True), d - C.T @ y)
        return y[:, 0] if vector else y

    def _recycle(self, residual: np.ndarray, solved: np.ndarray) -> None:
        """Extend the orthonormal basis of solved right-hand sides (and their solutions) by ``residual``'s
        columns, orthogonalized again, each only if at least half of it is new (the solution of what is
        left after a cancellation would lose the digits it cancelled); a full basis starts afresh."""
        for r, x in zip(residual.T, solved.T):
            if self._basis.shape[1] >= tuning.RECYCLED:
                self._basis, self._solved = self._basis[:, :0], self._solved[:, :0]
            projection = self._basis.T @ r
            length = np.linalg.norm(r)
            r, x = r - self._basis @ projection, x - self._solved @ projection
            norm = np.linalg.norm(r)
            if norm > 0 and norm >= 0.5 * length:
                self._basis = np.column_stack([self._basis, r / norm])
                self._solved = np.column_stack([self._solved, x / norm])

    def _extend(self, new: sp.csc_matrix, z: np.ndarray) -> None:
        k, a = self._rank, new.shape[1]
        corner = np.eye(a) + new.T @ z
        corner = (corner + corner.T) / 2.0
        block = np.zeros((k + a, k + a))
        block[:k, :k] = self._cholesky
        if k:
            # [[L, 0], [M, N]] with L M^T = C_old^T Z_new and N N^T = corner - M M^T
            below = solve_triangular(self._cholesky, self._columns[:, :k].T @ z, lower=True).T
            corner -= below @ below.T
            block[k:, :k] = below
        block[k:, k:] = np.linalg.cholesky(corner)
        if k + a > self._z.shape[1]:
            grown = np.empty((len(z), max(2 * self._z.shape[1], k + a)), order="F")
            grown[:, :k] = self._z[:, :k]
            self._z = grown
        self._z[:, k : k + a] = z
        self._cholesky, self._rank = block, k + a


def available_memory() -> int:
    """Bytes of memory available to new allocations (``MemAvailable`` on Linux)."""
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return 8 << 30


def default_memory_budget() -> int:
    """Bytes a direct factor may take under ``backend="auto"``: :data:`~o3d_lsmesh.core.tuning.BUDGET_FRACTION`
    of the available memory, or ``O3D_LSMESH_MEMORY_BUDGET`` (bytes, or with a ``K``/``M``/``G`` suffix)."""
    text = os.environ.get("O3D_LSMESH_MEMORY_BUDGET", "").strip().upper()
    if text:
        factor = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30}.get(text[-1], 1)
        number = text[:-1] if factor > 1 else text
        try:
            return int(float(number) * factor)
        except ValueError as error:
            raise InputError(
                f"O3D_LSMESH_MEMORY_BUDGET must be a number of bytes such as 8G, got {text!r}"
            ) from error
    return int(tuning.BUDGET_FRACTION * available_memory())


def estimate_factor_bytes(n: int, nnz: int) -> float:
    """Peak memory of a CHOLMOD factor of an ``(n, n)`` mesh system with ``nnz`` entries: ``O(n log n)``
    fill (:data:`~o3d_lsmesh.core.tuning.FILL_PER_ROW_LOG`), 8 bytes an entry, 1.5 for the workspace."""
    if n <= 1:
        return float(nnz) * 16.0
    per_row = max(nnz / n, 1.0)
    factor_entries = tuning.FILL_PER_ROW_LOG * per_row / 19.0 * n * np.log2(n)
    return 1.5 * 8.0 * factor_entries


def operator_scale(operator: sp.spmatrix) -> float:
    """``max diag(L^T L)``, a lower bound on ``||L^T L||_2``: the scale a penalty is negligible against."""
    csr = sp.csr_matrix(operator)  # no copy of a CSR operator
    if csr.nnz == 0:
        return 0.0
    return float(np.bincount(csr.indices, weights=csr.data**2, minlength=csr.shape[1]).max())


def check_constant_modes(
    ones_product: np.ndarray,
    labels: np.ndarray,
    *,
    scale: float,
    name: str,
    value: Any,
    what: str = "the constraints",
    vertex_of: np.ndarray | None = None,
) -> None:
    """Raise :class:`InputError` naming ``name`` if a penalty leaves a component's translation undetermined.

    For ``N = L^T L + P`` with ``L 1_c = 0`` on each component ``c``, only ``P`` makes
    ``q_c = 1_c^T N 1_c / n_c`` positive; round-off moves the solution along ``1_c`` by
    ``eps ||L^T L|| / q_c``. Raises when ``q_c < NEGLIGIBLE * scale``. ``ones_product (u,)``: ``N @ 1``
    (summed over ``c``: ``1_c^T N 1_c``); ``labels (u,)``: each unknown's component; ``scale``: ``||L^T L||``
    (:func:`operator_scale` of ``L``); ``name``, ``value``, ``what``, ``vertex_of (u,)`` (each unknown's
    vertex, when some are known): the message's words.
    """
    labels = np.asarray(labels)
    if labels.size == 0 or not scale > 0:
        return
    check_finite(ones_product, name=name, what="the system's entries")
    sizes = np.bincount(labels)
    quotient = np.bincount(labels, weights=ones_product, minlength=len(sizes)) / np.maximum(sizes, 1)
    weak = (sizes > 0) & (quotient < tuning.NEGLIGIBLE * scale)
    if weak.any():
        worst = int(np.argmin(np.where(sizes > 0, quotient, np.inf)))
        vertex = int(np.flatnonzero(labels == worst)[0])
        vertex = vertex if vertex_of is None else int(vertex_of[vertex])
        raise InputError(
            f"{name} is too small: {what} must pin every connected component, got {name}={_short(value)}, "
            f"which leaves {int(weak.sum())} component(s) (the first with vertex {vertex}) held with strength "
            f"{quotient[worst]:.3g}, {quotient[worst] / scale:.2g} of the smoothness term "
            f"(need >= {tuning.NEGLIGIBLE:g}): the solution would drift by round-off; increase {name}",
            param=name,
        )


def check_weight_pins_components(operator: sp.spmatrix, weight: float, *, name: str) -> None:
    """:func:`check_constant_modes` for a scalar weight ``w`` of ``||L x||^2 + w^2 sum_a |x_a - c_a|^2`` with
    one anchor per component at least (``q_c = w^2 / n_c``); also rejects ``w`` whose square overflows."""
    check_finite(lambda: np.asarray([weight], dtype=np.float64) ** 2, name=name, what=f"{name}**2")
    labels = csgraph.connected_components(operator, directed=False)[1]
    pinned = np.zeros(operator.shape[0])
    pinned[np.unique(labels, return_index=True)[1]] = float(weight) ** 2
    check_constant_modes(
        pinned, labels, scale=operator_scale(operator), name=name, value=weight, what="the anchor weight"
    )


def _short(value: Any) -> str:
    array = np.asarray(value)
    if array.ndim == 0 or array.size == 1:
        return f"{float(array.ravel()[0]):g}"
    return f"array of {array.size} (min {array.min():g})"


def check_symmetric(csc: sp.csc_matrix, *, lower: bool, name: str = "matrix") -> None:
    """Raise unless the canonical ``csc`` is symmetric within :data:`~o3d_lsmesh.core.tuning.SYMMETRY_TOLERANCE`
    (with ``lower``: has no entry above the diagonal): CHOLMOD reads one triangle, LU and CG the whole."""
    from .._block_kernel import symmetry_gap

    gap, i, j, above = symmetry_gap(*csr_parts(csc.T))  # CSC arrays, read in place
    if lower and above:
        raise InputError(
            f"{name} must hold only its lower triangle with lower=True, got {above} entries above the diagonal",
            param=name,
        )
    largest = max(csc.data.max(initial=0.0), -csc.data.min(initial=0.0))
    if not lower and gap > tuning.SYMMETRY_TOLERANCE * largest:
        i, j = min(i, j), max(i, j)
        raise InputError(
            f"{name} must be symmetric, got a[{i}, {j}] = {csc[i, j]:g} against a[{j}, {i}] = {csc[j, i]:g} "
            "(pass only its lower triangle with lower=True if that is what it means)",
            param=name,
        )


def symmetric_from_lower(lower: sp.csc_matrix) -> sp.csc_matrix:
    strict = sp.tril(lower, k=-1)
    full = (lower + strict.T).tocsc()
    full.sort_indices()
    return full


def stored(csc: sp.csc_matrix, *, given_lower: bool, keep_lower: bool) -> sp.csc_matrix:
    """The form an :class:`SPDSolver` keeps: the lower triangle for CHOLMOD, the whole matrix otherwise."""
    if keep_lower:
        stored = csc if given_lower else sp.tril(csc, format="csc")
    else:
        stored = symmetric_from_lower(csc) if given_lower else csc
    stored.sort_indices()
    return stored


def check_numbers(tol: Any, reduction: Any, max_iterations: Any, memory_budget: Any) -> None:
    """Raise :class:`InputError` naming the first of :class:`~o3d_lsmesh.core.solve.SPDSolver`'s numbers out of
    range (:class:`InputTypeError` when it is not a number)."""
    real, integer = (int, float, np.floating), (int, np.integer)
    bytes_ = (*integer, float)
    for name, value, types, rule, fits in (
        ("tol", tol, real, "a number in (0, 1)", lambda v: 0 < v < 1),
        ("reduction", reduction, real, "None or a number in (0, 1)", lambda v: 0 < v < 1),
        ("max_iterations", max_iterations, integer, "a positive integer", lambda v: v >= 1),
        ("memory_budget", memory_budget, bytes_, "a non-negative number of bytes", lambda v: v >= 0),
    ):
        if value is None and name in ("reduction", "memory_budget"):
            continue
        if isinstance(value, bool) or not isinstance(value, types):
            raise InputTypeError(f"{name} must be {rule}, got {value!r}", param=name)
        if not fits(value):
            raise InputError(f"{name} must be {rule}, got {value!r}", param=name)


def nonfinite_blocks(matrix: sp.csr_matrix, rhs: np.ndarray) -> np.ndarray | None:
    """Rows of the connected blocks of ``matrix`` free of non-finite entries (in it or in their ``(n, k)``
    ``rhs`` rows), or None when every entry is finite."""
    bad = ~np.isfinite(rhs).all(axis=1)
    bad[np.repeat(np.arange(matrix.shape[0]), np.diff(matrix.indptr))[~np.isfinite(matrix.data)]] = True
    if not bad.any():
        return None
    _, label = csgraph.connected_components(matrix, directed=False)
    return ~np.isin(label, label[bad])

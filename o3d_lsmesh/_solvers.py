"""The CHOLMOD gateway: the only module that imports ``sksparse.cholmod``.

:class:`SPDSolver` factors a sparse SPD matrix once, solves ``(n, k)``
right-hand sides in one call, refactors reusing the symbolic analysis and
applies rank-k updates (SciPy's ``splu`` and a low-rank correction without
scikit-sparse or with ``O3D_LSMESH_NO_CHOLMOD=1``; conjugate gradients preconditioned by an AMG
V-cycle or an incomplete Cholesky factor above a memory budget).
:func:`check_constant_modes` and :func:`check_finite` keep an ill-posed system
from giving a wrong answer silently.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import sys
import threading
import warnings
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ._errors import ConvergenceError, O3DLSMeshWarning, SingularSystemError
from ._progress import decades_bar
from ._validate import as_choice

__all__ = [
    "BACKENDS",
    "DEFAULT_TOLERANCE",
    "ORDERINGS",
    "PRECONDITIONERS",
    "SOLVERS",
    "SPDSolver",
    "check_constant_modes",
    "check_finite",
    "check_weight_pins_components",
    "cholmod_available",
    "default_memory_budget",
    "estimate_factor_bytes",
    "gram_matrix",
    "operator_scale",
    "solver_backend",
]

ORDERINGS = ("default", "nesdis", "metis", "amd", "colamd", "natural")
#: What the public functions take as ``solver=``.
SOLVERS = ("auto", "cholmod", "iterative")
#: What :class:`SPDSolver` takes as ``backend=``.
BACKENDS = ("auto", "cholmod", "scipy", "iterative")
#: What :class:`SPDSolver` takes as ``preconditioner=`` for its iterative path.
PRECONDITIONERS = ("amg", "ic0")
#: Relative residual ``||b - A x|| / ||b||`` at which conjugate gradients stop, per column: within
#: 3e-8 of CHOLMOD's solution at 200k and 1M vertices (LS meshes, 2% controls; 1e-10: 3e-9 for 20%
#: more iterations; 1e-8: 3e-7), well inside the documented 1e-6.
DEFAULT_TOLERANCE = 1e-9
#: Fraction of the available memory that the factor may take under ``backend="auto"``.
BUDGET_FRACTION = 0.5
#: A component whose constant mode has a Rayleigh quotient below this fraction of ``||L^T L||``
#: is not determined by the system in float64: round-off of size eps ||L^T L|| |x| moves it by
#: more than 1e-6 of |x|.
NEGLIGIBLE = 1e-10
NO_CHOLMOD_ENV = "O3D_LSMESH_NO_CHOLMOD"


def _cholmod_disabled() -> bool:
    """Whether the user chose the SciPy path with ``O3D_LSMESH_NO_CHOLMOD=1`` (``make test``'s second pass)."""
    return os.environ.get(NO_CHOLMOD_ENV, "").strip().lower() not in ("", "0", "false", "no")


def _import_cholmod():
    if _cholmod_disabled():
        return None
    try:
        # ``import sksparse`` alone does not load the submodule: import it by name.
        return importlib.import_module("sksparse.cholmod")
    except ImportError:
        return None


_cholmod = _import_cholmod()


def cholmod_available() -> bool:
    """Whether scikit-sparse's CHOLMOD can be imported."""
    return _cholmod is not None


def solver_backend(solver: Any, backend: str = "auto") -> str:
    """The :class:`SPDSolver` backend for a public function's ``solver=`` (and older ``backend=``) option.

    ``solver="auto"`` defers to ``backend`` (itself ``"auto"`` by default:
    CHOLMOD or SciPy below the memory budget, iterative above it).
    """
    solver = as_choice(solver, SOLVERS, name="solver")
    return backend if solver == "auto" else solver


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
    """Bytes a direct factor may take under ``backend="auto"``: half of the available memory.

    ``O3D_LSMESH_MEMORY_BUDGET`` (bytes, or with a ``K``/``M``/``G`` suffix) overrides it.
    """
    text = os.environ.get("O3D_LSMESH_MEMORY_BUDGET", "").strip().upper()
    if text:
        factor = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30}.get(text[-1], 1)
        number = text[:-1] if factor > 1 else text
        try:
            return int(float(number) * factor)
        except ValueError as error:
            raise ValueError(
                f"O3D_LSMESH_MEMORY_BUDGET must be a number of bytes such as 8G, got {text!r}"
            ) from error
    return int(BUDGET_FRACTION * available_memory())


def estimate_factor_bytes(n: int, nnz: int) -> float:
    """Measured model of the peak memory of a CHOLMOD factor of an ``(n, n)`` mesh system with ``nnz`` entries.

    Mesh graphs give ``O(n log n)`` fill: :data:`_FILL_PER_ROW_LOG` factor entries per ``n log2 n``
    at 19 entries a row (LS-mesh normal matrices), scaled by the entries per row; 8 bytes each,
    times 1.5 for CHOLMOD's workspace (measured peak at 200k: 440 MB, model 460 MB).
    """
    if n <= 1:
        return float(nnz) * 16.0
    per_row = max(nnz / n, 1.0)
    factor_entries = _FILL_PER_ROW_LOG * per_row / 19.0 * n * np.log2(n)
    return 1.5 * 8.0 * factor_entries


# nnz(L) / (n log2 n) of CHOLMOD's factor of LS-mesh normal matrices on torus grids: 12.8 at 20k vertices,
# 10.1 at 80k, 10.8 at 500k (benchmarks/results/scale.md); 2.6 GB at 1M, 31 GB at 10M.
_FILL_PER_ROW_LOG = 11.0


def operator_scale(operator: sp.spmatrix) -> float:
    """``max_j ||L e_j||^2 = max diag(L^T L)``: a lower bound on ``||L^T L||_2`` within the row count factor.

    The scale against which a penalty is negligible (:func:`check_constant_modes`).
    """
    csr = sp.csr_matrix(operator)  # no copy of a CSR operator (a CSC copy of a 10M-row one took 1.6 s)
    if csr.nnz == 0:
        return 0.0
    return float(np.bincount(csr.indices, weights=csr.data**2, minlength=csr.shape[1]).max())


def check_finite(values: Any, *, name: str, what: str) -> None:
    """Raise ``ValueError`` naming ``name`` when ``values`` (something built from it) holds inf or NaN.

    ``values`` may be a callable, run with overflow warnings off (the overflow is what this reports).
    """
    if callable(values):
        with np.errstate(over="ignore", invalid="ignore"):
            values = values()
    finite = np.isfinite(values)
    if not finite.all():
        first = int(np.flatnonzero(~finite.ravel())[0])
        raise ValueError(
            f"{name} must be small enough that {what} is finite, got {np.ravel(values)[first]} "
            f"(overflow) at entry {first}"
        )


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
    """Raise ``ValueError`` naming ``name`` if a penalty leaves a component's translation undetermined.

    For ``N = L^T L + P`` with ``L 1_c = 0`` on each component ``c``, only ``P`` makes the
    Rayleigh quotient ``q_c = 1_c^T N 1_c / n_c`` positive; round-off of ``eps ||L^T L||`` moves
    the solution along ``1_c`` by ``eps ||L^T L|| / q_c`` (a translated sphere solved with
    ``weights=1e-8`` lands at the origin). Raises when ``q_c < NEGLIGIBLE * scale``.

    Parameters
    ----------
    ones_product : (u,) float array
        ``N @ 1`` (components are diagonal blocks, so ``1_c^T N 1_c`` is its sum over ``c``).
    labels : (u,) int array
        Connected component of each unknown.
    scale : float
        ``||L^T L||``, e.g. :func:`operator_scale` of ``L``: the smoothness term only,
        so that huge weights (a near-interpolatory system, well posed) pass.
    name, value
        The caller's parameter and its value, for the message.
    vertex_of : (u,) int array, optional
        The mesh vertex of each unknown (when some vertices are known), for the message.
    """
    labels = np.asarray(labels)
    if labels.size == 0 or not scale > 0:
        return
    check_finite(ones_product, name=name, what="the system's entries")
    sizes = np.bincount(labels)
    quotient = np.bincount(labels, weights=ones_product, minlength=len(sizes)) / np.maximum(sizes, 1)
    weak = (sizes > 0) & (quotient < NEGLIGIBLE * scale)
    if weak.any():
        worst = int(np.argmin(np.where(sizes > 0, quotient, np.inf)))
        vertex = int(np.flatnonzero(labels == worst)[0])
        vertex = vertex if vertex_of is None else int(vertex_of[vertex])
        raise ValueError(
            f"{name} is too small: {what} must pin every connected component, got {name}={_short(value)}, "
            f"which leaves {int(weak.sum())} component(s) (the first with vertex {vertex}) held with strength "
            f"{quotient[worst]:.3g}, {quotient[worst] / scale:.2g} of the smoothness term (need >= {NEGLIGIBLE:g}): "
            f"the solution would drift by round-off; increase {name}"
        )


def check_weight_pins_components(operator: sp.spmatrix, weight: float, *, name: str) -> None:
    """Check a scalar weight ``w`` of ``||L x||^2 + w^2 sum_a |x_a - c_a|^2`` with one anchor per component at least.

    The weakest case of :func:`check_constant_modes` (``q_c = w^2 / n_c``), for callers that
    choose the anchors later; also rejects ``w`` whose square overflows.
    """
    from scipy.sparse import csgraph

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


def _as_csc(matrix: Any, *, name: str = "matrix", square: bool = True) -> sp.csc_matrix:
    """``matrix`` as canonical float64 CSC (sorted, summed) with CHOLMOD's 32-bit indices where they fit.

    The caller's arrays are not touched: a non-canonical matrix is copied first.
    """
    if not sp.issparse(matrix):
        raise TypeError(f"{name} must be a scipy sparse matrix, got {type(matrix).__name__}")
    if square and matrix.shape[0] != matrix.shape[1]:
        raise ValueError(f"{name} must be square, got shape {matrix.shape}")
    if matrix.dtype.kind not in "biuf":
        raise TypeError(f"{name} must have real entries, got {matrix.dtype}")
    csc = sp.csc_matrix(matrix, dtype=np.float64)
    if not np.isfinite(csc.data).all():
        first = int(np.flatnonzero(~np.isfinite(csc.data))[0])
        raise ValueError(
            f"{name} must have finite entries, got {csc.data[first]} (an overflowing weight or a NaN input?)"
        )
    if not csc.has_canonical_format:
        csc = csc.copy()
        csc.sum_duplicates()
    if csc.indices.dtype != np.int32 and max(csc.nnz, *csc.shape) < np.iinfo(np.int32).max:
        # CHOLMOD's int interface: the long one would copy and store 64-bit indices
        csc = sp.csc_matrix(
            (csc.data, csc.indices.astype(np.int32), csc.indptr.astype(np.int32)), shape=csc.shape
        )
    return csc


#: Largest ``|a_ij - a_ji|``, relative to the largest entry, that :class:`SPDSolver` takes as symmetric: an
#: assembled normal matrix's round-off (1e-16 of its entries) passes, a wrong entry does not.
SYMMETRY_TOLERANCE = 1e-10


def _check_symmetric(csc: sp.csc_matrix, *, lower: bool, name: str = "matrix") -> None:
    """Raise ``ValueError`` naming ``name`` unless the canonical ``csc`` is symmetric within
    :data:`SYMMETRY_TOLERANCE` (with ``lower``: has no entry above the diagonal). CHOLMOD reads one
    triangle, SciPy's LU and CG the whole: an unsymmetric matrix gave each a different wrong answer."""
    from . import _block_kernel  # compiled by the package's build: imported where used

    gap, i, j, above = _block_kernel.symmetry_gap(*_csr_parts(csc.T))  # CSC arrays, read in place
    if lower and above:
        raise ValueError(
            f"{name} must hold only its lower triangle with lower=True, got {above} entries above the diagonal"
        )
    largest = max(csc.data.max(initial=0.0), -csc.data.min(initial=0.0))
    if not lower and gap > SYMMETRY_TOLERANCE * largest:
        i, j = min(i, j), max(i, j)
        raise ValueError(
            f"{name} must be symmetric, got a[{i}, {j}] = {csc[i, j]:g} against a[{j}, {i}] = {csc[j, i]:g} "
            "(pass only its lower triangle with lower=True if that is what it means)"
        )


def _symmetric_from_lower(lower: sp.csc_matrix) -> sp.csc_matrix:
    strict = sp.tril(lower, k=-1)
    full = (lower + strict.T).tocsc()
    full.sort_indices()
    return full


def _stored(csc: sp.csc_matrix, *, given_lower: bool, keep_lower: bool) -> sp.csc_matrix:
    """The form an :class:`SPDSolver` keeps: the lower triangle for CHOLMOD, the whole matrix otherwise."""
    if keep_lower:
        stored = csc if given_lower else sp.tril(csc, format="csc")
    else:
        stored = _symmetric_from_lower(csc) if given_lower else csc
    stored.sort_indices()
    return stored


def _splu_spd(matrix: sp.csc_matrix) -> Any:
    """SuperLU set for an SPD matrix: a symmetric ordering of ``A + A^T`` and diagonal pivots.

    Partial pivoting (SciPy's default) abandons the fill-reducing ordering whenever an off-diagonal
    entry wins a pivot test (30-40x the time here); an SPD matrix needs no pivoting.
    """
    return spla.splu(
        matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
    )


#: A right-hand side within this relative distance of the span of those solved before is solved from
#: their solutions (a direct solve's own error is of the order of the condition number times 1e-16).
RECYCLE_TOLERANCE = 1e-13
#: Solved right-hand sides kept: greedy selection's span four (the controls' x, y and z about their
#: centroid, which moves as anchors arrive), so its solves after the first two are recycled.
RECYCLED = 8


def single_threaded_blas() -> Any:
    """BLAS limited to one thread in a ``with`` block, if threadpoolctl is installed.

    Memory-bound level-2 BLAS ran 10x slower with OpenBLAS threads on two busy cores (ARPACK, camel,
    k = 100: 22.5 s against 2.3 s); SuperLU's solves of several columns took up to 3.4x a single column's
    time per column with them, 0.35-0.8x without (bunny_scan, igea: benchmarks/results/no_cholmod.md).
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # optional: without it the BLAS keeps its own thread count
        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


class _Woodbury:
    """A kept ``splu`` of ``B`` solving ``B + C C^T`` (the SciPy path's rank-k updates; Woodbury's identity)::

        (B + C C^T)^-1 b = y + Z (I + C^T Z)^-1 (d - C^T y),   y = B^-1 (b - C d),   Z = B^-1 C

    exact for any ``d``: ``d`` is the least-norm one making ``b - C d`` zero on each column's largest
    entry's row (all of it for one-entry columns: anchors), so that ``y`` does not carry an anchor's
    ``w^2 c`` (with ``y = B^-1 b`` the terms of that size cancel: 2e-4 of the camel's size off at the
    bases paper's ``w = 10 n``, against 1e-14 this way; columns with large entries on several rows keep
    a backward error of about 1e-9 at entries 1e4 times the matrix's). The capacitance
    ``I + C^T Z`` (SPD) is held by its Cholesky factor, extended by a block per update; an update's
    columns are base-solved along with the next right-hand side, of which only the part outside the
    span of those solved before is solved (:meth:`_recycle`; one SuperLU call). :attr:`work`
    counts the multiply-adds the correction has cost (its columns' base solves, the products with
    ``Z``), :attr:`factor_work` those of the factorization (``sum_j |L_j|^2``): the owner refactors
    once the first reaches the second, at most twice the cost of the best fixed refactoring period.
    """

    def __init__(self, lu: Any) -> None:
        from scipy.linalg import cho_solve, solve_triangular

        self._lu, self._cho_solve, self._triangular = lu, cho_solve, solve_triangular
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
        fresh = np.linalg.norm(residual, axis=0) > RECYCLE_TOLERANCE * np.linalg.norm(rest, axis=0)
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
            y = y + self._z[:, : self._rank] @ self._cho_solve((self._cholesky, True), d - C.T @ y)
        return y[:, 0] if vector else y

    def _recycle(self, residual: np.ndarray, solved: np.ndarray) -> None:
        """Extend the orthonormal basis of solved right-hand sides (and their solutions) by ``residual``'s
        columns, orthogonalized again, each only if at least half of it is new (the solution of what is
        left after a cancellation would lose the digits it cancelled); a full basis starts afresh."""
        for r, x in zip(residual.T, solved.T):
            if self._basis.shape[1] >= RECYCLED:
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
            below = self._triangular(self._cholesky, self._columns[:, :k].T @ z, lower=True).T
            corner -= below @ below.T
            block[k:, :k] = below
        block[k:, k:] = np.linalg.cholesky(corner)
        if k + a > self._z.shape[1]:
            grown = np.empty((len(z), max(2 * self._z.shape[1], k + a)), order="F")
            grown[:, :k] = self._z[:, :k]
            self._z = grown
        self._z[:, k : k + a] = z
        self._cholesky, self._rank = block, k + a


_PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__))


def user_stacklevel() -> int:
    """The ``stacklevel`` that makes a warning point at the first caller outside o3d_lsmesh.

    A fixed ``stacklevel`` would be right for one call path only (``ls_mesh`` -> ``LSMeshSolver`` -> ...).
    """
    frame: Any = sys._getframe(1)  # the caller of user_stacklevel, i.e. the function that warns
    level = 1
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(_PACKAGE_DIR + os.sep):
        frame = frame.f_back
        level += 1
    return level


#: Whether this process has shown the SciPy fallback's warning (each solver would repeat it otherwise).
_fallback_warned = False


def _warn_fallback_once() -> None:
    global _fallback_warned
    if not _fallback_warned:
        _fallback_warned = True
        warnings.warn(
            "scikit-sparse is not importable; solving with scipy.sparse.linalg.splu, slower than CHOLMOD "
            f"(pip install 'o3d_lsmesh[cholmod]' for CHOLMOD, or set {NO_CHOLMOD_ENV}=1 to choose SciPy "
            "and silence this warning; shown once)",
            O3DLSMeshWarning,
            stacklevel=user_stacklevel(),
        )


def _not_a(value: Any, types: tuple[type, ...]) -> bool:
    return isinstance(value, bool) or not isinstance(value, types)


class SPDSolver:
    """Factor a sparse SPD matrix once and solve, refactor or update it.

    Parameters
    ----------
    matrix : (n, n) scipy sparse matrix or None
        Symmetric positive definite: the whole matrix, or only its lower
        triangle with ``lower=True`` (which lets the caller free the whole one).
        ``ValueError`` for a matrix farther from symmetric than
        :data:`SYMMETRY_TOLERANCE` of its largest entry, or with entries above
        the diagonal under ``lower=True``; ``TypeError`` for complex entries.
        ``None`` with ``product_of``.
    product_of : (n, k) scipy sparse matrix, optional, keyword-only
        Factor ``A A^T`` for this ``A`` without forming it (CHOLMOD assembles it
        while it factors: less memory and time). Updates append their columns to ``A``.
    backend : {"auto", "cholmod", "scipy", "iterative"}
        ``"auto"``: the iterative path when :func:`estimate_factor_bytes` exceeds
        ``memory_budget``, else CHOLMOD, else SciPy's ``splu`` (with an
        :class:`O3DLSMeshWarning` unless ``O3D_LSMESH_NO_CHOLMOD=1`` chose it).
        ``"iterative"``: conjugate gradients, to relative residual ``tol``.
    preconditioner : {"amg", "ic0"}
        The iterative path's: a smoothed-aggregation AMG V-cycle (``pyamg``'s
        aggregation; iterations independent of the size on Laplacian-like
        systems), or the zero-fill incomplete Cholesky factor (set up in one
        pass, no hierarchy: cheaper where the system is well conditioned
        whatever its size, e.g. a data term on every vertex). Where rows of
        thousands of entries would make that pass superlinear (a UV sphere's
        poles), ``"ic0"`` runs the V-cycle (:data:`IC_WORK`).
    lower : bool
        ``matrix`` holds only its lower triangle.
    ordering : {"default", "nesdis", "metis", "amd", "colamd", "natural"}
        CHOLMOD's fill-reducing ordering (``"default"``: CHOLMOD's least fill).
        ``"nesdis"`` has the balanced elimination tree the geometry-aware bases
        paper's update bound assumes (cheaper rank-1 updates, slower factor).
    pattern_of : (n, k) scipy sparse matrix, optional, keyword-only
        CHOLMOD analyzes the pattern of ``A A^T`` for this ``A`` (which must hold
        the matrix's; ``"colamd"`` orders ``A`` itself): a normal matrix
        ``K^T K + ...`` analyzed from the sparser ``K^T``. CHOLMOD only.
    locality_of : (n, n) scipy sparse matrix, optional, keyword-only
        A symmetric matrix whose graph has the matrix's neighbourhoods, sparser
        (a mesh's Laplacian for its normal matrix): the iterative path numbers
        scattered unknowns (:data:`LOCAL_SPAN`) by its reverse Cuthill-McKee order
        instead of the matrix's, and renumbers ``product_of``'s rows before forming
        the product. Iterative path only.
    memory_budget : int, optional
        Bytes the direct factor may take under ``backend="auto"``; default
        :func:`default_memory_budget` (half the available memory, or
        ``O3D_LSMESH_MEMORY_BUDGET``).
    tol : float
        Relative residual ``||b - A x|| / ||b||`` per column at which the
        iterative path stops (default :data:`DEFAULT_TOLERANCE`, which matches
        CHOLMOD to about 3e-8 relative at 1M vertices).
    reduction : float, optional
        The iterative path also stops a column once its residual is this
        fraction of the residual at its start ``x0``, ``||b - A x|| <=
        reduction ||b - A x0||``: the accuracy of a correction to ``x0`` (a
        filter's displacement of the positions it starts from), not of ``x``.
    max_iterations : int
        Conjugate-gradient iterations before :class:`ConvergenceError`.
    progress : bool
        Show the iterative solves' relative residual in a tqdm bar.

    Attributes
    ----------
    backend : str
        The backend that actually runs, ``"cholmod"``, ``"scipy"`` or ``"iterative"``.
    shape : tuple of int
    iterations : int
        Conjugate-gradient iterations of the last solve (0 for direct backends).
    residual : float
        Largest relative residual of the last iterative solve (0.0 for direct backends).

    Notes
    -----
    Solves and updates hold a lock (CHOLMOD's workspace is shared by the factor):
    a solver may be shared between threads. It pickles as its matrix and refactors on load.

    Examples
    --------
    >>> import scipy.sparse as sp, numpy as np
    >>> solver = SPDSolver(sp.identity(3, format="csc") * 2.0)
    >>> solver.solve(np.ones((3, 2))).tolist()
    [[0.5, 0.5], [0.5, 0.5], [0.5, 0.5]]
    """

    def __init__(
        self,
        matrix: Any = None,
        *,
        backend: str = "auto",
        preconditioner: str = "amg",
        ordering: str = "default",
        lower: bool = False,
        product_of: Any = None,
        pattern_of: Any = None,
        locality_of: Any = None,
        memory_budget: int | None = None,
        tol: float = DEFAULT_TOLERANCE,
        reduction: float | None = None,
        max_iterations: int = 5000,
        progress: bool = False,
    ) -> None:
        backend = as_choice(backend, BACKENDS, name="backend")
        self.preconditioner = as_choice(preconditioner, PRECONDITIONERS, name="preconditioner")
        self.ordering = as_choice(ordering, ORDERINGS, name="ordering")
        if _not_a(tol, (int, float, np.floating)) or not 0 < tol < 1:
            raise ValueError(f"tol must be a number in (0, 1), got {tol!r}")
        if reduction is not None and _not_a(reduction, (int, float, np.floating)):
            raise TypeError(f"reduction must be None or a number in (0, 1), got {reduction!r}")
        if reduction is not None and not 0 < reduction < 1:
            raise ValueError(f"reduction must be None or a number in (0, 1), got {reduction!r}")
        if _not_a(max_iterations, (int, np.integer)) or max_iterations < 1:
            raise ValueError(f"max_iterations must be a positive integer, got {max_iterations!r}")
        if memory_budget is not None and (
            _not_a(memory_budget, (int, float, np.integer)) or memory_budget < 0
        ):
            raise ValueError(f"memory_budget must be a non-negative number of bytes, got {memory_budget!r}")
        self.tol = float(tol)
        self.reduction = None if reduction is None else float(reduction)
        self.max_iterations = int(max_iterations)
        self.progress = bool(progress)
        self.memory_budget = memory_budget
        if backend == "cholmod" and _cholmod is None:
            raise ImportError(
                "backend='cholmod' needs scikit-sparse: pip install 'o3d_lsmesh[cholmod]' "
                "(after apt-get install libsuitesparse-dev)"
                + (f"; {NO_CHOLMOD_ENV} is set" if _cholmod_disabled() else "")
            )
        if (matrix is None) == (product_of is None):
            raise TypeError("pass exactly one of matrix and product_of")
        if product_of is None:
            given = _as_csc(matrix)
            _check_symmetric(given, lower=bool(lower))
        else:
            given = _as_csc(product_of, name="product_of", square=False)
        if backend == "auto":
            n = given.shape[0]
            # entries of the (whole) matrix: the product's are about those of A A^T's pattern
            nnz = given.nnz * (2 if lower else 1) if product_of is None else 3 * given.nnz
            budget = default_memory_budget() if memory_budget is None else memory_budget
            self.estimated_factor_bytes = estimate_factor_bytes(n, nnz)
            if self.estimated_factor_bytes > budget:
                backend = "iterative"
        if backend == "auto":
            if _cholmod is None and not _cholmod_disabled():
                _warn_fallback_once()
            backend = "scipy" if _cholmod is None else "cholmod"
        self.backend = backend
        self.iterations = 0
        self.residual = 0.0
        self._lock = threading.RLock()
        # CHOLMOD reads only the lower triangle, so it is all that is kept (half the memory
        # while the factor is computed); SciPy's LU and the iterative path need the whole matrix
        self._lower = self.backend == "cholmod"
        self._matrix: sp.csc_matrix | None = None
        self._product_of: sp.csc_matrix | None = None
        #: the iterative path's renumbering of the unknowns (``_matrix`` is then stored renumbered), and
        #: whether it was chosen (it is at the first solve, unless ``locality_of`` chose it here)
        self._order: np.ndarray | None = None
        self._ordered = False
        if self.backend == "iterative" and locality_of is not None:
            graph = _as_csc(locality_of, name="locality_of")
            if graph.shape[0] != given.shape[0]:
                raise ValueError(f"locality_of must have shape {(given.shape[0],) * 2}, got {graph.shape}")
            self._order, self._ordered = _locality_order(graph), True
            del graph
        if product_of is None:
            self._matrix = _stored(given, given_lower=bool(lower), keep_lower=self._lower)
            if self._order is not None:
                self._matrix = _renumbered(self._matrix, self._order)
        elif self.backend == "iterative":
            # CG multiplies by the matrix and AMG coarsens it: form A A^T once, from A's rows renumbered
            # (no renumbered copy of the product: 6 s at 10M vertices)
            if self._order is not None:
                inverse = np.empty_like(self._order)
                inverse[self._order] = np.arange(len(inverse))
                given = sp.csc_matrix((given.data, inverse[given.indices], given.indptr), shape=given.shape)
            self._matrix = gram_matrix(given)
        else:
            self._product_of = given
        del given
        self._pattern_of = (
            None if pattern_of is None else _as_csc(pattern_of, name="pattern_of", square=False)
        )
        if self._pattern_of is not None and self._pattern_of.shape[0] != self.shape[0]:
            raise ValueError(f"pattern_of must have {self.shape[0]} rows, got shape {self._pattern_of.shape}")
        self._pending: list[sp.csc_matrix] = []
        self._factor: Any = None
        self._factorize(analyze=True)

    @property
    def shape(self) -> tuple[int, int]:
        if self._product_of is not None:
            return (self._product_of.shape[0],) * 2
        assert self._matrix is not None  # one of the two is always set
        return self._matrix.shape

    @property
    def matrix(self) -> sp.csc_matrix:
        """The whole matrix currently factored, updates included, ``(n, n)`` CSC."""
        with self._lock:
            self._flush()
            if self._product_of is not None:
                return gram_matrix(self._product_of)
            if self._order is not None:
                return _renumbered(self._matrix, np.argsort(self._order))
            if not self._lower:
                return self._matrix
            return _symmetric_from_lower(self._matrix)

    def _flush(self) -> None:
        if self._pending and self._product_of is not None:
            # A A^T + C C^T = [A C] [A C]^T
            self._product_of = sp.hstack([self._product_of, *self._pending], format="csc")
        elif self._pending:
            self._pattern_of = None  # C C^T may reach outside it: later analyses take the matrix's own
            for c in self._pending:
                if self._order is not None:
                    c = c[self._order]  # C's rows in the matrix's stored numbering
                product = c @ c.T
                self._matrix = (self._matrix + (sp.tril(product) if self._lower else product)).tocsc()
            assert self._matrix is not None
            self._matrix.sort_indices()
        self._pending.clear()

    def _factorize(self, *, analyze: bool) -> None:
        try:
            if self.backend == "iterative":
                # the AMG hierarchy is built at the first solve: updates and refactors before it cost nothing
                self._factor = None
            elif self.backend == "cholmod":
                pattern = self._pattern_of if self._product_of is None else self._product_of
                if (analyze or self._factor is None) and pattern is not None:
                    self._factor = _cholmod.analyze_AAt(pattern, ordering_method=self.ordering)
                elif analyze or self._factor is None:
                    self._factor = _cholmod.analyze(self._matrix, ordering_method=self.ordering)
                if self._product_of is not None:
                    self._factor.cholesky_AAt_inplace(self._product_of)
                else:
                    self._factor.cholesky_inplace(self._matrix)
            else:
                self._factor = _Woodbury(
                    _splu_spd(self._matrix if self._product_of is None else gram_matrix(self._product_of))
                )
        except Exception as error:
            if _cholmod is not None and isinstance(error, _cholmod.CholmodNotPositiveDefiniteError):
                raise SingularSystemError(
                    f"matrix must be positive definite, got a failing pivot at column {error.column}"
                ) from error
            if isinstance(error, RuntimeError) and "singular" in str(error).lower():
                raise SingularSystemError(f"matrix must be non-singular: {error}") from error
            raise

    def refactor(self, matrix: Any, *, lower: bool = False) -> None:
        """Factor a new matrix of the same sparsity pattern, reusing the symbolic analysis.

        ``lower=True`` says that ``matrix`` holds only its lower triangle.
        """
        if self._product_of is not None:
            raise TypeError(
                "refactor takes a matrix, and this solver factors a product: build a new SPDSolver"
            )
        csc = _as_csc(matrix)
        _check_symmetric(csc, lower=lower)
        assert self._matrix is not None  # a product solver raised above
        if csc.shape != self._matrix.shape:
            raise ValueError(f"matrix must have shape {self._matrix.shape}, got {csc.shape}")
        with self._lock:
            self._matrix = _stored(csc, given_lower=lower, keep_lower=self._lower)
            self._order, self._ordered = None, False
            self._pending.clear()
            self._factorize(analyze=False)

    def solve(self, rhs: Any, *, x0: Any = None) -> np.ndarray:
        """Solve ``A x = rhs`` for an ``(n,)`` or ``(n, k)`` right-hand side, all columns at once.

        ``x0`` (same shape) is a starting guess for the iterative backend (current
        positions when fairing, a prolongated coarse solution); direct backends ignore it.
        """
        try:
            b = np.asarray(rhs, dtype=np.float64)
        except (TypeError, ValueError) as error:
            raise TypeError(f"rhs must be an array of real numbers, got {type(rhs).__name__}") from error
        n = self.shape[0]
        if b.shape[:1] != (n,) or b.ndim > 2:
            raise ValueError(f"rhs must have shape ({n},) or ({n}, k), got {b.shape}")
        if not np.isfinite(b).all():
            first = int(np.flatnonzero(~np.isfinite(b).ravel())[0])
            raise ValueError(
                f"rhs must be finite, got {b.ravel()[first]} at row {first // max(b.size // n, 1)} "
                "(an overflowing weight or position?)"
            )
        with self._lock:
            if self.backend == "iterative":
                x = self._solve_iterative(b, x0)
            elif self.backend == "cholmod":
                x = self._factor(b)
            else:
                try:
                    x = self._factor.solve(b)
                except np.linalg.LinAlgError:  # the updates' capacitance lost definiteness: factor them in
                    self._flush()
                    self._factorize(analyze=True)
                    x = self._factor.solve(b)
        if not np.all(np.isfinite(x)):
            raise SingularSystemError(
                "the factored matrix is numerically singular: the solve of a finite right-hand side "
                "returned non-finite values"
            )
        return np.asarray(x)

    def _solve_iterative(self, b: np.ndarray, x0: Any) -> np.ndarray:
        if x0 is not None:
            x0 = np.asarray(x0, dtype=np.float64)
            if x0.shape != b.shape:
                raise ValueError(f"x0 must have the shape of rhs {b.shape}, got {x0.shape}")
            if not np.isfinite(x0).all():
                raise ValueError("x0 must be finite")
        if self._factor is None:  # the preconditioner, built at the first solve
            self._flush()
            assert self._matrix is not None  # the iterative path takes matrices only
            if not self._ordered:
                self._order, self._ordered = _locality_order(self._matrix), True
                if self._order is not None:
                    self._matrix = _renumbered(self._matrix, self._order)
            if self.preconditioner == "ic0" and _incomplete_cholesky_is_linear(self._matrix):
                self._factor = _IncompleteCholesky(self._matrix)
            else:
                self._factor = _amg_preconditioner(self._matrix)
        order = self._order
        x, self.iterations, self.residual = _block_cg(
            _csr_view(self._matrix),
            b if order is None else b[order],
            x0 if order is None or x0 is None else x0[order],
            self._factor,
            tol=self.tol,
            reduction=self.reduction,
            max_iterations=self.max_iterations,
            progress=self.progress,
        )
        if order is None:
            return x
        out = np.empty_like(x)
        out[order] = x
        return out

    def update(self, c: Any) -> None:
        """Replace ``A`` by ``A + C C^T`` (CHOLMOD rank-k update, no refactoring).

        ``C`` is ``(n, k)`` sparse in the matrix's own row order. The SciPy path keeps its LU and
        corrects the solves by Woodbury's identity (:class:`_Woodbury`), refactoring once the
        correction has cost as much as a factorization; the iterative path rebuilds its
        preconditioner at the next solve.
        """
        if not (sp.isspmatrix_csc(c) and c.dtype == np.float64):
            try:
                c = sp.csc_matrix(c, dtype=np.float64)
            except (TypeError, ValueError) as error:
                raise TypeError(
                    f"C must be a sparse matrix or an array of real numbers, got {type(c).__name__}"
                ) from error
        if c.shape[0] != self.shape[0]:
            raise ValueError(f"C must have {self.shape[0]} rows, got shape {c.shape}")
        if not np.isfinite(c.data).all():
            raise ValueError("C must have finite entries (an overflowing weight?)")
        if not c.has_sorted_indices:
            c = c.sorted_indices()
        with self._lock:
            self._pending.append(c)
            if self.backend == "cholmod":
                self._factor.update_inplace(c)
                return
            if self.backend == "scipy" and self._factor.affords(c.shape[1]):
                self._factor.add(c)
                return
            self._flush()
            self._factorize(analyze=True)

    def __getstate__(self) -> dict:
        with self._lock:
            self._flush()
            return {
                "backend": self.backend,
                "preconditioner": self.preconditioner,
                "ordering": self.ordering,
                "matrix": self._matrix if self._order is None else self.matrix,
                "lower": self._lower,
                "product_of": self._product_of,
                "pattern_of": self._pattern_of,
                "tol": self.tol,
                "reduction": self.reduction,
                "max_iterations": self.max_iterations,
                "progress": self.progress,
                "memory_budget": self.memory_budget,
            }

    def __setstate__(self, state: dict) -> None:
        product_of = state.get("product_of")
        SPDSolver.__init__(
            self,
            state["matrix"] if product_of is None else None,
            backend="scipy" if state["backend"] == "cholmod" and _cholmod is None else state["backend"],
            preconditioner=state.get("preconditioner", "amg"),
            ordering=state.get("ordering", "default"),
            lower=state.get("lower", False),
            product_of=product_of,
            pattern_of=state.get("pattern_of"),
            memory_budget=state.get("memory_budget"),
            tol=state.get("tol", DEFAULT_TOLERANCE),
            reduction=state.get("reduction"),
            max_iterations=state.get("max_iterations", 5000),
            progress=state.get("progress", False),
        )


#: Entries a 32-bit index array can address.
INT32_ENTRIES = int(np.iinfo(np.int32).max)


def gram_matrix(a: sp.csc_matrix) -> sp.csc_matrix:
    """``A A^T`` for a CSC ``A`` (a normal matrix from its stacked rows' transpose), sorted CSC
    (``_block_kernel.gram``: exactly symmetric, on every core)."""
    from . import _block_kernel  # compiled by the package's build: imported where used

    rows = a.tocsr()
    index = np.result_type(rows.indptr, rows.indices, a.indptr, a.indices)
    # the product's entries are at most the sum of the columns' squared lengths: 64-bit indices where
    # 32 bits might not hold them
    if np.sum(np.diff(a.indptr).astype(np.int64) ** 2) >= INT32_ENTRIES:
        index = np.dtype(np.int64)
    indptr, indices, data = _block_kernel.gram(
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


def _amg_preconditioner(matrix: sp.spmatrix) -> Any:
    """One smoothed-aggregation AMG V-cycle on a block, as a function ``(n, k) -> (n, k)``.

    On the system itself with the constant near-null space: faster than AMG on the Laplacian
    alone or linear near-null-space candidates (benchmarks/results/scale.md).
    """
    csr = _csr_view(matrix)
    if csr.shape[0] <= COARSE_UNKNOWNS:
        # too small for a hierarchy: the exact inverse is the best preconditioner
        dense = _splu_spd(csr.tocsc())
        return lambda r: dense.solve(np.asfortranarray(r))
    return _VCycle(*_aggregation_levels(csr))


#: ``preconditioner="ic0"`` factors only where IC(0)'s set-up, at most ``sum_i (row i's entries)^2 / 4``
#: multiply-adds, is within this many times the matrix's entries (4.7-4.9 on the scans and the
#: subdivided camel and feline); past it (a UV sphere's poles: 32 at 200k vertices, 66 at 1M, rows of
#: 1265 and 2829 entries) it grows like the largest valence cubed (1.0 s of set-up at 200k, the whole
#: default 105 s against the V-cycle's 41 s at 4M) and the AMG V-cycle runs.
IC_WORK = 16


def _incomplete_cholesky_is_linear(matrix: sp.spmatrix) -> bool:
    # row i's lower part times its upper part bounds the products its column takes part in
    lengths = np.diff(_csr_view(matrix).indptr).astype(np.float64)
    return float(np.dot(lengths, lengths)) / 4.0 <= IC_WORK * max(matrix.nnz, 1)


#: IC(0) retries a breakdown with the diagonal scaled by ``1 + shift``, the shift starting here and
#: doubling (nine of the ten raw scans' systems factor unshifted; ear_back's takes 1e-3).
FIRST_SHIFT = 1e-3
#: Shifts tried after the first breakdown (the last scales the diagonal by about 500: far past
#: diagonal dominance, where IC(0) cannot break down).
MAX_SHIFTS = 20


class _IncompleteCholesky:
    """``r -> (L L^T)^-1 r`` for the zero-fill incomplete Cholesky factor ``L`` of a symmetric matrix.

    One linear pass to set up (the compiled :func:`~o3d_lsmesh._block_kernel.incomplete_cholesky`),
    two triangular passes a solve, every column at once. A breakdown (a non-positive pivot, which
    IC(0) may meet on an SPD matrix that is not an M-matrix, e.g. a thin-plate normal matrix) is
    retried on the diagonal scaled by ``1 + shift`` (Manteuffel 1980), the shift doubling from
    :data:`FIRST_SHIFT`. Holds arrays only: threads may share it.
    """

    def __init__(self, matrix: sp.spmatrix) -> None:
        from . import _block_kernel  # compiled by the package's build: imported where used

        self._parts = _csr_parts(_csr_view(matrix))
        shifts = [0.0] + [FIRST_SHIFT * 2.0**i for i in range(MAX_SHIFTS)]
        try:
            for shift in shifts:
                values, diagonal, failed = _block_kernel.incomplete_cholesky(*self._parts, shift)
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
        from . import _block_kernel  # compiled by the package's build: imported where used

        indptr, indices, _ = self._parts
        return lambda r, out: _block_kernel.incomplete_cholesky_solve(
            indptr, indices, self._values, self._diagonal, r, out
        )


#: The AMG hierarchy stops coarsening at this many unknowns and solves them with a sparse LU.
COARSE_UNKNOWNS = 500
#: Strength threshold of the AMG's aggregation and prolongator smoothing: keeps an LS mesh normal
#: matrix's 1-ring entries (about 0.24 of the diagonal) and drops its 2-ring ones (below 0.05);
#: 0.05 and 0.2 took 33 and 32 CG iterations at 200k vertices, as 0.1 did; 0.3 drops the 1-ring (263).
STRENGTH = 0.1


def _aggregation_levels(
    A: sp.csr_matrix, *, max_levels: int = 10, omega: float = 4.0 / 3.0, theta: float = STRENGTH
) -> tuple:
    """Smoothed-aggregation levels ``[(A, R, P), ...]`` and the coarsest level's LU.

    pyamg's smoothed aggregation with the constant as near-null space, from its aggregation and
    tentative prolongator: the candidate is improved by four symmetric Gauss-Seidel sweeps on ``A x = 0``
    on the finest level; each level keeps ``A``'s strong entries (``|a_ij| >= theta sqrt(|a_ii a_jj|)``,
    the weak ones lumped onto the diagonal: ``A_F``), aggregates on their graph and smooths the
    tentative prolongator with them, ``P = (I - omega D^-1 A_F) T`` with ``D`` the rows' absolute sums
    (a local Gershgorin bound: pyamg's eigenvalue estimate took a fifth of the solve at 100k vertices).
    On the normal matrix of an LS mesh (a 2-ring stencil) the strong entries are the 1-ring: aggregates
    and prolongator on the whole stencil took 79 CG iterations at 1M vertices, on its strong part 30
    (benchmarks/results/scale.md). Only the filtered copy's values are scaled (pyamg's smoother copies
    the whole matrix three times, the peak of a solve at 10M vertices).
    """
    try:
        from pyamg.aggregation.aggregate import standard_aggregation
        from pyamg.aggregation.tentative import fit_candidates
    except ImportError as error:  # pragma: no cover - pyamg is in install_requires
        raise ImportError("the iterative solver path needs pyamg: pip install pyamg") from error
    from . import _block_kernel  # compiled by the package's build: imported where used

    candidate, zero, finest = np.ones((A.shape[0], 1)), np.zeros((A.shape[0], 1)), _csr_parts(A)
    for _ in range(4):
        _block_kernel.gauss_seidel(*finest, candidate, zero, True, _sweep_blocks(A))
        _block_kernel.gauss_seidel(*finest, candidate, zero, False, _sweep_blocks(A))
    levels: list[tuple[sp.csr_matrix, sp.csr_matrix, sp.csr_matrix]] = []
    while len(levels) + 1 < max_levels and A.shape[0] > COARSE_UNKNOWNS:
        strong = sp.csr_matrix(_block_kernel.strong_part(*_csr_parts(A), theta)[::-1], shape=A.shape)
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
    return levels, _splu_spd(A.tocsc())


#: The iterative path renumbers the unknowns by reverse Cuthill-McKee when a matrix row reaches farther
#: than this many rows on average (16384 rows of ``(n, 3)`` positions are 384 KiB, within the L2 cache
#: a core reads them from): on a 3.2M-vertex midpoint-subdivided mesh (new vertices numbered after the
#: old) the LS mesh's rows reached 522k rows, its products ran 3x slower and CG took 59 iterations;
#: renumbered (4.7k), 37, and the whole LS mesh 62 -> 36-40 s. Merged or subdivided meshes number
#: neighbours far apart; a UV sphere's rows reach 2.7k at 3M vertices and are kept.
LOCAL_SPAN = 16384


def _locality_order(symmetric: sp.spmatrix) -> np.ndarray | None:
    """A renumbering of a symmetric matrix's unknowns that keeps rows' entries close
    (:func:`~o3d_lsmesh._block_kernel.level_order`, reverse Cuthill-McKee), or None when they are close
    already (:data:`LOCAL_SPAN`)."""
    from . import _block_kernel  # compiled by the package's build: imported where used

    indptr, indices, _ = _csr_parts(_csr_view(symmetric))
    if _block_kernel.row_span(indptr, indices) <= LOCAL_SPAN:
        return None
    return _block_kernel.level_order(indptr, indices)


def _renumbered(symmetric: sp.spmatrix, order: np.ndarray) -> sp.csc_matrix:
    """``B[r, s] = A[order[r], order[s]]`` for a symmetric ``A``, CSC (one copy, sorted indices)."""
    from . import _block_kernel  # compiled by the package's build: imported where used

    indptr, indices, data = _block_kernel.permuted(*_csr_parts(_csr_view(symmetric)), order)
    # a symmetric matrix's CSR arrays are also its CSC arrays
    renumbered = sp.csc_matrix((data, indices, indptr), shape=symmetric.shape)
    renumbered.has_sorted_indices = True
    return renumbered


def _csr_view(symmetric: sp.spmatrix) -> sp.csr_matrix:
    """A symmetric matrix as CSR without a copy when it is CSC (its arrays are also its transpose's)."""
    return symmetric.T if sp.isspmatrix_csc(symmetric) else sp.csr_matrix(symmetric)


def _csr_parts(matrix: sp.spmatrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(indptr, indices, data)`` of ``matrix`` as CSR (no copy when it is one), one index type."""
    csr = sp.csr_matrix(matrix, dtype=np.float64)
    index = np.result_type(csr.indptr, csr.indices)
    return csr.indptr.astype(index, copy=False), csr.indices.astype(index, copy=False), csr.data


class _VCycle:
    """One V-cycle of :func:`_aggregation_levels`' levels and coarse LU on a whole ``(n, k)`` block: a
    forward Gauss-Seidel sweep before the coarse correction and a backward one after (symmetric, as CG
    needs; 135 CG iterations against 102 with symmetric sweeps on both sides, but 10% less time, LS mesh
    with 2% controls at 100k vertices), each column with pyamg's arithmetic (``_block_kernel``); every
    sweep and product streams its level's matrix once for all columns, on every core (the sweeps in
    :func:`_sweep_blocks` blocks; the same iteration counts at 1M vertices as one sequential sweep).

    ``cycle(r)`` returns a new block; :meth:`bound` gives ``apply(r, out)`` with the levels' work blocks
    allocated once, for a solve's every iteration: fresh blocks cost a page fault per page on every
    cycle (at 3.2M vertices a third of the LS mesh's time went to the kernel, before). The object holds
    no block itself: threads may share it.
    """

    def __init__(self, levels: list, coarse: Any) -> None:
        self._operators = [
            (_csr_parts(A), _sweep_blocks(A), _csr_parts(R), _csr_parts(P)) for A, R, P in levels
        ]
        self._coarse = coarse

    def __call__(self, r: np.ndarray) -> np.ndarray:
        r = np.ascontiguousarray(r, dtype=np.float64)
        out = np.empty_like(r)
        self.bound(r.shape[1])(r, out)
        return out

    def bound(self, k: int) -> Any:
        """``apply(r, out)``: one cycle of C-ordered ``(n, k)`` ``r`` into ``out``, reusing its work blocks."""
        from . import _block_kernel  # compiled by the package's build: imported where used

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
            _block_kernel.gauss_seidel(*A, x, b, True, blocks)
            _block_kernel.block_product(*A, x, residual, -1.0, b)  # b - A x in one pass
            _block_kernel.block_product(*R, residual, coarse_b)
            cycle(depth + 1, coarse_b, coarse_x)
            _block_kernel.block_product(*P, coarse_x, x, 1.0, x)  # x += P correction in one pass
            _block_kernel.gauss_seidel(*A, x, b, False, blocks)

        return lambda r, out: cycle(0, r, out)


#: Rows per block of the parallel (hybrid) Gauss-Seidel sweeps; at most :data:`SWEEP_BLOCKS` blocks. The
#: count depends on the matrix alone, so results do not depend on the machine's thread count.
ROWS_PER_SWEEP_BLOCK = 65536
SWEEP_BLOCKS = 32


def _sweep_blocks(A: sp.spmatrix) -> int:
    return int(np.clip(A.shape[0] // ROWS_PER_SWEEP_BLOCK, 1, SWEEP_BLOCKS))


def _block_cg(
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

    Independent CG runs sharing the matrix passes; column ``j`` stops when
    ``||r_j|| <= max(tol ||b_j||, reduction ||r_j^0||)`` (``r^0`` at the start, ``reduction``
    default none).
    Returns the solution, the iteration count and the largest relative residual.
    """
    from . import _block_kernel  # compiled by the package's build: imported where used

    vector = b.ndim == 1
    B = np.ascontiguousarray(b[:, None] if vector else b, dtype=np.float64)
    X = np.zeros_like(B) if x0 is None else np.array(x0, dtype=np.float64, order="C").reshape(B.shape)
    norms = np.linalg.norm(B, axis=0)
    scale = np.where(norms > 0, norms, 1.0)
    parts = _csr_parts(matrix)
    R = B.copy()
    if x0 is not None:
        _block_kernel.block_product(*parts, X, R, -1.0, B)  # B - A X in one pass
        # a start farther from the solution than zero (e.g. controls moved far from the mesh) is dropped
        worse = np.linalg.norm(R, axis=0) > norms
        X[:, worse] = 0.0
        R[:, worse] = B[:, worse]
    relative = np.linalg.norm(R, axis=0) / scale
    relative[norms == 0] = 0.0
    # each column's stopping point as a relative residual
    limit = np.full(B.shape[1], tol) if reduction is None else np.maximum(tol, reduction * relative)
    if norms.size and not (norms > 0).any():
        return (np.zeros_like(b), 0, 0.0)
    # the bar counts the decades the worst column's residual falls to its stopping point
    bar = decades_bar(progress, to_go=float((relative / limit).max()), desc="conjugate gradients")
    converged = False
    # the work blocks, allocated once for the solve (see _VCycle)
    if hasattr(precondition, "bound"):
        apply = precondition.bound(B.shape[1])
    else:
        apply = lambda r, out: np.copyto(out, precondition(r))
    Z, Q = np.empty_like(B), np.empty_like(B)
    apply(R, Z)
    P = Z.copy()
    rz = _block_kernel.column_dots(R, Z)
    iteration = 0
    try:
        while (relative > limit).any():
            if iteration >= max_iterations:
                raise ConvergenceError(
                    f"conjugate gradients reached relative residual {relative.max():.3g} after {iteration} "
                    f"iterations, tolerance {tol:g}: raise max_iterations or tol, or use solver='cholmod'"
                )
            _block_kernel.block_product(*parts, P, Q)
            pq = _block_kernel.column_dots(P, Q)
            active = relative > limit
            if (pq[active] <= 0).any():
                raise SingularSystemError(
                    "matrix must be positive definite: conjugate gradients met a direction of non-positive "
                    "curvature"
                )
            alpha = np.where(active, rz / np.where(active, pq, 1.0), 0.0)
            relative = np.sqrt(_block_kernel.cg_step(X, R, P, Q, alpha)) / scale  # one pass, no temporaries
            relative[norms == 0] = 0.0
            iteration += 1
            bar.reached(float((relative / limit).max()), f"residual={relative.max():.2e}, {iteration} it")
            apply(R, Z)
            rz_new = _block_kernel.column_dots(R, Z)
            beta = np.where(active, rz_new / np.where(rz != 0, rz, 1.0), 0.0)
            _block_kernel.cg_direction(P, Z, beta)
            rz = rz_new
        converged = True
    finally:
        if converged:
            bar.finish()
        bar.close()
    if not np.isfinite(X).all():
        raise SingularSystemError("conjugate gradients diverged: the matrix is not positive definite")
    return (X[:, 0] if vector else X), iteration, float(relative.max(initial=0.0))


#: :func:`solve_spd` solves systems with at most this many unknowns with a dense Cholesky (measured on
#: hole filling's patches: below it the sparse path's assembly, analysis and factorization overheads
#: cost more than the dense products).
DENSE_UNKNOWNS = 120


def solve_spd(matrix: Any, rhs: np.ndarray) -> np.ndarray:
    """Solve one SPD system once: a dense Cholesky for at most :data:`DENSE_UNKNOWNS` unknowns,
    :class:`SPDSolver` (AMD ordering) otherwise; ``matrix`` (n, n) dense or sparse, ``rhs`` (n,) or (n, k).

    For one-off small systems (a hole's patch), where analysing and factoring once for many solves does
    not pay. Raises :class:`SingularSystemError` if the matrix is not numerically positive definite.

    Examples
    --------
    >>> solve_spd(np.array([[4.0, 1.0], [1.0, 3.0]]), np.array([1.0, 2.0])).round(4)
    array([0.0909, 0.6364])
    """
    from scipy.linalg import cho_factor, cho_solve

    if matrix.shape[0] > DENSE_UNKNOWNS:
        # small systems: SciPy without its warning when CHOLMOD is missing
        backend = "auto" if cholmod_available() else "scipy"
        return SPDSolver(sp.csc_matrix(matrix), ordering="amd", backend=backend).solve(np.asarray(rhs))
    dense = matrix.toarray() if sp.issparse(matrix) else np.asarray(matrix, dtype=np.float64)
    try:
        return cho_solve(cho_factor(dense), rhs)
    except np.linalg.LinAlgError as error:
        raise SingularSystemError(f"the system is not positive definite: {error}") from error

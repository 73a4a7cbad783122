"""The solve gateway: every factorization and solve of the package, the only ``sksparse.cholmod`` import.

:class:`SPDSolver` factors once (CHOLMOD; SciPy's ``splu`` with Woodbury updates without it; conjugate
gradients above a memory budget), solves ``(n, k)`` right-hand sides, refactors and updates;
:func:`solve_spd` solves a small system once. Design and figures: docs/algorithms/solvers.rst.
"""

from __future__ import annotations

import contextlib
import os
import threading
from dataclasses import fields, replace
from typing import Any, NoReturn

import numpy as np
import scipy.sparse as sp

from . import _direct, tuning
from ._direct import (
    BACKENDS,
    ORDERINGS,
    PRECONDITIONERS,
    SOLVERS,
    Plan,
    check_constant_modes,
    check_finite,
    check_weight_pins_components,
    default_memory_budget,
    estimate_factor_bytes,
    operator_scale,
    single_threaded_blas,
    solver_backend,
)
from ._iterative import block_cg, csr_view, gram_matrix, locality_order, preconditioner, renumbered, splu_spd
from .errors import InputError, InputTypeError, SingularSystemError, called_from_outside, warn
from .validate import as_bool, as_choice, as_csc

__all__ = [
    "BACKENDS",
    "ORDERINGS",
    "PRECONDITIONERS",
    "SOLVERS",
    "Plan",
    "SPDSolver",
    "check_constant_modes",
    "check_finite",
    "check_weight_pins_components",
    "cholmod_available",
    "default_memory_budget",
    "estimate_factor_bytes",
    "gram_matrix",
    "operator_scale",
    "single_threaded_blas",
    "solve_spd",
    "solver_backend",
]

NO_CHOLMOD_ENV = "O3D_LSMESH_NO_CHOLMOD"


def _cholmod_disabled() -> bool:
    """Whether the user chose the SciPy path with ``O3D_LSMESH_NO_CHOLMOD=1``."""
    return os.environ.get(NO_CHOLMOD_ENV, "").strip().lower() not in ("", "0", "false", "no")


def _import_cholmod() -> Any:
    if not _cholmod_disabled():
        with contextlib.suppress(ImportError):
            from sksparse import cholmod

            return cholmod
    return None


_cholmod = _import_cholmod()


def cholmod_available() -> bool:
    """Whether scikit-sparse's CHOLMOD can be imported."""
    return _cholmod is not None


#: Fallback warning shown by this process already (each solver would repeat it otherwise).
_fallback_warned = False


def _warn_fallback_once() -> None:
    global _fallback_warned
    if not _fallback_warned:
        _fallback_warned = True
        warn(
            "scikit-sparse is not importable; solving with scipy.sparse.linalg.splu, slower than CHOLMOD "
            f"(pip install 'o3d_lsmesh[cholmod]' for CHOLMOD, or set {NO_CHOLMOD_ENV}=1 to choose SciPy "
            "and silence this warning; shown once)"
        )


def _reraise(error: Exception) -> NoReturn:
    """Raise a factorization's ``error`` as :class:`SingularSystemError` where it means a singular matrix."""
    if _cholmod is not None and isinstance(error, _cholmod.CholmodNotPositiveDefiniteError):
        message = f"matrix must be positive definite, got a failing pivot at column {error.column}"
        raise SingularSystemError(message) from error
    if isinstance(error, RuntimeError) and "singular" in str(error).lower():
        raise SingularSystemError(f"matrix must be non-singular: {error}") from error
    raise error


class SPDSolver:
    """Factor a sparse SPD matrix once and solve, refactor or update it.

    Parameters
    ----------
    matrix : (n, n) scipy sparse matrix
        Symmetric positive definite: the whole matrix, or only its lower triangle with ``lower=True``.
    backend : {"auto", "cholmod", "scipy", "iterative"}
        ``"auto"``: the iterative path when :func:`estimate_factor_bytes` exceeds the memory budget,
        else CHOLMOD, else SciPy's ``splu`` (with an :class:`O3DLSMeshWarning` unless
        ``O3D_LSMESH_NO_CHOLMOD=1`` chose it). ``"iterative"``: conjugate gradients to ``tol``.
    ordering : {"default", "nesdis", "metis", "amd", "colamd", "natural"}
        CHOLMOD's fill-reducing ordering (``"default"``: CHOLMOD's least fill).
    lower : bool
        ``matrix`` holds only its lower triangle.
    tol : float
        Relative residual ``||D^-1 (b - A x)|| / ||D^-1 b||`` per column (``D`` the diagonal of ``A``) at
        which the iterative path stops.
    max_iterations : int
        Conjugate-gradient iterations before :class:`ConvergenceError`.
    progress : bool
        Show the iterative solves' residual in a progress bar.

    Attributes ``backend`` (the one that runs), ``iterations`` and ``residual`` (the last CG solve's).
    Thread-safe; pickles as its matrix. :class:`Plan`'s fields as keywords are deprecated (``_plan=``).
    Raises :class:`InputError` (:class:`InputTypeError`) for a bad matrix or option; an indefinite matrix
    is solved by CHOLMOD's ``LDL^T`` and SciPy's LU, refused by CG (docs/algorithms/solvers.rst).

    Examples
    --------
    >>> import scipy.sparse as sp, numpy as np
    >>> SPDSolver(sp.identity(3, format="csc") * 2.0).solve(np.ones((3, 2))).tolist()
    [[0.5, 0.5], [0.5, 0.5], [0.5, 0.5]]
    """

    def __init__(
        self,
        matrix: Any = None,
        *,
        backend: str = "auto",
        ordering: str = "default",
        lower: bool = False,
        tol: float = tuning.DEFAULT_TOLERANCE,
        max_iterations: int = tuning.MAX_ITERATIONS,
        progress: bool = False,
        _plan: Plan | None = None,
        **deprecated: Any,
    ) -> None:
        unknown = next(iter(sorted(set(deprecated) - {f.name for f in fields(Plan)})), None)
        if unknown:
            raise InputTypeError(f"SPDSolver() got an unexpected keyword argument {unknown!r}", param=unknown)
        plan = replace(_plan or Plan(), **deprecated)
        backend = as_choice(backend, BACKENDS, name="backend")
        self.preconditioner = as_choice(plan.preconditioner, PRECONDITIONERS, name="preconditioner")
        self.ordering = as_choice(ordering, ORDERINGS, name="ordering")
        reduction, memory_budget, product_of = plan.reduction, plan.memory_budget, plan.product_of
        _direct.check_numbers(tol, reduction, max_iterations, memory_budget)
        self.tol = float(tol)
        self.reduction = None if reduction is None else float(reduction)
        self.max_iterations = int(max_iterations)
        self.progress = as_bool(progress, name="progress")
        self.memory_budget = memory_budget
        if backend == "cholmod" and _cholmod is None:
            raise ImportError(
                "backend='cholmod' needs scikit-sparse: pip install 'o3d_lsmesh[cholmod]' "
                "(after apt-get install libsuitesparse-dev)"
                + (f"; {NO_CHOLMOD_ENV} is set" if _cholmod_disabled() else "")
            )
        if (matrix is None) == (product_of is None):
            raise InputTypeError("pass exactly one of matrix and product_of", param="matrix")
        if product_of is None:
            given = as_csc(matrix)
            _direct.check_symmetric(given, lower=as_bool(lower, name="lower"))
        else:
            given = as_csc(product_of, name="product_of", square=False)
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
        # CHOLMOD reads only the lower triangle, so only it is kept; SciPy's LU and CG need the whole matrix
        self._lower = self.backend == "cholmod"
        self._matrix: sp.csc_matrix | None = None
        self._product_of: sp.csc_matrix | None = None
        # the iterative path's renumbering (``_matrix`` stored renumbered); chosen at the first solve
        self._order: np.ndarray | None = None
        self._ordered = False
        if self.backend == "iterative" and plan.locality_of is not None:
            graph = as_csc(plan.locality_of, name="locality_of")
            if graph.shape[0] != given.shape[0]:
                raise InputError(
                    f"locality_of must have shape {(given.shape[0],) * 2}, got {graph.shape}",
                    param="locality_of",
                )
            self._order, self._ordered = locality_order(graph), True
            del graph
        if product_of is None:
            self._matrix = _direct.stored(given, given_lower=bool(lower), keep_lower=self._lower)
            if self._order is not None:
                self._matrix = renumbered(self._matrix, self._order)
        elif self.backend == "iterative":
            # CG multiplies by the matrix and AMG coarsens it: form A A^T once, from A's rows renumbered
            if self._order is not None:
                inverse = np.empty_like(self._order)
                inverse[self._order] = np.arange(len(inverse))
                given = sp.csc_matrix((given.data, inverse[given.indices], given.indptr), shape=given.shape)
            self._matrix = gram_matrix(given)
        else:
            self._product_of = given
        del given
        self._pattern_of = (
            None if plan.pattern_of is None else as_csc(plan.pattern_of, name="pattern_of", square=False)
        )
        if self._pattern_of is not None and self._pattern_of.shape[0] != self.shape[0]:
            raise InputError(
                f"pattern_of must have {self.shape[0]} rows, got shape {self._pattern_of.shape}",
                param="pattern_of",
            )
        self._pending: list[sp.csc_matrix] = []
        self._factor: Any = None
        self._factorize(analyze=True)
        if deprecated and called_from_outside(1):
            names = ", ".join(f"{name}=" for name in sorted(deprecated))
            warn(
                f"SPDSolver({names}) is deprecated: pass _plan=o3d_lsmesh.core.solve.Plan({names}...)",
                DeprecationWarning,
            )

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
                return renumbered(self._matrix, np.argsort(self._order))
            if not self._lower:
                return self._matrix
            return _direct.symmetric_from_lower(self._matrix)

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
                # the preconditioner is built at the first solve: updates and refactors before it cost nothing
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
                self._factor = _direct.Woodbury(
                    splu_spd(self._matrix if self._product_of is None else gram_matrix(self._product_of))
                )
        except Exception as error:
            _reraise(error)

    def refactor(self, matrix: Any, *, lower: bool = False) -> None:
        """Factor a new matrix of the same sparsity pattern (``lower``: its lower triangle), reusing the analysis."""
        if self._product_of is not None:
            raise InputTypeError(
                "refactor takes a matrix, and this solver factors a product: build a new SPDSolver",
                param="matrix",
            )
        csc = as_csc(matrix)
        _direct.check_symmetric(csc, lower=lower)
        assert self._matrix is not None  # a product solver raised above
        if csc.shape != self._matrix.shape:
            raise InputError(f"matrix must have shape {self._matrix.shape}, got {csc.shape}", param="matrix")
        with self._lock:
            self._matrix = _direct.stored(csc, given_lower=lower, keep_lower=self._lower)
            self._order, self._ordered = None, False
            self._pending.clear()
            self._factorize(analyze=False)

    def solve(self, rhs: Any, *, x0: Any = None) -> np.ndarray:
        """Solve ``A x = rhs`` for an ``(n,)`` or ``(n, k)`` right-hand side, all columns at once.

        ``x0`` (same shape) is a starting guess for the iterative backend; direct backends ignore it.
        """
        try:
            b = np.asarray(rhs)
        except (TypeError, ValueError):  # (ragged)
            b = np.asarray(None)
        if b.dtype.kind not in "biuf":  # (a complex one would be cast to its real part)
            got = f"dtype {b.dtype}" if isinstance(rhs, np.ndarray) else type(rhs).__name__
            raise InputTypeError(f"rhs must be an array of real numbers, got {got}", param="rhs")
        b = b.astype(np.float64, copy=False)
        n = self.shape[0]
        if b.shape[:1] != (n,) or b.ndim > 2:
            raise InputError(f"rhs must have shape ({n},) or ({n}, k), got {b.shape}", param="rhs")
        if not np.isfinite(b).all():
            first = int(np.flatnonzero(~np.isfinite(b).ravel())[0])
            raise InputError(
                f"rhs must be finite, got {b.ravel()[first]} at row {first // max(b.size // n, 1)} "
                "(an overflowing weight or position?)",
                param="rhs",
            )
        if b.size == 0:  # (n, 0): no column to solve
            return np.zeros(b.shape)
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
                raise InputError(f"x0 must have the shape of rhs {b.shape}, got {x0.shape}", param="x0")
            if not np.isfinite(x0).all():
                raise InputError("x0 must be finite", param="x0")
        if self._factor is None:  # the preconditioner, built at the first solve
            self._flush()
            assert self._matrix is not None  # the iterative path takes matrices only
            if not self._ordered:
                self._order, self._ordered = locality_order(self._matrix), True
                if self._order is not None:
                    self._matrix = renumbered(self._matrix, self._order)
            try:
                self._factor = preconditioner(self._matrix, self.preconditioner)
            except Exception as error:  # (a direct coarse solve meeting a singular matrix)
                _reraise(error)
        order = self._order
        x, self.iterations, self.residual = block_cg(
            csr_view(self._matrix),
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
        """Replace ``A`` by ``A + C C^T`` for an ``(n, k)`` sparse ``C`` in the matrix's row order.

        CHOLMOD updates its factor; the SciPy path corrects its solves by Woodbury's identity and
        refactors once that has cost a factorization; the iterative path rebuilds its preconditioner.
        """
        if not (sp.isspmatrix_csc(c) and c.dtype == np.float64):
            try:
                c = sp.csc_matrix(c, dtype=np.float64)
            except (TypeError, ValueError) as error:
                raise InputTypeError(
                    f"C must be a sparse matrix or an array of real numbers, got {type(c).__name__}",
                    param="c",
                ) from error
        if c.shape[0] != self.shape[0]:
            raise InputError(f"C must have {self.shape[0]} rows, got shape {c.shape}", param="c")
        if not np.isfinite(c.data).all():
            raise InputError("C must have finite entries (an overflowing weight?)", param="c")
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
        # a key missing from an older pickle takes the constructor's or Plan's default
        plan = Plan(**{key: state[key] for key in (f.name for f in fields(Plan)) if key in state})
        options = {
            key: state[key]
            for key in ("ordering", "lower", "tol", "max_iterations", "progress")
            if key in state
        }
        matrix = state["matrix"] if plan.product_of is None else None
        backend = "scipy" if state["backend"] == "cholmod" and _cholmod is None else state["backend"]
        SPDSolver.__init__(self, matrix, backend=backend, _plan=plan, **options)


def solve_spd(matrix: Any, rhs: np.ndarray, *, isolate_nonfinite: bool = False) -> np.ndarray:
    """Solve one SPD system once: a dense Cholesky up to :data:`~o3d_lsmesh.core.tuning.DENSE_UNKNOWNS`
    unknowns, :class:`SPDSolver` (AMD ordering) above; ``matrix`` (n, n) dense or sparse, ``rhs`` (n,) or (n, k).

    ``isolate_nonfinite=True`` (sparse ``matrix``, ``(n, k)`` ``rhs``): the connected blocks of the matrix
    holding a non-finite entry (in it or in their ``rhs`` rows) are left NaN and the others solved.
    Raises :class:`SingularSystemError` if the matrix is not numerically positive definite (sparse: see SPDSolver).

    >>> solve_spd(np.array([[4.0, 1.0], [1.0, 3.0]]), np.array([1.0, 2.0])).round(4)
    array([0.0909, 0.6364])
    """
    if isolate_nonfinite:
        matrix = sp.csr_matrix(matrix)
        ok = _direct.nonfinite_blocks(matrix, rhs)
        if ok is not None:
            x = np.full(rhs.shape, np.nan)
            if ok.any():
                x[ok] = solve_spd(matrix[ok][:, ok], rhs[ok])
            return x
    if matrix.shape[0] > tuning.DENSE_UNKNOWNS:
        # small systems: SciPy without its warning when CHOLMOD is missing
        backend = "auto" if cholmod_available() else "scipy"
        return SPDSolver(sp.csc_matrix(matrix), ordering="amd", backend=backend).solve(np.asarray(rhs))
    from scipy.linalg.lapack import dpotrf, dpotrs  # cho_factor/cho_solve's calls, without their checks

    dense = matrix.toarray() if sp.issparse(matrix) else np.asarray(matrix, dtype=np.float64)
    rhs = np.asarray(rhs, dtype=np.float64)
    if not (np.isfinite(dense).all() and np.isfinite(rhs).all()):
        raise ValueError("array must not contain infs or NaNs")
    if not len(dense):
        return np.zeros(rhs.shape)
    factor, info = dpotrf(dense, lower=0, clean=0)
    if info > 0:
        raise SingularSystemError(
            f"the system is not positive definite: {info}-th leading minor of the array is not positive definite"
        )
    return dpotrs(factor, rhs, lower=0)[0]

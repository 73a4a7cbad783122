"""The CHOLMOD gateway: the only module that imports ``sksparse.cholmod``.

:class:`SPDSolver` factors a sparse symmetric positive definite matrix once,
solves ``(n,)`` or ``(n, k)`` right-hand sides in one call, refactors a matrix
of the same pattern reusing the symbolic analysis (the fill-reducing ordering
is about half of a large solve), and applies rank-k updates ``A + C C^T`` in
place. Without scikit-sparse it falls back to SciPy's ``splu`` with a warning,
refactoring where CHOLMOD would update.
"""

from __future__ import annotations

import importlib
import threading
import warnings
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ._errors import O3DLSMeshWarning, SingularSystemError
from ._validate import as_choice

__all__ = ["SPDSolver", "cholmod_available", "ORDERINGS"]

ORDERINGS = ("default", "nesdis", "metis", "amd", "colamd", "natural")


def _import_cholmod():
    try:
        # ``import sksparse`` alone does not load the submodule: import it by name.
        return importlib.import_module("sksparse.cholmod")
    except ImportError:
        return None


_cholmod = _import_cholmod()


def cholmod_available() -> bool:
    """Whether scikit-sparse's CHOLMOD can be imported."""
    return _cholmod is not None


def _as_csc(matrix: Any, *, name: str = "matrix", square: bool = True) -> sp.csc_matrix:
    """``matrix`` as canonical float64 CSC (sorted, summed) with CHOLMOD's 32-bit indices where they fit.

    The caller's arrays are not touched: a non-canonical matrix is copied first.
    """
    if not sp.issparse(matrix):
        raise TypeError(f"{name} must be a scipy sparse matrix, got {type(matrix).__name__}")
    if square and matrix.shape[0] != matrix.shape[1]:
        raise ValueError(f"{name} must be square, got shape {matrix.shape}")
    csc = sp.csc_matrix(matrix, dtype=np.float64)
    if not csc.has_canonical_format:
        csc = csc.copy()
        csc.sum_duplicates()
    if csc.indices.dtype != np.int32 and max(csc.nnz, *csc.shape) < np.iinfo(np.int32).max:
        # CHOLMOD's int interface: the long one would copy and store 64-bit indices
        csc = sp.csc_matrix((csc.data, csc.indices.astype(np.int32), csc.indptr.astype(np.int32)), shape=csc.shape)
    return csc


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


class SPDSolver:
    """Factor a sparse SPD matrix once and solve, refactor or update it.

    Parameters
    ----------
    matrix : (n, n) scipy sparse matrix or None
        Symmetric positive definite: the whole matrix, or only its lower
        triangle with ``lower=True`` (which lets the caller free the whole one).
        ``None`` with ``product_of``.
    product_of : (n, k) scipy sparse matrix, optional, keyword-only
        Factor ``A A^T`` for this ``A`` without forming the product (CHOLMOD
        assembles it column by column while it factors): the normal matrix of a
        least-squares problem ``min |A^T x - b|`` from the transposed rows, in
        less memory and time than ``A @ A.T``. Updates append their columns to
        ``A``.
    backend : {"auto", "cholmod", "scipy"}
        ``"auto"`` takes CHOLMOD when scikit-sparse imports, else SciPy's
        ``splu`` with an :class:`O3DLSMeshWarning`.
    lower : bool
        ``matrix`` holds only its lower triangle.
    ordering : {"default", "nesdis", "metis", "amd", "colamd", "natural"}
        CHOLMOD's fill-reducing ordering. ``"default"`` lets CHOLMOD pick the
        least fill (usually AMD on meshes). ``"nesdis"`` (nested dissection) has
        a balanced elimination tree, the structure the geometry-aware bases
        paper's update bound assumes: rank-1 updates touch fewer entries, at
        the price of a slower factor and solve. Ignored by the SciPy backend.

    Attributes
    ----------
    backend : str
        The backend that actually runs, ``"cholmod"`` or ``"scipy"``.
    shape : tuple of int

    Notes
    -----
    Solves and updates hold a lock: CHOLMOD's common workspace is shared by
    the factor, so one solver may be used from several threads but its calls
    run one at a time. A solver pickles as its matrix and refactors on load.

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
        ordering: str = "default",
        lower: bool = False,
        product_of: Any = None,
    ) -> None:
        backend = as_choice(backend, ("auto", "cholmod", "scipy"), name="backend")
        self.ordering = as_choice(ordering, ORDERINGS, name="ordering")
        if backend == "cholmod" and _cholmod is None:
            raise ImportError(
                "backend='cholmod' needs scikit-sparse: pip install 'o3d_lsmesh[cholmod]' "
                "(after apt-get install libsuitesparse-dev)"
            )
        if backend == "auto":
            if _cholmod is None:
                warnings.warn(
                    "scikit-sparse is not importable; solving with scipy.sparse.linalg.splu, "
                    "which is slower and refactors instead of updating",
                    O3DLSMeshWarning,
                    stacklevel=2,
                )
                backend = "scipy"
            else:
                backend = "cholmod"
        self.backend = backend
        self._lock = threading.RLock()
        # CHOLMOD reads only the lower triangle, so it is all that is kept (half the memory
        # while the factor is computed); SciPy's LU needs the whole matrix
        self._lower = self.backend == "cholmod"
        self._matrix: sp.csc_matrix | None = None
        self._product_of: sp.csc_matrix | None = None
        if (matrix is None) == (product_of is None):
            raise TypeError("pass exactly one of matrix and product_of")
        if product_of is None:
            self._matrix = _stored(_as_csc(matrix), given_lower=bool(lower), keep_lower=self._lower)
        else:
            self._product_of = _as_csc(product_of, name="product_of", square=False)
        self._pending: list[sp.csc_matrix] = []
        self._factor: Any = None
        self._factorize(analyze=True)

    @property
    def shape(self) -> tuple[int, int]:
        if self._product_of is not None:
            return (self._product_of.shape[0],) * 2
        return self._matrix.shape

    @property
    def matrix(self) -> sp.csc_matrix:
        """The whole matrix currently factored, updates included, ``(n, n)`` CSC."""
        with self._lock:
            self._flush()
            if self._product_of is not None:
                product = (self._product_of @ self._product_of.T).tocsc()
                product.sort_indices()
                return product
            if not self._lower:
                return self._matrix
            return _symmetric_from_lower(self._matrix)

    def _flush(self) -> None:
        if self._pending:
            if self._product_of is not None:
                # A A^T + C C^T = [A C] [A C]^T
                self._product_of = sp.hstack([self._product_of, *self._pending], format="csc")
                self._pending.clear()
                return
            for c in self._pending:
                product = c @ c.T
                self._matrix = (self._matrix + (sp.tril(product) if self._lower else product)).tocsc()
            self._pending.clear()
            self._matrix.sort_indices()

    def _factorize(self, *, analyze: bool) -> None:
        try:
            if self.backend == "cholmod" and self._product_of is not None:
                if analyze or self._factor is None:
                    self._factor = _cholmod.analyze_AAt(self._product_of, ordering_method=self.ordering)
                self._factor.cholesky_AAt_inplace(self._product_of)
            elif self.backend == "cholmod":
                if analyze or self._factor is None:
                    self._factor = _cholmod.analyze(self._matrix, ordering_method=self.ordering)
                self._factor.cholesky_inplace(self._matrix)
            elif self._product_of is not None:
                product = (self._product_of @ self._product_of.T).tocsc()
                self._factor = spla.splu(product, permc_spec="MMD_AT_PLUS_A")
            else:
                self._factor = spla.splu(self._matrix, permc_spec="MMD_AT_PLUS_A")
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
            raise TypeError("refactor takes a matrix, and this solver factors a product: build a new SPDSolver")
        csc = _as_csc(matrix)
        if csc.shape != self._matrix.shape:
            raise ValueError(f"matrix must have shape {self._matrix.shape}, got {csc.shape}")
        with self._lock:
            self._matrix = _stored(csc, given_lower=lower, keep_lower=self._lower)
            self._pending.clear()
            self._factorize(analyze=False)

    def solve(self, rhs: Any) -> np.ndarray:
        """Solve ``A x = rhs`` for an ``(n,)`` or ``(n, k)`` right-hand side, all columns at once."""
        b = np.asarray(rhs, dtype=np.float64)
        n = self.shape[0]
        if b.shape[:1] != (n,) or b.ndim > 2:
            raise ValueError(f"rhs must have shape ({n},) or ({n}, k), got {b.shape}")
        with self._lock:
            if self.backend == "cholmod":
                x = self._factor(b)
            else:
                x = self._factor.solve(np.asfortranarray(b))
        if not np.all(np.isfinite(x)):
            raise SingularSystemError("the factored matrix is numerically singular: the solve returned non-finite values")
        return np.asarray(x)

    def update(self, c: Any) -> None:
        """Replace ``A`` by ``A + C C^T`` (CHOLMOD rank-k update, no refactoring).

        ``C`` is an ``(n, k)`` sparse matrix in the matrix's own row order:
        CHOLMOD applies its fill-reducing permutation itself.
        """
        if not (sp.isspmatrix_csc(c) and c.dtype == np.float64):
            c = sp.csc_matrix(c, dtype=np.float64)
        if c.shape[0] != self.shape[0]:
            raise ValueError(f"C must have {self.shape[0]} rows, got shape {c.shape}")
        if not c.has_sorted_indices:
            c = c.sorted_indices()
        with self._lock:
            self._pending.append(c)
            if self.backend == "cholmod":
                self._factor.update_inplace(c)
            else:
                self._flush()
                self._factorize(analyze=True)

    def __getstate__(self) -> dict:
        with self._lock:
            self._flush()
            return {
                "backend": self.backend,
                "ordering": self.ordering,
                "matrix": self._matrix,
                "lower": self._lower,
                "product_of": self._product_of,
            }

    def __setstate__(self, state: dict) -> None:
        self.backend = state["backend"]
        self.ordering = state.get("ordering", "default")
        if self.backend == "cholmod" and _cholmod is None:
            self.backend = "scipy"
        self._lock = threading.RLock()
        was_lower = state.get("lower", False)
        self._lower = self.backend == "cholmod"
        self._product_of = state.get("product_of")
        self._matrix = None
        if self._product_of is None:
            self._matrix = _stored(state["matrix"], given_lower=was_lower, keep_lower=self._lower)
        self._pending = []
        self._factor = None
        self._factorize(analyze=True)

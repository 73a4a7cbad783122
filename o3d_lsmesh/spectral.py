"""Spectral mesh compression baseline (Karni and Gotsman, 2000), as compared in the geometry-aware bases paper.

The geometry is projected on the first ``k`` eigenvectors of the symmetric
combinatorial Laplacian ``L = D - A`` (section II of Sorkine et al.,
*Geometry-aware Bases for Shape Approximation*; ``D`` the valences, ``A`` the
adjacency), the smoothest orthonormal mesh functions. Only small meshes are
practical: the eigenvectors cost ``O(n k)`` memory and about ``O(n k^2)`` time.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ._o3d import new_mesh, read_mesh
from ._solvers import SPDSolver
from ._validate import as_count
from .topology import adjacency_matrix

__all__ = ["spectral_approximation", "combinatorial_laplacian", "SPECTRAL_MAX_VERTICES"]

# Measured on 2 busy cores (eigsh, shift-invert through CHOLMOD): 100 eigenvectors take
# 0.1 s at 3k vertices, 0.4 s at 10k, 1.8 s at 20k and 5 s at 50k; 300 at 10k take 3.6 s
# and 600 at 3k about 10 to 50 s. Beyond 50k vertices a useful number of
# eigenvectors (thousands) is out of reach, as the paper found at 11k with MATLAB.
SPECTRAL_MAX_VERTICES = 50_000
# Lanczos basis of 2k + 1 vectors of n doubles: n * k <= 2e7 keeps it near 300 MB.
SPECTRAL_MAX_WORK = 20_000_000
# Above k > n / 4, LAPACK's dense eigh beats ARPACK (1.7 s against 170 s for 1500 of
# 3000 eigenvectors); a dense n x n matrix is 200 MB at n = 5000.
DENSE_MAX_VERTICES = 5_000
_SHIFT = -1e-6  # L - sigma I is positive definite for sigma < 0; 0 is an eigenvalue


def combinatorial_laplacian(triangles: np.ndarray, n: int) -> sp.csc_matrix:
    """Symmetric combinatorial Laplacian ``L = D - A`` ``(n, n)`` CSC (bases paper, section II)."""
    adjacency = adjacency_matrix(triangles, n)
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    return (sp.diags(degree) - adjacency).tocsc()


def spectral_basis(triangles: np.ndarray, n: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` smallest eigenpairs of ``D - A``: ``(eigenvalues (k,), eigenvectors (n, k))``, ascending.

    ``scipy.sparse.linalg.eigsh`` in shift-invert mode around ``sigma = -1e-6``,
    with ``(L - sigma I)^-1`` applied by the CHOLMOD gateway; dense LAPACK
    ``eigh`` when ``k > n / 4`` on meshes up to 5000 vertices. Raises
    ``ValueError`` beyond the measured practical sizes (see module constants).
    """
    if n > SPECTRAL_MAX_VERTICES:
        raise ValueError(
            f"mesh must have at most {SPECTRAL_MAX_VERTICES} vertices for the spectral baseline "
            f"(eigenvectors cost O(n k) memory and O(n k^2) time), got {n}; use encode_geometry or approximate"
        )
    L = combinatorial_laplacian(triangles, n)
    if k > n // 4:
        if n > DENSE_MAX_VERTICES:
            raise ValueError(
                f"k must be at most n / 4 = {n // 4} on meshes above {DENSE_MAX_VERTICES} vertices "
                f"(more eigenvectors need a dense eigensolver), got k = {k} with n = {n}"
            )
        values, vectors = sla.eigh(L.toarray(), subset_by_index=[0, k - 1])
        return values, vectors
    if n * k > SPECTRAL_MAX_WORK:
        raise ValueError(
            f"k must be at most {SPECTRAL_MAX_WORK // n} for a mesh of {n} vertices "
            f"(the Lanczos basis would exceed n * k = {SPECTRAL_MAX_WORK:.0e} doubles), got {k}"
        )
    factor = SPDSolver(L - _SHIFT * sp.identity(n, format="csc"))
    inverse = spla.LinearOperator((n, n), matvec=factor.solve, dtype=np.float64)
    start = np.random.default_rng(0).standard_normal(n)  # reproducible Lanczos start
    values, vectors = spla.eigsh(L, k=k, sigma=_SHIFT, which="LM", OPinv=inverse, v0=start)
    order = np.argsort(values)
    return values[order], vectors[:, order]


def quantize_coefficients(coefficients: np.ndarray, bits: int) -> np.ndarray:
    """Uniformly quantize each column to ``bits`` bits in its ``[min, max]`` and return the dequantized values."""
    levels = (1 << bits) - 1
    lower, upper = coefficients.min(axis=0), coefficients.max(axis=0)
    extent = upper - lower
    scale = np.divide(levels, extent, out=np.zeros_like(extent), where=extent > 0)
    q = np.rint((coefficients - lower) * scale)
    return lower + q * np.divide(extent, levels)


def spectral_approximation(mesh: Any, k: int, *, bits: int | None = None) -> Any:
    """Project the geometry on the first ``k`` Laplacian eigenvectors (Karni and Gotsman's spectral compression).

    With ``U (n, k)`` the eigenvectors of the ``k`` smallest eigenvalues of
    ``L = D - A`` (orthonormal columns), the result is ``U (U^T X)`` for the
    vertex positions ``X (n, 3)``: the best ``k``-term approximation in the
    Laplacian-spectral basis of section II of the geometry-aware bases paper.
    ``bits`` quantizes the ``3k`` coefficients first (Karni and Gotsman use 14).

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
        At most 50,000 vertices.
    k : int
        Number of basis functions, ``1..n``.
    bits : int, optional
        Quantization bits per coefficient, 1 to 31; default no quantization.

    Returns
    -------
    TriangleMesh
        A new mesh of the input's kind with the approximated positions.

    Raises
    ------
    ValueError
        ``k`` out of range, ``bits`` out of range, or a mesh or ``k`` beyond the
        practical sizes: more than 50,000 vertices, ``n * k > 2e7``, or
        ``k > n / 4`` above 5,000 vertices.

    Examples
    --------
    >>> import open3d as o3d, numpy as np
    >>> sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=10)
    >>> n = len(sphere.vertices)
    >>> full = spectral_approximation(sphere, n)
    >>> bool(np.allclose(np.asarray(full.vertices), np.asarray(sphere.vertices)))
    True
    """
    data = read_mesh(mesh, weld=True)
    n = len(data.vertices)
    k = as_count(k, name="k", minimum=1, maximum=n)
    if bits is not None:
        bits = as_count(bits, name="bits", minimum=1, maximum=31)
    _, basis = spectral_basis(data.triangles, n, k)
    coefficients = basis.T @ data.vertices
    if bits is not None:
        coefficients = quantize_coefficients(coefficients, bits)
    return new_mesh(data, basis @ coefficients)

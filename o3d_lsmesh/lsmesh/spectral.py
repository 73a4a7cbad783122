"""Spectral mesh compression baseline (Karni and Gotsman, 2000), as compared in the geometry-aware bases paper.

The geometry projected on the first ``k`` eigenvectors of ``D - A`` (bases paper, section II); small
meshes only. Docs: ``docs/algorithms/least_squares_meshes.rst``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse import csgraph

from .._o3d import new_mesh, read_mesh
from ..core.arrays import dequantize, quantize
from ..core.connectivity import Connectivity
from ..core.errors import InputError
from ..core.operators import graph_laplacian
from ..core.progress import Progress
from ..core.solve import SPDSolver, single_threaded_blas
from ..core.validate import as_bool, as_count

if TYPE_CHECKING:
    from .._types import MeshT

__all__ = ["SPECTRAL_MAX_VERTICES", "combinatorial_laplacian", "null_space_basis", "spectral_approximation"]

# Practical sizes (time and memory of the eigenvectors): benchmarks/results/spectral.md
SPECTRAL_MAX_VERTICES = 50_000  # beyond, a useful k is out of reach: spectral.md, eigensolve times
SPECTRAL_MAX_WORK = 20_000_000  # n * k of the Lanczos basis (about 300 MB): spectral.md, eigensolve times
DENSE_MAX_VERTICES = 5_000  # dense eigh for k > n / 4 up to this n: spectral.md, dense against ARPACK
_SHIFT = -1e-6  # L - sigma I is positive definite for sigma < 0; 0 is an eigenvalue


def combinatorial_laplacian(triangles: np.ndarray, n: int) -> sp.csc_matrix:
    """Symmetric combinatorial Laplacian ``L = D - A`` ``(n, n)`` CSC (bases paper, section II)."""
    return graph_laplacian(Connectivity(triangles, n))


def null_space_basis(adjacency: sp.spmatrix) -> sp.csc_matrix:
    """Orthonormal null space of ``D - A``, ``(n, c)`` CSC: column ``j`` is ``1 / sqrt(size)`` on the ``j``-th
    largest component (ties to the smaller first vertex; an isolated vertex is one), exact eigenvectors of 0."""
    n = adjacency.shape[0]
    count, labels = csgraph.connected_components(adjacency, directed=False)
    size = np.bincount(labels, minlength=count)
    rank = np.empty(count, dtype=np.int64)
    rank[np.lexsort((np.arange(count), -size))] = np.arange(count)  # largest first, stable
    return sp.csc_matrix((1.0 / np.sqrt(size[labels]), (np.arange(n), rank[labels])), shape=(n, count))


def spectral_basis(
    triangles: np.ndarray, n: int, k: int, *, progress: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` smallest eigenpairs of ``D - A``, ascending: ``(eigenvalues (k,), eigenvectors (n, k))``; the
    null space written down, the rest by ARPACK on the deflated shift-invert operator (solves by the
    gateway) or dense ``eigh`` (docs page). ``InputError`` beyond the practical sizes (module constants)."""
    if n > SPECTRAL_MAX_VERTICES:
        raise InputError(
            f"mesh must have at most {SPECTRAL_MAX_VERTICES} vertices for the spectral baseline "
            f"(eigenvectors cost O(n k) memory and O(n k^2) time), got {n}; use encode_geometry or approximate",
            param="mesh",
        )
    dense = k > n // 4
    if dense and n > DENSE_MAX_VERTICES:
        raise InputError(
            f"k must be at most n / 4 = {n // 4} on meshes above {DENSE_MAX_VERTICES} vertices "
            f"(more eigenvectors need a dense eigensolver), got k = {k} with n = {n}",
            param="k",
        )
    if not dense and n * k > SPECTRAL_MAX_WORK:
        raise InputError(
            f"k must be at most {SPECTRAL_MAX_WORK // n} for a mesh of {n} vertices "
            f"(the Lanczos basis would exceed n * k = {SPECTRAL_MAX_WORK:.0e} doubles), got {k}",
            param="k",
        )
    as_bool(progress, name="progress")
    L = combinatorial_laplacian(triangles, n)
    Z = null_space_basis(L)  # (n, c): the components of L's graph are the mesh's
    c = Z.shape[1]
    if k <= c:  # only eigenvalue 0: the k largest components' indicators
        return np.zeros(k), Z[:, :k].toarray()
    m = k - c
    # ARPACK needs m well below the rank n - c of the deflated operator; small meshes go dense
    dense = dense or (m > (n - c) // 4 and n <= DENSE_MAX_VERTICES)
    stage_names = ("eigensolve (dense)",) if dense else ("factor", "eigensolve")
    with Progress(progress, "spectral basis").stages(stage_names) as begin:
        if dense:
            begin("eigensolve (dense)")
            # indices c..k-1: past the c zero eigenvalues, the smallest nonzero ones
            values, vectors = sla.eigh(L.toarray(), subset_by_index=[c, k - 1])
        else:
            begin("factor")
            factor = SPDSolver(L - _SHIFT * sp.identity(n, format="csc"))
            ZT = Z.T.tocsr()

            def deflate(x: np.ndarray) -> np.ndarray:
                return x - Z @ (ZT @ x)

            def apply(x: np.ndarray) -> np.ndarray:
                # the solve amplifies round-off along the null space by 1 / -sigma: project after it too
                return deflate(factor.solve(deflate(np.ravel(x))))

            operator = spla.LinearOperator((n, n), matvec=apply, dtype=np.float64)
            start = deflate(np.random.default_rng(0).standard_normal(n))  # reproducible Lanczos start
            begin("eigensolve")
            with single_threaded_blas():
                inverse_values, vectors = spla.eigsh(operator, k=m, which="LA", v0=start)
            values = _SHIFT + 1.0 / inverse_values
            order = np.argsort(values)
            values, vectors = values[order], vectors[:, order]
    return np.concatenate([np.zeros(c), values]), np.hstack([Z.toarray(), vectors])


def quantize_coefficients(coefficients: np.ndarray, bits: int) -> np.ndarray:
    """Each column quantized to ``bits`` bits in its ``[min, max]`` and dequantized (the geometry stream's
    quantizer, so that both compression methods are compared at the same quantization)."""
    lower, upper = coefficients.min(axis=0), coefficients.max(axis=0)
    return dequantize(quantize(coefficients, lower, upper, bits), lower, upper, bits)


def spectral_approximation(mesh: MeshT, k: int, *, bits: int | None = None, progress: bool = False) -> MeshT:
    """Project the geometry on the first ``k`` Laplacian eigenvectors (Karni and Gotsman's spectral compression).

    ``c + U (U^T (X - c))`` for positions ``X (n, 3)``, their centroid ``c`` and ``U (n, k)`` the eigenvectors
    of the ``k`` smallest eigenvalues of ``D - A`` (bases paper, section II); ``bits`` quantizes the ``3k``
    coefficients first (Karni and Gotsman use 14). With ``k`` below the number of components, the ``k``
    largest are kept (the others go to ``c``).

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
        At most 50,000 vertices.
    k, bits : int
        Basis functions, ``1..n``; optional quantization bits per coefficient, 1 to 31.
    progress : bool

    Raises
    ------
    InputError
        ``k`` or ``bits`` out of range, or beyond the practical sizes (module constants).

    Examples
    --------
    >>> import open3d as o3d, numpy as np
    >>> sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=10)
    >>> bool(np.allclose(spectral_approximation(sphere, len(sphere.vertices)).vertices, sphere.vertices))
    True
    """
    as_bool(progress, name="progress")
    data = read_mesh(mesh, weld=True)
    n = len(data.vertices)
    k = as_count(k, name="k", minimum=1, maximum=n)
    if bits is not None:
        bits = as_count(bits, name="bits", minimum=1, maximum=31)
    _, basis = spectral_basis(data.triangles, n, k, progress=progress)
    # about the centroid: the constant vectors' coefficients would carry the mesh's distance from the
    # origin into the quantizer's range (1000 sizes away, 12 bits lost the shape)
    centre = data.vertices.mean(axis=0)
    coefficients = basis.T @ (data.vertices - centre)
    if bits is not None:
        coefficients = quantize_coefficients(coefficients, bits)
    return new_mesh(data, basis @ coefficients + centre)

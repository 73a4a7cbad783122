"""The public mesh Laplacian ``L = I - D^-1 W`` (eq. 1 of Least-squares Meshes) over :mod:`o3d_lsmesh.core.operators`."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from ._o3d import read_mesh
from .core import operators
from .core.connectivity import Connectivity
from .core.validate import as_choice

if TYPE_CHECKING:
    from ._types import AnyMesh

__all__ = ["cotangent_laplacian", "laplacian", "laplacian_matrix", "uniform_laplacian"]


def uniform_laplacian(triangles: np.ndarray, n: int) -> sp.csr_matrix:
    """:func:`o3d_lsmesh.core.operators.uniform_laplacian` of ``triangles``."""
    return operators.uniform_laplacian(Connectivity(triangles, n))


def cotangent_laplacian(vertices: np.ndarray, triangles: np.ndarray) -> sp.csr_matrix:
    """:func:`o3d_lsmesh.core.operators.cotangent_laplacian` of ``triangles``."""
    return operators.cotangent_laplacian(vertices, Connectivity(triangles, len(vertices)))


def laplacian_matrix(vertices: np.ndarray, triangles: np.ndarray, kind: str = "uniform") -> sp.csr_matrix:
    """Array twin of :func:`laplacian`."""
    kind = as_choice(kind, operators.LAPLACIAN_KINDS, name="kind")
    return operators.laplacian_of_kind(vertices, Connectivity(triangles, len(vertices)), kind)


def laplacian(mesh: AnyMesh, kind: str = "uniform") -> sp.csr_matrix:
    """The ``(n, n)`` Laplacian operator of a mesh, ``L = I - D^-1 W`` (scipy CSR).

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh or open3d.t.geometry.TriangleMesh
    kind : {"uniform", "cotangent"}
        ``"uniform"``: ``W`` the adjacency (eq. 1 of Least-squares Meshes); ``"cotangent"``:
        cotangent weights, normalized per row.

    Returns
    -------
    L : (n, n) scipy.sparse.csr_matrix
        ``(L x)_i = x_i - sum_j W_ij x_j / sum_j W_ij``; ``L @ 1 = 0``, diagonal 1 (0 for
        unreferenced vertices).

    Examples
    --------
    >>> import open3d as o3d, numpy as np
    >>> L = laplacian(o3d.geometry.TriangleMesh.create_sphere())
    >>> bool(np.allclose(L @ np.ones(L.shape[0]), 0))
    True
    """
    data = read_mesh(mesh)
    return laplacian_matrix(data.vertices, data.triangles, kind)

"""Mesh Laplacians ``L = I - D^-1 W``: uniform (eq. 1 of Least-squares Meshes) and cotangent."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from ._o3d import read_mesh
from ._validate import as_choice
from .topology import adjacency_matrix, edge_structure, ring_pattern

if TYPE_CHECKING:
    from ._types import AnyMesh

__all__ = ["cotangent_laplacian", "laplacian", "laplacian_matrix", "uniform_laplacian"]

LAPLACIAN_KINDS = ("uniform", "cotangent")


def _normalized(weights: sp.csr_matrix, n: int) -> sp.csr_matrix:
    row_sum = np.asarray(weights.sum(axis=1)).ravel()
    inv = np.zeros(n)
    np.divide(1.0, row_sum, out=inv, where=row_sum > 0)
    has_neighbours = (row_sum > 0).astype(np.float64)
    return (sp.diags(has_neighbours) - sp.diags(inv) @ weights).tocsr()


def uniform_laplacian(triangles: np.ndarray, n: int, *, edges: np.ndarray | None = None) -> sp.csr_matrix:
    """Uniform Laplacian ``(n, n)`` CSR of eq. 1: ``L_ii = 1``, ``L_ij = -1/d_i`` for each edge neighbour ``j``.

    ``(L x)_i = x_i - mean of the neighbours of i``: positive where ``x_i`` sticks
    out above its neighbours (the sign of Least-squares Meshes, eq. 1). Rows sum
    to zero. Rows of unreferenced vertices are all zero. ``edges``: the mesh's
    undirected edges ``(e, 2)`` (``lo < hi``, sorted, as in
    :class:`~o3d_lsmesh.topology.EdgeStructure`) when the caller has them:
    the matrix is then written into the 1-ring pattern without another edge sort.

    Examples
    --------
    >>> import numpy as np
    >>> L = uniform_laplacian(np.array([[0, 1, 2]]), 3)
    >>> L.toarray().tolist()
    [[1.0, -0.5, -0.5], [-0.5, 1.0, -0.5], [-0.5, -0.5, 1.0]]
    """
    if edges is None:
        laplacian = _laplacian_from_edges(edge_structure(triangles, n).edges, n)
        laplacian.eliminate_zeros()  # the explicit zeros on unreferenced vertices' diagonals
        return laplacian
    return _laplacian_from_edges(edges, n)


def _laplacian_from_edges(edges: np.ndarray, n: int) -> sp.csr_matrix:
    # written straight into the 1-ring CSR layout; rows of isolated vertices keep an explicit zero on the
    # diagonal (same operator)
    indptr, indices, diagonal, forward, backward = ring_pattern(edges, n)
    degree = np.bincount(edges.ravel(), minlength=n)
    inv = np.zeros(n)
    np.divide(-1.0, degree, out=inv, where=degree > 0)
    data = np.empty(len(indices))
    data[diagonal] = degree > 0
    data[forward] = inv[edges[:, 0]]
    data[backward] = inv[edges[:, 1]]
    laplacian = sp.csr_matrix((data, indices, indptr), shape=(n, n))
    laplacian.has_canonical_format = True
    return laplacian


def cotangent_laplacian(vertices: np.ndarray, triangles: np.ndarray) -> sp.csr_matrix:
    """Normalized cotangent Laplacian ``(n, n)`` CSR: ``L = I - D^-1 W``.

    ``W_ij = (cot alpha_ij + cot beta_ij) / 2`` over the angles opposite edge
    ``ij`` and ``D = diag(W 1)``: the same sign convention and row normalization
    as :func:`uniform_laplacian`, with geometry-dependent weights (the "other
    discretizations" of the paper's conclusion). Cotangents of near-zero angles
    are clamped to ``+-1e4`` so that zero-area triangles give finite weights;
    rows whose weights sum to zero or less fall back to uniform weights.
    """
    n = len(vertices)
    v = vertices[triangles]  # (m, 3, 3)
    cots = []
    for p in range(3):  # the corner opposite edge (p+1, p+2)
        a = v[:, (p + 1) % 3] - v[:, p]
        b = v[:, (p + 2) % 3] - v[:, p]
        dot = np.einsum("ij,ij->i", a, b)
        cross = np.linalg.norm(np.cross(a, b), axis=1)
        cot = np.divide(dot, cross, out=np.sign(dot) * 1e4, where=cross > 1e-300)
        cots.append(np.clip(cot, -1e4, 1e4))
    rows = np.concatenate([triangles[:, 1], triangles[:, 2], triangles[:, 0]])
    cols = np.concatenate([triangles[:, 2], triangles[:, 0], triangles[:, 1]])
    data = 0.5 * np.concatenate(cots)
    weights = sp.csr_matrix((data, (rows, cols)), shape=(n, n))
    weights = (weights + weights.T).tocsr()
    row_sum = np.asarray(weights.sum(axis=1)).ravel()
    degenerate = row_sum <= 1e-12 * max(1.0, np.abs(weights).sum() / max(n, 1))
    if degenerate.any():
        # rows that cotangents cannot normalize take uniform weights instead
        fallback = sp.diags(degenerate.astype(np.float64))
        keep = sp.diags((~degenerate).astype(np.float64))
        weights = keep @ weights + fallback @ adjacency_matrix(triangles, n)
    return _normalized(sp.csr_matrix(weights), n)


def laplacian_matrix(vertices: np.ndarray, triangles: np.ndarray, kind: str = "uniform") -> sp.csr_matrix:
    """Array twin of :func:`laplacian`."""
    kind = as_choice(kind, LAPLACIAN_KINDS, name="kind")
    if kind == "uniform":
        return uniform_laplacian(triangles, len(vertices))
    return cotangent_laplacian(vertices, triangles)


def laplacian(mesh: AnyMesh, kind: str = "uniform") -> sp.csr_matrix:
    """The ``(n, n)`` Laplacian operator of a mesh, ``L = I - D^-1 W`` (scipy CSR).

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh or open3d.t.geometry.TriangleMesh
    kind : {"uniform", "cotangent"}
        ``"uniform"``: ``W`` is the adjacency matrix, eq. 1 of Least-squares
        Meshes (depends on connectivity only). ``"cotangent"``: cotangent weights,
        normalized per row.

    Returns
    -------
    L : (n, n) scipy.sparse.csr_matrix
        Sign convention: ``(L x)_i = x_i - sum_j W_ij x_j / sum_j W_ij``, the
        vertex minus the weighted average of its neighbours; ``L @ 1 = 0`` and
        the diagonal is 1 (0 for unreferenced vertices).

    Examples
    --------
    >>> import open3d as o3d, numpy as np
    >>> L = laplacian(o3d.geometry.TriangleMesh.create_sphere())
    >>> bool(np.allclose(L @ np.ones(L.shape[0]), 0))
    True
    """
    data = read_mesh(mesh)
    return laplacian_matrix(data.vertices, data.triangles, kind)

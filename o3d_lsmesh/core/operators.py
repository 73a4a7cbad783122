"""Every sparse matrix the papers use, built from a :class:`~.connectivity.Connectivity`; nothing is solved here.

Least-squares meshes (Sorkine & Cohen-Or 2004): uniform and cotangent Laplacians (eq. 1), the graph
Laplacian ``D - A``, the hole patch's continuity-0/1/2 system. Liu et al. 2001: the local operator
(eq. 6-7) and the barycenter penalty (eq. 5), the boundary-curve Laplacian (section 3.3). The scan
energy's normal matrix ``K^T K + mu H^T W H + lambda G`` and the umbrella (1- and 2-ring) weights.
Docs: ``docs/algorithms/`` (one page per method).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .connectivity import (
    Connectivity,
    VertexRings,
    ring_pattern,
)

__all__ = [
    "cotangent_laplacian",
    "graph_laplacian",
    "rim_neighbours",
    "single_slots",
    "two_ring_rows",
    "umbrella",
    "umbrella_weights",
    "uniform_from_edges",
    "uniform_laplacian",
]

# ---------------------------------------------------------------------------------- eq. 1 and D - A


def uniform_laplacian(conn: Connectivity, *, keep_pattern: bool = False) -> sp.csr_matrix:
    """Uniform Laplacian ``(n, n)`` CSR of eq. 1: ``L_ii = 1``, ``L_ij = -1/d_i`` for each edge neighbour.

    ``(L x)_i`` is ``x_i`` minus the mean of its neighbours; rows of unreferenced vertices are zero
    (an explicit zero on their diagonal with ``keep_pattern``: the full 1-ring pattern).

    >>> uniform_laplacian(Connectivity(np.array([[0, 1, 2]]), 3)).toarray()[0].tolist()
    [1.0, -0.5, -0.5]
    """
    laplacian = uniform_from_edges(conn.edges, conn.n)
    if not keep_pattern:
        laplacian.eliminate_zeros()  # the explicit zeros on unreferenced vertices' diagonals
    return laplacian


def uniform_from_edges(edges: np.ndarray, n: int) -> sp.csr_matrix:
    """:func:`uniform_laplacian` on the 1-ring pattern of sorted ``edges (e, 2)`` (``lo < hi``)."""
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


def _normalized(weights: sp.csr_matrix, n: int) -> sp.csr_matrix:
    row_sum = np.asarray(weights.sum(axis=1)).ravel()
    inv = np.zeros(n)
    np.divide(1.0, row_sum, out=inv, where=row_sum > 0)
    has_neighbours = (row_sum > 0).astype(np.float64)
    return (sp.diags(has_neighbours) - sp.diags(inv) @ weights).tocsr()


def cotangent_laplacian(vertices: np.ndarray, conn: Connectivity) -> sp.csr_matrix:
    """Normalized cotangent Laplacian ``I - D^-1 W`` ``(n, n)`` CSR, ``W_ij = (cot a_ij + cot b_ij) / 2``.

    Cotangents are clamped to ``+-1e4``; rows whose weights sum to zero or less take uniform weights.

    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> cotangent_laplacian(V, Connectivity(np.array([[0, 1, 2]]))).toarray()[0].round(3).tolist()
    [1.0, -0.5, -0.5]
    """
    triangles, n = conn.triangles, len(vertices)
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
        weights = keep @ weights + fallback @ conn.adjacency
    return _normalized(sp.csr_matrix(weights), n)


def graph_laplacian(conn: Connectivity) -> sp.csc_matrix:
    """Symmetric combinatorial Laplacian ``D - A`` ``(n, n)`` CSC.

    >>> graph_laplacian(Connectivity(np.array([[0, 1, 2]]))).toarray()[0].tolist()
    [2.0, -1.0, -1.0]
    """
    adjacency = conn.adjacency
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    return (sp.diags(degree) - adjacency).tocsc()


# ---------------------------------------------------------------------------------- umbrellas


def umbrella(vertices: np.ndarray, edges: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Umbrella vectors ``(mean of the edges-neighbours - x_i)`` of the ``mask`` vertices, ``(k, 3)``.

    ``edges (e, 2)`` any undirected edge set (the mesh's: the 1-ring; its boundary edges: the curve).

    >>> umbrella(np.eye(3), np.array([[0, 1], [0, 2]]), np.array([True, False, False])).tolist()
    [[-1.0, 0.5, 0.5]]
    """
    n = len(vertices)
    lo, hi = edges[:, 0], edges[:, 1]
    degree = np.bincount(edges.ravel(), minlength=n)[mask].astype(np.float64)
    total = np.empty((int(mask.sum()), 3))
    for k in range(3):
        total[:, k] = (
            np.bincount(lo, vertices[hi, k], minlength=n) + np.bincount(hi, vertices[lo, k], minlength=n)
        )[mask]
    return total / degree[:, None] - vertices[mask]


def two_ring_rows(ring: sp.csr_matrix, rows: np.ndarray) -> sp.csr_matrix:
    """Binary ``(len(rows), n)`` CSR: the vertices within two edges of each of ``rows``, itself excluded.

    ``ring`` the binary 1-ring adjacency (:attr:`~.connectivity.Connectivity.adjacency`).
    """
    block = ring[rows]
    two = block @ ring + block
    two.data[:] = 1.0
    own = np.repeat(rows, np.diff(two.indptr)) == two.indices  # the vertex itself is not its neighbour
    two.data[own] = 0.0
    two.eliminate_zeros()
    return two


def rim_neighbours(conn: Connectivity, movable: np.ndarray) -> sp.csr_matrix:
    """Binary ``(n, n)`` CSR of the ``movable`` rows: a rim vertex's neighbours along the rim, others' 1-ring."""
    n, counts = conn.n, conn.edge_triangles
    lo, hi = conn.edges[:, 0].astype(np.int64), conn.edges[:, 1].astype(np.int64)
    boundary = np.zeros(n, dtype=bool)
    boundary[conn.edges[counts == 1].ravel()] = True
    on_curve = np.tile(counts == 1, 2)
    rows, cols = np.r_[lo, hi], np.r_[hi, lo]
    keep = movable[rows] & (~boundary[rows] | on_curve)
    return sp.csr_matrix((np.ones(int(keep.sum())), (rows[keep], cols[keep])), shape=(n, n))


def umbrella_weights(rings: VertexRings) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray | None]:
    """Row-stochastic ``W`` on the rings' pattern (zero diagonal): the 1-ring inside, the neighbours along
    the boundary on a boundary; each row's weight ``(n,)``; the boundary vertices (None without any)."""
    n, indptr = rings.n, rings.indptr
    degree = rings.valence.astype(np.float64)
    counts = np.diff(indptr)
    on_boundary = None
    if rings.boundary.any():
        single = single_slots(rings)
        boundary_count = np.add.reduceat(single, indptr[:-1], dtype=np.int64)
        if boundary_count.any():
            on_boundary = boundary_count > 0
            degree[on_boundary] = boundary_count[on_boundary]
    scale = np.divide(1.0, degree, out=np.zeros(n), where=degree > 0)
    data = np.repeat(scale, counts)
    data[rings.diagonal] = 0.0
    if on_boundary is not None:  # a boundary vertex's row reads its curve neighbours only
        np.copyto(data, 0.0, where=np.repeat(on_boundary, counts) & ~single)
    return _csr(data, rings.indices, indptr, n), scale, on_boundary


def single_slots(rings: VertexRings) -> np.ndarray:
    """``(nnz,) bool``: the ring slots on an edge of one triangle (its one entry held twice)."""
    single = rings.pairs[0] == rings.pairs[1]
    single[rings.diagonal] = False
    return single


def _csr(data: np.ndarray, indices: np.ndarray, indptr: np.ndarray, n: int) -> sp.csr_matrix:
    """A canonical ``(n, n)`` CSR matrix on the given arrays (shared, not copied or re-checked)."""
    matrix = sp.csr_matrix((n, n), dtype=np.float64)
    matrix.data, matrix.indices, matrix.indptr = data, indices, indptr
    matrix.has_canonical_format = True  # sorted columns, no duplicates: the rings' pattern
    return matrix

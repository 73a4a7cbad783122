"""Every sparse matrix the papers use, built from a :class:`~.connectivity.Connectivity`; nothing is solved here.

Least-squares meshes (Sorkine & Cohen-Or 2004): uniform and cotangent Laplacians (eq. 1), the graph
Laplacian ``D - A``, the hole patch's continuity-0/1/2 system; the scan energy's normal matrix
``K^T K + mu H^T W H + lambda G``; umbrella (1- and 2-ring) vectors and weights; Liu et al. 2001's
penalty (eq. 5). Their local operator (eq. 6-7) and curve Laplacian (section 3.3): :mod:`.liu`. Docs:
``docs/algorithms/connectivity.rst``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from .arrays import kernel_index
from .connectivity import (
    Connectivity,
    VertexRings,
    ring_pattern,
)
from .liu import ring_csr
from .validate import collapsed_triangles

__all__ = [
    "LAPLACIAN_KINDS",
    "Penalty",
    "cotangent_laplacian",
    "graph_laplacian",
    "laplacian_of_kind",
    "lower_csc",
    "patch_system",
    "penalty_matrix",
    "rim_neighbours",
    "scan_normal_matrix",
    "single_slots",
    "two_ring_sums",
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
    weights = sp.csr_matrix(weights)
    row_sum = np.asarray(weights.sum(axis=1)).ravel()
    inv = np.zeros(n)
    np.divide(1.0, row_sum, out=inv, where=row_sum > 0)
    return (sp.diags((row_sum > 0).astype(np.float64)) - sp.diags(inv) @ weights).tocsr()


#: The Laplacians of eq. 1 a caller may name.
LAPLACIAN_KINDS = ("uniform", "cotangent")


def laplacian_of_kind(vertices: np.ndarray, conn: Connectivity, kind: str) -> sp.csr_matrix:
    """The ``(n, n)`` Laplacian of eq. 1 named by ``kind`` (one of :data:`LAPLACIAN_KINDS`, checked by the caller)."""
    return uniform_laplacian(conn) if kind == "uniform" else cotangent_laplacian(vertices, conn)


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
    from .._block_kernel import edge_sums  # compiled by the package's build: imported where used

    n = len(vertices)
    edges = kernel_index(edges, 2)
    degree = np.bincount(edges.ravel(), minlength=n)[mask].astype(np.float64)
    total = edge_sums(edges, np.ascontiguousarray(vertices, dtype=np.float64))[mask]
    return total / degree[:, None] - vertices[mask]


def two_ring_sums(ring: sp.csr_matrix, rows: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each of ``rows``: the number of vertices within two edges of it, itself excluded, ``(r,)``
    float64, and the sum of their rows of ``values (n, k)``, ``(r, k)``.

    ``ring`` the binary 1-ring adjacency (:attr:`~.connectivity.Connectivity.adjacency`); one compiled
    pass, the 2-ring's matrix never formed.

    >>> c = Connectivity(np.array([[0, 1, 2], [1, 3, 2], [3, 4, 2]]))
    >>> counts, sums = two_ring_sums(c.adjacency, np.array([0]), np.arange(5.0)[:, None])
    >>> counts.tolist(), sums.tolist()
    ([4.0], [[10.0]])
    """
    from .._block_kernel import two_ring_sums as sums  # compiled by the package's build

    index = np.result_type(ring.indptr, ring.indices)
    return sums(
        ring.indptr.astype(index, copy=False),
        ring.indices.astype(index, copy=False),
        np.ascontiguousarray(rows, dtype=np.int64),
        np.ascontiguousarray(values, dtype=np.float64),
    )


def rim_neighbours(conn: Connectivity, movable: np.ndarray) -> sp.csr_matrix:
    """Binary ``(n, n)`` CSR of the ``movable`` rows: a rim vertex's neighbours along the rim, others' 1-ring.

    Cut from the 1-ring pattern (:attr:`~.connectivity.Connectivity.ring_pattern`), canonical.
    """
    n, on_curve = conn.n, conn.boundary_edges
    boundary = conn.rim[0]
    indptr, indices, _, forward, backward = conn.ring_pattern
    lo, hi = conn.edges[:, 0], conn.edges[:, 1]
    data = np.zeros(len(indices))
    data[forward] = movable[lo] & (~boundary[lo] | on_curve)
    data[backward] = movable[hi] & (~boundary[hi] | on_curve)
    # copies: eliminate_zeros works in place, and the pattern is the connectivity's cached one
    neighbours = sp.csr_matrix((data, indices.copy(), indptr.copy()), shape=(n, n))
    neighbours.eliminate_zeros()  # the diagonal and the rows and edges left out
    return neighbours


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
    return ring_csr(data, rings.indices, indptr, n), scale, on_boundary


def single_slots(rings: VertexRings) -> np.ndarray:
    """``(nnz,) bool``: the ring slots on an edge of one triangle (its one entry held twice)."""
    single = rings.pairs[0] == rings.pairs[1]
    single[rings.diagonal] = False
    return single


# ---------------------------------------------------------------------------------- the scan energy


def scan_normal_matrix(
    conn: Connectivity, mu: float, membrane: float, boundary_weight: float, rim_curve: float = 0.0
) -> tuple[sp.csr_matrix, sp.csc_matrix, np.ndarray]:
    """``K^T K + mu H^T W H + lambda G`` ``(n, n)`` CSR (canonical, symmetric), the 1-ring pattern, ``w (m,)``.

    ``H`` the triangle-vertex incidence weighted by ``w_t`` (``boundary_weight`` on a triangle with a
    vertex on an edge of one triangle, else 1), ``G`` the graph Laplacian (``lambda = membrane``),
    ``K`` the uniform Laplacian whose rim rows mix in, with weight ``t = rim_curve``, the Laplacian
    along the boundary curve; an unreferenced vertex gets a unit diagonal. ``H^T W H + G`` is
    scattered into the 1-ring pattern, only ``K^T K`` (the 2-ring) is a sparse product.

    >>> N, _, w = scan_normal_matrix(Connectivity(np.array([[0, 1, 2], [0, 2, 3]]), 5), 0.03, 0.45, 0.1)
    >>> N.shape, w.tolist()
    ((5, 5), [0.1, 0.1])
    """
    from .._block_kernel import add_subset  # compiled by the package's build
    from .._block_kernel import empty_small_pages as fresh  # mesh-sized values (constrained_fairing.rst)
    from ._iterative import gram_matrix

    triangles, n = conn.triangles, conn.n
    if collapsed_triangles(triangles).any():
        raise ValueError("scan_normal_matrix takes triangles of three distinct vertices")
    edges, counts, halfedge_edge = conn.edges, conn.edge_triangles, conn.halfedge_edge
    boundary, valence = conn.rim
    lo, hi = edges[:, 0], edges[:, 1]
    referenced = valence > 0
    indptr, indices, diagonal, forward, backward = conn.ring_pattern
    at_rim = boundary[triangles[:, 0]] | boundary[triangles[:, 1]] | boundary[triangles[:, 2]]
    weight = np.where(at_rim, float(boundary_weight), 1.0)  # (m,) w_t
    # mu H^T W H + lambda G (+ 1 on an unreferenced vertex's diagonal), on the 1-ring pattern
    data, corner_weight = fresh(len(indices)), fresh(3 * len(triangles))
    corner_weight.reshape(-1, 3)[:] = weight[:, None]  # np.repeat(weight, 3)
    data[diagonal] = mu * np.bincount(triangles.ravel(), corner_weight, minlength=n)
    data[diagonal] += membrane * valence
    data[diagonal[~referenced]] = 1.0
    # half-edge a * m + t is triangle t's edge from corner a: its weights are np.tile(w, 3)
    corner_weight.reshape(3, -1)[:] = weight  # np.tile(weight, 3)
    on_edge = mu * np.bincount(halfedge_edge, corner_weight, minlength=len(edges)) - membrane
    del corner_weight
    data[forward] = on_edge
    data[backward] = on_edge
    matrix = sp.csr_matrix((data, indices, indptr), shape=(n, n))
    # K: row i is 1 at i and -(1 - t) / n_i - t / c_i at each neighbour (the second part only across
    # boundary edges, c_i of them; t = rim_curve for a rim vertex, the one-sided row otherwise)
    t = float(rim_curve)
    inverse = np.zeros(n)
    np.divide(np.where(boundary, 1.0 - t, 1.0), valence, out=inverse, where=referenced)
    from_lo, from_hi = -inverse[lo], -inverse[hi]  # each edge's entry in row lo, in row hi
    if t > 0.0:
        rim = counts == 1
        curve_valence = np.bincount(edges[rim].ravel(), minlength=n)
        curve_inverse = np.divide(t, curve_valence, out=np.zeros(n), where=curve_valence > 0)
        from_lo[rim] -= curve_inverse[lo[rim]]
        from_hi[rim] -= curve_inverse[hi[rim]]
    # K's CSR arrays are K^T's CSC: K^T K by the compiled product; symmetric, so its CSC arrays are its
    # CSR ones. Its pattern holds the 1-ring (K_ii K_ij): the 1-ring terms are added into it in place
    # K^T's rows: K's values mirrored on the symmetric 1-ring pattern (no transpose of K), both written
    # from the edges' values (no gather of K's)
    plate, mirrored = fresh(len(indices)), fresh(len(indices))
    plate[diagonal] = mirrored[diagonal] = referenced
    plate[forward], plate[backward] = from_lo, from_hi
    mirrored[forward], mirrored[backward] = from_hi, from_lo
    del from_lo, from_hi
    rows = sp.csr_matrix((mirrored, indices, indptr), shape=(n, n))
    square = gram_matrix(sp.csc_matrix((plate, indices, indptr), shape=(n, n)), rows=rows)
    del plate, mirrored, rows
    index = square.indices.dtype
    missing = add_subset(
        square.indptr,
        square.indices,
        square.data,
        matrix.indptr.astype(index, copy=False),
        matrix.indices.astype(index, copy=False),
        matrix.data,
    )
    assert missing == 0, "the 1-ring lies within K^T K's pattern"
    del matrix
    ring = sp.csc_matrix((fresh(len(indices), fill=1.0), indices, indptr), shape=(n, n))
    ring.has_canonical_format = True  # the connectivity's pattern: sorted, no duplicates
    normal = sp.csr_matrix((square.data, square.indices, square.indptr), shape=(n, n))
    normal.has_sorted_indices = True  # canonical: CHOLMOD and the lower-triangle cut need it
    return normal, ring, weight


def lower_csc(symmetric: sp.csr_matrix) -> sp.csc_matrix:
    """The lower triangle of a symmetric canonical CSR matrix as CSC: its upper CSR triangle, reinterpreted."""
    n = symmetric.shape[0]
    rows = np.repeat(np.arange(n, dtype=symmetric.indices.dtype), np.diff(symmetric.indptr))
    keep = symmetric.indices >= rows
    indptr = np.zeros(n + 1, dtype=symmetric.indptr.dtype)
    np.cumsum(np.bincount(rows[keep], minlength=n), out=indptr[1:])
    return sp.csc_matrix((symmetric.data[keep], symmetric.indices[keep], indptr), shape=(n, n))


# ---------------------------------------------------------------------------------- the hole patch


def patch_system(
    vertices: np.ndarray,
    triangles: np.ndarray,
    unknown: np.ndarray,
    rings: list,
    level: int,
    *,
    cotangent: bool = False,
    dense: bool = True,
) -> tuple[np.ndarray | sp.csr_matrix, np.ndarray]:
    """The SPD system ``(A (u, u), b (u, 3))`` whose solution places the ``unknown`` local vertices.

    ``K = D - W``, ``L = S K``: uniform (``W`` the adjacency, ``S = D^-1``, eq. 1) or, if ``cotangent``,
    cotangent weights clamped below at 5% of their mean ``|w|`` with ``S`` the inverse vertex areas
    normalized to mean 1. The energy at continuity ``level``: 0 ``x^T K x`` (harmonic); 1
    ``sum |(L x)_r|^2`` over the rows touching an unknown (LS meshes eq. 3); 2 ``sum |(L x)_r - (L x)_s|^2``
    over the edges touching such a row (``rings[0]`` the loop vertices, ``rings[1]`` the next ring).
    Others fixed at ``vertices (n, 3)``; ``A`` dense if ``dense``, else CSR. Assembled in one compiled
    pass (docs/algorithms/hole_filling.rst).

    >>> fan = np.array([[0, 1, 3], [1, 2, 3], [2, 0, 3]])
    >>> A, b = patch_system(np.eye(4, 3), fan, np.array([3]), [], 0)  # the centre of a fan
    >>> (np.linalg.solve(A, b) * 3).round(6).tolist()
    [[1.0, 1.0, 1.0]]
    """
    from .._patch_kernel import patch_system as assemble  # compiled by the package's build

    ring0 = rings[0] if rings else np.zeros(0, dtype=np.int64)
    ring1 = rings[1] if level > 1 else ring0
    normal, rhs = assemble(vertices, triangles, unknown, ring0, ring1, level, cotangent, dense)
    if dense:
        return normal, rhs
    indptr, indices, data = normal  # K_uu, or the rows A_u of the least squares
    matrix = sp.csr_matrix((data, indices, indptr), shape=(len(indptr) - 1, len(unknown)))
    if level == 0:
        return matrix, rhs
    return (matrix.T @ matrix).tocsr(), -(matrix.T @ rhs)


class Penalty(NamedTuple):
    """Eq. 5's penalty form on the free (interior) vertices (:func:`penalty_matrix`)."""

    normal: sp.csc_matrix  # (f, f) K_F^T K_F + mu H_F^T H_F, sorted
    laplacian: sp.csr_matrix  # (f, f) K_F
    pull: sp.csr_matrix | None  # (f, b) K_F^T K_B, the known vertices' pull (None without known ones)
    incidence: sp.csr_matrix  # (k, f) sqrt(mu) H_F over the interior triangles
    free: np.ndarray  # (f,) vertex ids
    known: np.ndarray  # (b,) vertex ids


def penalty_matrix(conn: Connectivity, mu: float) -> Penalty:
    """``K_F^T K_F + mu H_F^T H_F`` of ``min |K_I X|^2 + mu |H_I (X - X0)|^2`` (Liu et al. eq. 5, penalty form).

    ``K`` the uniform Laplacian, ``H`` the triangle-vertex incidence of the interior triangles (no
    vertex on an edge of other than two triangles); boundary and isolated vertices are known and
    eliminated. Right-hand side: ``H_F^T (H_F X0_F) - K_F^T K_B X_B``.

    >>> p = penalty_matrix(Connectivity(np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]])), 1.0)
    >>> p.normal.shape, p.known.tolist()
    ((4, 4), [])
    """
    from ._iterative import gram_matrix

    n = conn.n
    boundary = np.zeros(n, dtype=bool)
    boundary[conn.edges[conn.edge_triangles != 2].ravel()] = True
    free = (conn.rim[1] > 0) & ~boundary
    free_ids, known = np.flatnonzero(free), np.flatnonzero(~free)
    K = uniform_laplacian(conn, keep_pattern=True)
    if len(free_ids) < n:  # the rows of the interior vertices, their columns (none to cut when closed)
        K = K[free_ids]
    K_F = K if len(free_ids) == n else K[:, free_ids]
    pull = (K_F.T @ K[:, known]).tocsr() if len(known) else None
    tri = conn.triangles[np.flatnonzero(~boundary[conn.triangles].any(axis=1))]
    k = len(tri)
    index = K_F.indices.dtype  # one index type for both blocks: a mixed stack goes to int64
    reduced = np.full(n, -1, dtype=index)
    reduced[free_ids] = np.arange(len(free_ids), dtype=index)
    H = sp.csr_matrix(
        (np.full(3 * k, np.sqrt(float(mu))), reduced[tri].ravel(), np.arange(0, 3 * k + 1, 3, dtype=index)),
        shape=(k, len(free_ids)),
    )
    # one product of the stacked rows (no sum of two 2-ring matrices), sorted
    normal = gram_matrix(sp.vstack([K_F, H], format="csr").T)
    return Penalty(normal, K_F, pull, H, free_ids, known)

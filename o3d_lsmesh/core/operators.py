"""Every sparse matrix the papers use, built from a :class:`~.connectivity.Connectivity`; nothing is solved here.

Least-squares meshes (Sorkine & Cohen-Or 2004): uniform and cotangent Laplacians (eq. 1), the graph
Laplacian ``D - A``, the hole patch's continuity-0/1/2 system. Liu et al. 2001: the local operator
(eq. 6-7) and the barycenter penalty (eq. 5), the boundary-curve Laplacian (section 3.3). The scan
energy's normal matrix ``K^T K + mu H^T W H + lambda G`` and the umbrella (1- and 2-ring) weights.
Docs: ``docs/algorithms/`` (one page per method).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from .connectivity import (
    RING_COLUMN_SLOT,
    RING_ROW_SLOT,
    Connectivity,
    VertexRings,
    gather,
    group_keys,
    ring_pattern,
)

__all__ = [
    "LocalMatrices",
    "Penalty",
    "accumulate_block",
    "cotangent_laplacian",
    "graph_laplacian",
    "local_operator",
    "lower_csc",
    "penalty_matrix",
    "rim_neighbours",
    "scan_normal_matrix",
    "single_slots",
    "triangle_coefficients",
    "two_ring_rows",
    "umbrella",
    "umbrella_weights",
    "uniform_from_edges",
    "uniform_laplacian",
    "valence_tables",
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


# ---------------------------------------------------------------------------------- Liu et al. eq. 5-7


def triangle_coefficients(valences: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 7 for triangles of vertex valences ``(k, 3)``: ``M (k, 3, 3)`` and ``u (k, 3)``, ``P = M Q + u C``.

    ``A`` (row ``a``: vertex ``a``'s uniform Laplacian restricted to the triangle) and ``B = [1, 1, 1]``;
    ``P`` minimizes ``|A P - Q|^2`` subject to ``B P = C``, solved from the KKT system
    ``[[A^T A, B^T], [B, 0]]`` (non-singular for every valence) once per distinct valence triple.

    >>> M, u = triangle_coefficients(np.array([[6, 6, 6]]))
    >>> u.round(4).tolist()
    [[0.3333, 0.3333, 0.3333]]
    """
    group, _table, M, u = valence_tables(valences)
    return M[group], u[group]


def valence_tables(triangles: np.ndarray, valence: np.ndarray | None = None):
    """Eq. 7 once per distinct valence triple: ``group (k,)``, ``table (g, 3)``, ``M (g, 3, 3)``, ``u (g, 3)``.

    ``triangles (k, 3)`` with ``valence (n,)`` per vertex, or (``valence=None``) the valences of
    each triangle's corners themselves.
    """
    triangles = np.asarray(triangles).reshape(-1, 3)
    if valence is None:
        valence = np.asarray(triangles, dtype=np.int64).ravel()
        triangles = np.arange(len(valence)).reshape(-1, 3)
    valence = np.asarray(valence, dtype=np.int64)
    if len(triangles) == 0:
        return np.zeros(0, dtype=np.int64), np.ones((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 3))
    # key on the rank of each valence among the distinct ones (a few dozen): the triple keys then
    # fit the dense look-up below
    present_valence = np.zeros(int(valence.max()) + 1, dtype=bool)
    present_valence[valence] = True
    values = np.flatnonzero(present_valence)
    base = len(values)
    key_type = np.int32 if base**3 < np.iinfo(np.int32).max else np.int64
    rank = np.zeros(len(present_valence), dtype=key_type)
    rank[values] = np.arange(base, dtype=key_type)
    vertex_rank = rank[valence]  # per vertex, then gathered per corner
    keys = gather(vertex_rank, triangles[:, 0])
    spare = np.empty_like(keys)
    for corner in (1, 2):
        keys *= key_type(base)
        keys += gather(vertex_rank, triangles[:, corner], out=spare)
    del vertex_rank
    # group the distinct valence triples: a dense look-up when the key range is small, else sort-and-mask
    if base**3 <= 1 << 22:
        present = np.zeros(base**3, dtype=bool)
        for i in range(0, len(keys), 1 << 16):  # in blocks: the int32 keys are converted to intp
            present[keys[i : i + (1 << 16)]] = True
        distinct = np.flatnonzero(present)
        slot = np.zeros(base**3, dtype=key_type)
        slot[distinct] = np.arange(len(distinct), dtype=key_type)
        group = gather(slot, keys, out=spare)
    else:
        keys = keys.astype(np.int64)
        order, starts, _, group = group_keys(keys, int(keys.max()) + 1)
        distinct = keys[order[starts]]
    table = values[np.stack([distinct // (base * base), (distinct // base) % base, distinct % base], axis=1)]
    table = table.astype(np.float64)
    g = len(table)
    A = np.repeat(np.eye(3)[None], g, axis=0) - (1.0 / table)[:, :, None] * (1.0 - np.eye(3))[None]
    kkt = np.zeros((g, 4, 4))
    kkt[:, :3, :3] = np.transpose(A, (0, 2, 1)) @ A
    kkt[:, :3, 3] = 1.0
    kkt[:, 3, :3] = 1.0
    rhs = np.zeros((g, 4, 4))
    rhs[:, :3, :3] = np.transpose(A, (0, 2, 1))
    rhs[:, 3, 3] = 1.0
    solution = np.linalg.solve(kkt, rhs)  # closed-form algebra of batched 4x4 blocks: rows 0..2 are [M | u]
    return group, table, solution[:, :3, :3], solution[:, :3, 3]


class LocalMatrices(NamedTuple):
    """One iteration of Liu's local operator: ``X_new = e1 @ (adjacency @ X) + e2 @ X + e3 @ X0``.

    The four ``(n, n)`` CSR share the 1-ring pattern (one index array); ``e3`` is None when built with
    ``keep_constraint=False``; ``initial (n, 3)`` is ``e3 @ X0`` of the given ``positions0`` (or None).
    """

    adjacency: sp.csr_matrix
    e1: sp.csr_matrix
    e2: sp.csr_matrix
    e3: sp.csr_matrix | None
    initial: np.ndarray | None


def accumulate_block(
    indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, x: np.ndarray, out: np.ndarray
) -> None:
    """``out += A @ x`` for the CSR rows ``(indptr, indices, data)`` of a block, ``x (n, 3)``, ``out (rows, 3)``
    C-ordered (the compiled block product, on every core)."""
    from .. import _block_kernel  # compiled by the package's build: imported where used

    _block_kernel.block_product(
        indptr.astype(indices.dtype, copy=False),
        indices,
        data.astype(np.float64, copy=False),
        np.ascontiguousarray(x, dtype=np.float64),
        out,
        1.0,
        out,
    )


def local_operator(
    conn: Connectivity,
    *,
    positions0: np.ndarray | None = None,
    keep_constraint: bool = True,
    block_rows: int = 1 << 13,
) -> LocalMatrices:
    """The :class:`LocalMatrices` of eq. 7 averaged over the interior triangles (no boundary vertex).

    Every coefficient depends on a triangle's valence triple and the two corners of a ring entry, so
    it is read from a ``(7 g + 7,)`` table per matrix; off the boundary a slot lies on an edge of two
    triangles and sums their two entries. Filled ``block_rows`` rows at a time; with ``positions0``
    the constant ``e3 @ X0`` is accumulated meanwhile. A vertex without an interior triangle keeps
    its place (identity row of ``e2``).

    >>> ops = local_operator(Connectivity(np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]])))
    >>> bool(np.allclose(ops.e1 @ (ops.adjacency @ np.ones((4, 3))) + ops.e2 @ np.ones((4, 3)), 0))
    True
    """
    triangles, rings = conn.triangles, conn.rings
    n = rings.n
    m = len(triangles)
    indptr, indices, index = rings.indptr, rings.indices, rings.indices.dtype
    if rings.boundary.any():
        interior = gather(rings.boundary, triangles[:, 0])  # first: touches the boundary
        corner_boundary = np.empty_like(interior)
        for corner in (1, 2):
            interior |= gather(rings.boundary, triangles[:, corner], out=corner_boundary)
        np.logical_not(interior, out=interior)
        del corner_boundary
        group, table, M, u = valence_tables(triangles[interior], rings.valence)
    else:  # a closed mesh: every triangle is interior
        interior = None
        group, table, M, u = valence_tables(triangles, rings.valence)
    g = len(table)
    alpha = M / table[:, None, :]  # (g, 3, 3): coefficient of S_{i_b} in P_a
    beta = alpha - alpha.sum(axis=2, keepdims=True)  # coefficient of x_{i_c}: -sum_{b != c} alpha_ab
    share = np.repeat(u[:, :, None], 3, axis=2)  # (g, 3, 3): u_a, whatever the column's corner
    del M
    # entry d of a triangle of group q reads row 7 q + d of the tables (row corner RING_ROW_SLOT[d],
    # column corner RING_COLUMN_SLOT[d]): E1, E2, E3, then E1's diagonal (a, a). Group g (not an
    # interior triangle) and entry 6 (a diagonal marker 6 m) read zeros.
    rows, cols = list(RING_ROW_SLOT), list(RING_COLUMN_SLOT)
    by_entry = np.zeros((4, g + 1, 7))
    for j, c in enumerate((alpha, beta, share)):
        by_entry[j, :g, :6] = c[:, rows, cols]
    by_entry[3, :g, :6] = alpha[:, rows, rows]
    columns = by_entry.reshape(4, -1)  # (4, 7 g + 7): a 1-D table per column
    # estimates per vertex: its interior triangles (off the boundary as many as its neighbours)
    count = rings.valence.copy()
    if interior is None:
        triangle_group = group.astype(index, copy=False)
    else:
        count -= np.bincount(triangles[~interior].reshape(-1), minlength=n)
        count[rings.boundary] = 0
        triangle_group = np.full(m, g, dtype=index)
        triangle_group[interior] = group
    del interior, group
    reciprocal = 1.0 / np.maximum(count, 1)
    # One pass over the slots, block by block. Off the diagonal of a row not on the boundary, a slot
    # holds the two triangles of its edge, and each triangle on the row's vertex lies in two of its
    # slots: a slot's coefficient is the sum of its two entries', half the row sum of an entry's
    # diagonal coefficient is the diagonal. E3's entries hold u_a for diagonal and column alike (its
    # diagonal is half its row sum); beta_aa = -(alpha_ab + alpha_ac) makes E2's diagonal minus E1's row sum.
    pairs, diagonal = rings.pairs, rings.diagonal
    data = [np.empty(len(indices)) for _ in range(4 if keep_constraint else 3)]  # E1, E2, W, E3
    if positions0 is not None:
        positions0 = np.ascontiguousarray(positions0, dtype=np.float64)
        initial = np.zeros((n, 3))
    for r0 in range(0, n, block_rows):
        r1 = min(n, r0 + block_rows)
        s0, s1 = int(indptr[r0]), int(indptr[r1])
        # a slot of one entry (a diagonal, a boundary edge) or more (a fin) holds its first entry
        # twice: it lies in a row whose every entry reads zeros
        first = _entry_rows(pairs[0, s0:s1].copy(), triangle_group, m)
        second = _entry_rows(pairs[1, s0:s1].copy(), triangle_group, m)
        local_starts = indptr[r0:r1] - s0
        spare = np.empty(s1 - s0)
        scale = reciprocal[r0:r1]
        row_scale = np.repeat(scale, np.diff(indptr[r0 : r1 + 1]))
        local_diagonal = diagonal[r0:r1] - s0
        part = {}  # the block's slots of E1, E2, E3
        part[0] = _slot_sums(columns[0], first, second, data[0][s0:s1], spare)
        diagonals = [
            _half_row_sums(_slot_sums(columns[3], first, second, np.empty(s1 - s0), spare), local_starts),
            -np.add.reduceat(part[0], local_starts),
        ]
        part[2] = _slot_sums(columns[2], first, second, data[3][s0:s1] if keep_constraint else None, spare)
        diagonals.append(_half_row_sums(part[2], local_starts))
        part[1] = _slot_sums(columns[1], first, second, data[1][s0:s1], spare)
        for block_data, diagonal_values in zip((part[0], part[1], part[2]), diagonals):
            block_data *= row_scale
            diagonal_values *= scale
            block_data[local_diagonal] = diagonal_values
        part[1][local_diagonal[count[r0:r1] == 0]] = 1.0  # vertices without estimates stay put
        adjacency = data[2][s0:s1]
        adjacency.fill(1.0)
        adjacency[local_diagonal] = 0.0
        if positions0 is not None:  # the block's rows of E3 @ X0
            block_indptr = indptr[r0 : r1 + 1] - indptr[r0]
            accumulate_block(block_indptr, indices[s0:s1], part[2], positions0, initial[r0:r1])
    del triangle_group
    e1, e2, adjacency = (_csr(values, indices, indptr, n) for values in data[:3])
    e3 = _csr(data[3], indices, indptr, n) if keep_constraint else None
    return LocalMatrices(adjacency, e1, e2, e3, initial if positions0 is not None else None)


def _slot_sums(
    column: np.ndarray, first: np.ndarray, second: np.ndarray, out: np.ndarray | None, spare: np.ndarray
) -> np.ndarray:
    # one table column's value at every slot: its two entries' (table rows first, second) summed
    out = gather(column, first, out=out)
    out += gather(column, second, out=spare)
    return out


def _half_row_sums(values: np.ndarray, starts: np.ndarray) -> np.ndarray:
    sums = np.add.reduceat(values, starts)
    sums *= 0.5  # exact
    return sums


def _entry_rows(entry: np.ndarray, triangle_group: np.ndarray, m: int) -> np.ndarray:
    # table row 7 * group + d of ring entries d * m + t (in place); a diagonal marker 6 m reads a zero row
    d = entry // m
    entry -= d * m  # the triangle (of a marker: triangle 0)
    row = gather(triangle_group, entry)
    row *= 7
    row += d
    return row


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
    valence = np.bincount(conn.edges.ravel(), minlength=n).astype(np.int64)
    boundary = np.zeros(n, dtype=bool)
    boundary[conn.edges[conn.edge_triangles != 2].ravel()] = True
    free = (valence > 0) & ~boundary
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
    from ._iterative import gram_matrix

    triangles, n = conn.triangles, conn.n
    if len(triangles) and (
        (triangles[:, 0] == triangles[:, 1]).any()
        | (triangles[:, 1] == triangles[:, 2]).any()
        | (triangles[:, 2] == triangles[:, 0]).any()
    ):
        raise ValueError("scan_normal_matrix takes triangles of three distinct vertices")
    edges, counts, halfedge_edge = conn.edges, conn.edge_triangles, conn.halfedge_edge
    boundary = np.zeros(n, dtype=bool)
    boundary[edges[counts == 1].ravel()] = True
    valence = np.bincount(edges.ravel(), minlength=n)
    lo, hi = edges[:, 0], edges[:, 1]
    referenced = valence > 0
    indptr, indices, diagonal, forward, backward = conn.ring_pattern
    weight = np.where(boundary[triangles].any(axis=1), float(boundary_weight), 1.0)  # (m,) w_t
    # mu H^T W H + lambda G (+ 1 on an unreferenced vertex's diagonal), on the 1-ring pattern
    data = np.empty(len(indices))
    data[diagonal] = mu * np.bincount(triangles.ravel(), np.repeat(weight, 3), minlength=n)
    data[diagonal] += membrane * valence
    data[diagonal[~referenced]] = 1.0
    # half-edge a * m + t is triangle t's edge from corner a: its weights are np.tile(w, 3)
    on_edge = mu * np.bincount(halfedge_edge, np.tile(weight, 3), minlength=len(edges)) - membrane
    data[forward] = on_edge
    data[backward] = on_edge
    matrix = sp.csr_matrix((data, indices, indptr), shape=(n, n))
    # K: row i is 1 at i and -(1 - t) / n_i - t / c_i at each neighbour (the second part only across
    # boundary edges, c_i of them; t = rim_curve for a rim vertex, the one-sided row otherwise)
    t = float(rim_curve)
    inverse = np.zeros(n)
    np.divide(np.where(boundary, 1.0 - t, 1.0), valence, out=inverse, where=referenced)
    plate = np.empty(len(indices))
    plate[diagonal] = referenced
    plate[forward] = -inverse[lo]
    plate[backward] = -inverse[hi]
    if t > 0.0:
        rim = counts == 1
        curve_valence = np.bincount(edges[rim].ravel(), minlength=n)
        curve_inverse = np.divide(t, curve_valence, out=np.zeros(n), where=curve_valence > 0)
        plate[forward[rim]] -= curve_inverse[lo[rim]]
        plate[backward[rim]] -= curve_inverse[hi[rim]]
    # K's CSR arrays are K^T's CSC: K^T K by the compiled product; symmetric, so its CSC arrays are its
    # CSR ones. Its pattern holds the 1-ring (K_ii K_ij): the 1-ring terms are added into it in place
    from .. import _block_kernel  # compiled by the package's build: imported where used

    square = gram_matrix(sp.csc_matrix((plate, indices, indptr), shape=(n, n)))
    del plate
    index = square.indices.dtype
    missing = _block_kernel.add_subset(
        square.indptr,
        square.indices,
        square.data,
        matrix.indptr.astype(index, copy=False),
        matrix.indices.astype(index, copy=False),
        matrix.data,
    )
    assert missing == 0, "the 1-ring lies within K^T K's pattern"
    del matrix
    ring = sp.csc_matrix((np.ones(len(indices)), indices, indptr), shape=(n, n))
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

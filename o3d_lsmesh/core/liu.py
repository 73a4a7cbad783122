"""Liu et al. 2001, barycenter-constrained fairing: the local operator (eq. 6-7), the penalty matrix of
eq. 5 and the boundary-curve Laplacian (section 3.3), as matrices; nothing is solved here.

Re-exported by :mod:`o3d_lsmesh.core.operators`. Docs: ``docs/algorithms/constrained_fairing.rst``,
``docs/algorithms/boundary_curves.rst``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from .arrays import concatenated_ranges, gather
from .boundary import BoundaryCurves
from .connectivity import RING_COLUMN_SLOT, RING_ROW_SLOT, Connectivity

__all__ = [
    "CurveOperator",
    "LocalMatrices",
    "accumulate_block",
    "curve_laplacian",
    "local_operator",
    "ring_csr",
    "triangle_coefficients",
    "valence_tables",
]


def triangle_coefficients(valences: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 7 for triangles of vertex valences ``(k, 3)``: ``M (k, 3, 3)`` and ``u (k, 3)``, ``P = M Q + u C``.

    ``A`` (row ``a``: vertex ``a``'s uniform Laplacian restricted to the triangle) and ``B = [1, 1, 1]``;
    ``P`` minimizes ``|A P - Q|^2`` subject to ``B P = C``, solved from the KKT system
    ``[[A^T A, B^T], [B, 0]]`` (non-singular for every valence) once per distinct valence triple.

    >>> M, u = triangle_coefficients(np.array([[6, 6, 6]]))
    >>> u.round(4).tolist()
    [[0.3333, 0.3333, 0.3333]]
    """
    valences = np.asarray(valences, dtype=np.int64)
    group, _table, M, u = valence_tables(np.arange(valences.size).reshape(-1, 3), valences.ravel())
    return M[group], u[group]


def valence_tables(triangles: np.ndarray, valence: np.ndarray):
    """Eq. 7 once per distinct valence triple of ``triangles (k, 3)`` with ``valence (n,)`` per vertex:
    ``group (k,)``, ``table (g, 3)``, ``M (g, 3, 3)``, ``u (g, 3)``."""
    triangles = np.asarray(triangles).reshape(-1, 3)
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
    else:  # more than 161 distinct valences
        distinct, group = np.unique(keys.astype(np.int64), return_inverse=True)
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
    from .._block_kernel import block_product  # compiled by the package's build: imported where used

    block_product(
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
    from .._block_kernel import empty_small_pages  # compiled by the package's build: imported where used

    # E1, E2, W, E3 (and E3 X0): mesh-sized, written once, on small pages (docs: constrained_fairing.rst)
    data = [empty_small_pages(len(indices)) for _ in range(4 if keep_constraint else 3)]
    if positions0 is not None:
        positions0 = np.ascontiguousarray(positions0, dtype=np.float64)
        initial = empty_small_pages((n, 3), fill=0.0)
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
        # the block's slots of E1, E2, E3 and their diagonals
        e1_part = _slot_sums(columns[0], first, second, data[0][s0:s1], spare)
        e1_diagonal = _half_row_sums(
            _slot_sums(columns[3], first, second, np.empty(s1 - s0), spare), local_starts
        )
        e2_diagonal = -np.add.reduceat(e1_part, local_starts)
        e3_part = _slot_sums(columns[2], first, second, data[3][s0:s1] if keep_constraint else None, spare)
        e2_part = _slot_sums(columns[1], first, second, data[1][s0:s1], spare)
        for block_data, diagonal_values in (
            (e1_part, e1_diagonal),
            (e2_part, e2_diagonal),
            (e3_part, _half_row_sums(e3_part, local_starts)),
        ):
            block_data *= row_scale
            diagonal_values *= scale
            block_data[local_diagonal] = diagonal_values
        e2_part[local_diagonal[count[r0:r1] == 0]] = 1.0  # vertices without estimates stay put
        adjacency = data[2][s0:s1]
        adjacency.fill(1.0)
        adjacency[local_diagonal] = 0.0
        if positions0 is not None:  # the block's rows of E3 @ X0
            block_indptr = indptr[r0 : r1 + 1] - indptr[r0]
            accumulate_block(block_indptr, indices[s0:s1], e3_part, positions0, initial[r0:r1])
    del triangle_group
    e1, e2, adjacency = (ring_csr(values, indices, indptr, n) for values in data[:3])
    e3 = ring_csr(data[3], indices, indptr, n) if keep_constraint else None
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


@dataclass(frozen=True)
class CurveOperator:
    """One averaged relaxation step of every boundary curve: ``X[vertex] <- moving @ X[support] + targets @ X0[support]``.

    ``vertex (b,)`` the boundary vertices that move, ``support (s,)`` those their estimates read;
    ``moving`` and ``targets`` ``(b, s)`` CSR. Arrays only: pickles, shared between threads.
    """

    vertex: np.ndarray
    support: np.ndarray
    moving: sp.csr_matrix
    targets: sp.csr_matrix

    def __len__(self) -> int:
        return len(self.vertex)

    def target(self, positions0: np.ndarray) -> np.ndarray:
        """The constant part of the step (the segment midpoints' share), ``(b, 3)``."""
        return self.targets @ positions0[self.support]

    def step(self, positions: np.ndarray, target: np.ndarray) -> np.ndarray:
        """New positions ``(b, 3)`` of :attr:`vertex` after one averaged relaxation of every segment."""
        return self.moving @ positions[self.support] + target


def curve_laplacian(curves: BoundaryCurves | list, min_length: int = 4) -> CurveOperator:
    """The :class:`CurveOperator` of boundary curves (Liu et al. section 3.3).

    ``curves``: a :class:`~.boundary.BoundaryCurves` (its junctions and chain ends held) or a list of
    closed loops. Segment ``(a, b)`` with outer neighbours ``a'``, ``b'`` estimates
    ``a <- (a' - b') / 6 + (a0 + b0) / 2`` (and ``b`` alike); with ``a`` held, ``b <- (a0 + b0) - a``.
    A vertex averages its estimates. Loops under ``min_length`` vertices and chains under
    ``min_length`` edges are held.

    >>> op = curve_laplacian([np.array([5, 6, 7, 8])])
    >>> op.vertex.tolist(), (op.moving.toarray()[0] * 12).round().tolist()  # (p6 + p8 - 2 p7) / 12
    ([5, 6, 7, 8], [0.0, 1.0, -2.0, 1.0])
    """
    if isinstance(curves, BoundaryCurves):
        loops, chains, held = list(curves.loops), list(curves.chains), curves.junctions
    else:
        loops, chains, held = list(curves), [], np.zeros(0, dtype=np.int64)
    loops = [np.asarray(loop, dtype=np.int64) for loop in loops if len(loop) >= min_length]
    # a chain of k edges has k + 1 vertices; like a short loop, a short chain would only shrink
    chains = [np.asarray(chain, dtype=np.int64) for chain in chains if len(chain) > min_length]
    ends = [chain[[0, -1]] for chain in chains]
    held = np.unique(np.concatenate([np.asarray(held, dtype=np.int64).ravel(), *ends]))
    a, b, outer_a, outer_b = _segments(loops, closed=True)
    ca, cb, couter_a, couter_b = _segments(chains, closed=False)
    a, b = np.concatenate([a, ca]), np.concatenate([b, cb])
    outer_a, outer_b = np.concatenate([outer_a, couter_a]), np.concatenate([outer_b, couter_b])
    a_held, b_held = np.isin(a, held), np.isin(b, held)
    # every estimate: (vertex, [(column, weight)] of the moving part, [(column, weight)] of the target part)
    blocks = []
    inner = ~a_held & ~b_held  # both ends free (then both have outer neighbours)
    ia, ib, oa, ob = a[inner], b[inner], outer_a[inner], outer_b[inner]
    blocks.append((ia, [(oa, 1 / 6), (ob, -1 / 6)], [(ia, 0.5), (ib, 0.5)]))
    blocks.append((ib, [(ob, 1 / 6), (oa, -1 / 6)], [(ia, 0.5), (ib, 0.5)]))
    start = a_held & ~b_held  # a is held: the midpoint constraint alone gives b
    blocks.append((b[start], [(a[start], -1.0)], [(a[start], 1.0), (b[start], 1.0)]))
    end = ~a_held & b_held
    blocks.append((a[end], [(b[end], -1.0)], [(a[end], 1.0), (b[end], 1.0)]))
    vertex_all = np.concatenate([block[0] for block in blocks])
    vertex, row = np.unique(vertex_all, return_inverse=True)
    scale = 1.0 / np.maximum(np.bincount(row, minlength=len(vertex)), 1)  # average the estimates
    columns_all = np.concatenate([column for block in blocks for part in (1, 2) for column, _ in block[part]])
    support = np.unique(columns_all)

    def matrix(part: int) -> sp.csr_matrix:
        rows = np.concatenate([np.searchsorted(vertex, block[0]) for block in blocks for _ in block[part]])
        columns = np.searchsorted(
            support, np.concatenate([column for block in blocks for column, _ in block[part]])
        )
        weights = np.concatenate(
            [np.full(len(column), weight) for block in blocks for column, weight in block[part]]
        )
        out = sp.csr_matrix((weights * scale[rows], (rows, columns)), shape=(len(vertex), len(support)))
        out.sum_duplicates()
        return out

    return CurveOperator(vertex, support, matrix(1), matrix(2))


def _segments(curves: list, *, closed: bool):
    # segments (a, b) of every curve with their outer neighbours (a', b') (-1 past a chain end)
    if not curves:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty, empty
    lengths = np.array([len(c) for c in curves], dtype=np.int64)
    vertex = np.concatenate(curves)
    position = concatenated_ranges(0, lengths)  # within its curve
    start = np.arange(len(vertex)) - position
    length = np.repeat(lengths, lengths)
    if closed:  # loop [5, 6, 7, 8]: segment (5, 6) has outer neighbours (8, 7)

        def at(by):
            return vertex[start + (position + by) % length]

        return vertex, at(1), at(-1), at(2)
    # a chain of k + 1 vertices has k segments: drop the last vertex as a segment start
    keep = position < length - 1
    a = vertex[keep]
    b = vertex[np.flatnonzero(keep) + 1]
    pos, size, first = position[keep], length[keep], start[keep]
    outer_a = np.where(pos > 0, vertex[np.maximum(first + pos - 1, 0)], -1)
    outer_b = np.where(pos + 2 < size, vertex[np.minimum(first + pos + 2, len(vertex) - 1)], -1)
    return a, b, outer_a, outer_b


def ring_csr(data: np.ndarray, indices: np.ndarray, indptr: np.ndarray, n: int) -> sp.csr_matrix:
    """A canonical ``(n, n)`` CSR matrix on the given arrays (shared, not copied or re-checked)."""
    matrix = sp.csr_matrix((n, n), dtype=np.float64)
    matrix.data, matrix.indices, matrix.indptr = data, indices, indptr
    matrix.has_canonical_format = True  # sorted columns, no duplicates: the rings' pattern
    return matrix

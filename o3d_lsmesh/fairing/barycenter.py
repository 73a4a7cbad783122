"""Barycenter-constrained surface fairing (Liu et al. 2001, sections 3.1 and 3.2): array core.

Two solvers of the constrained problem (eq. 5)::

    min  X^T K^T K X   subject to   H (X - X0) = 0,

``K = I - D^-1 W`` the uniform Laplacian (``w_ij = 1/n_i``) and ``H`` the
``(m, n)`` triangle-vertex incidence (one row per triangle, ones at its three
vertices, so ``H X`` is three times the barycenters).

* :class:`LocalOperator`: the paper's iterative operator. Each triangle's
  three vertices minimize their local Laplacian energy under the triangle's
  barycenter constraint (eq. 6, closed form eq. 7), then each vertex averages
  its estimates. With uniform weights this is a fixed linear map
  ``X <- M1 X + M0 X0`` that is assembled once (see :class:`LocalOperator`).
* :class:`GlobalSolver`: the penalty form of eq. 5 factored once by CHOLMOD.

Both act on the *interior triangles*: those with no boundary vertex. The
boundary is left to the curve fairing of :mod:`.boundary_curve`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .._solvers import (
    SPDSolver,
    check_constant_modes,
    check_finite,
    gram_matrix,
    operator_scale,
    solver_backend,
)
from ..topology import (
    RING_COLUMN_SLOT,
    RING_ROW_SLOT,
    BoundaryCurves,
    EdgeStructure,
    VertexRings,
    boundary_curves,
    edge_structure,
    gather,
    group_keys,
    vertex_rings,
)
from .tuning import BLOCK_ROWS, DEFAULT_MU

__all__ = [
    "DEFAULT_MU",
    "FairingTopology",
    "GlobalSolver",
    "LocalOperator",
    "fairing_topology",
    "local_operator",
    "triangle_coefficients",
]


@dataclass(frozen=True)
class FairingTopology:
    """Connectivity facts that both fairing methods need, computed once.

    Attributes
    ----------
    n : int
        Vertex count.
    edges : (e, 2) int64
        Undirected edges, ``edges[:, 0] < edges[:, 1]``.
    inverse : (3m,) int64
        Edge of every half-edge of :func:`o3d_lsmesh.topology.halfedges`.
    valence : (n,) int64
        ``n_i``, the number of edge neighbours (0 for isolated vertices).
    boundary : (n,) bool
        Vertices on an edge used by one triangle or by more than two.
    interior_triangles : (k,) int64
        Indices of the triangles with no boundary vertex.
    loops : BoundaryCurves or list
        The boundary curves: loops through pinches, chains ending at fins (empty unless asked for).
    structure : EdgeStructure or None
        The edge structure all of the above come from (one edge sort per call).
    """

    n: int
    edges: np.ndarray
    valence: np.ndarray
    boundary: np.ndarray
    interior_triangles: np.ndarray
    loops: BoundaryCurves | list = field(default_factory=list)
    structure: EdgeStructure | None = None

    @property
    def inverse(self) -> np.ndarray:
        """Edge of every half-edge (formed on first use from :attr:`structure`)."""
        return self.structure.inverse if self.structure is not None else np.zeros(0, dtype=np.int64)


def fairing_topology(
    triangles: np.ndarray, n: int, *, with_loops: bool, edges: EdgeStructure | None = None
) -> FairingTopology:
    """Edges, valences, boundary and interior triangles of a mesh; the boundary curves if ``with_loops``.

    ``boundary`` marks the vertices on an edge of one triangle and the
    vertices on an edge of more than two triangles (a fin): neither has a
    two-sided 1-ring, so both are held out of the surface relaxation.
    ``loops`` is the :class:`~o3d_lsmesh.topology.BoundaryCurves` of
    :func:`~o3d_lsmesh.topology.boundary_curves` (loops through pinch
    vertices, and chains ending at fins), which
    :func:`.boundary_curve.curve_operator` takes.
    Vertices joining several fans (two surfaces touching at a point, or a
    pinched boundary) are accepted: their uniform 1-ring is the union of the fans.
    The edges are sorted once (:func:`~o3d_lsmesh.topology.edge_structure`,
    or ``edges`` when the caller has it) and that one structure serves the
    valences, the boundary, the boundary curves and, through :attr:`structure`,
    the operators built on it.
    """
    es = edge_structure(triangles, n) if edges is None else edges
    valence = np.bincount(es.edges.ravel(), minlength=n).astype(np.int64)
    boundary = np.zeros(n, dtype=bool)
    boundary[es.edges[es.counts != 2].ravel()] = True
    interior_triangles = np.flatnonzero(~boundary[triangles].any(axis=1))
    loops: BoundaryCurves | list = (
        boundary_curves(triangles, n, edges=es) if with_loops and boundary.any() else []
    )
    return FairingTopology(n, es.edges, valence, boundary, interior_triangles, loops, es)


def triangle_coefficients(valences: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form solution of eq. 6 for triangles with the given vertex valences.

    For a triangle with valences ``(n_0, n_1, n_2)`` let
    ``A = [[1, -1/n_0, -1/n_0], [-1/n_1, 1, -1/n_1], [-1/n_2, -1/n_2, 1]]``
    (row ``a`` is vertex ``a``'s uniform Laplacian restricted to the
    triangle, ``w_ab = 1/n_a`` since the three are mutual neighbours) and
    ``B = [1, 1, 1]``. The minimizer of ``|A P - Q|^2`` subject to
    ``B P = C`` is linear in ``Q`` and ``C``: ``P = M Q + u C``. With ``A``
    invertible this is eq. 7, ``M = A^-1 - u B A^-1`` and
    ``u = A^-1 A^-T B^T / |B A^-1|^2``. It is computed here from the KKT system
    ``[[A^T A, B^T], [B, 0]]``, which is non-singular for every valence
    (``A p = 0`` with ``sum p = 0`` forces ``p_a (1 + 1/n_a) = 0``), so that
    an isolated triangle or a two-triangle pillow (all valences 2, ``A``
    singular) still has a defined answer. ``M`` and ``u`` depend only on the
    valences, so they are solved once per distinct valence triple (the
    paper's look-up tables) and gathered.

    Parameters
    ----------
    valences : (k, 3) int
        Valences of each triangle's vertices, in the triangle's vertex order.

    Returns
    -------
    M : (k, 3, 3) float64
    u : (k, 3) float64
    """
    group, _table, M, u = _valence_tables(valences)
    return M[group], u[group]


def _valence_tables(triangles: np.ndarray, valence: np.ndarray | None = None):
    """Eq. 7 once per distinct valence triple: ``group (k,)``, ``table (g, 3)``, ``M (g, 3, 3)``, ``u (g, 3)``.

    ``triangles (k, 3)`` with ``valence (n,)`` per vertex, or (``valence=None``) the valences of
    each triangle's corners themselves. Triangle ``t`` has valences ``table[group[t]]`` and
    coefficients ``M[group[t]]``, ``u[group[t]]`` (see :func:`triangle_coefficients`).
    """
    triangles = np.asarray(triangles).reshape(-1, 3)
    if valence is None:
        valence = np.asarray(triangles, dtype=np.int64).ravel()
        triangles = np.arange(len(valence)).reshape(-1, 3)
    valence = np.asarray(valence, dtype=np.int64)
    if len(triangles) == 0:
        return np.zeros(0, dtype=np.int64), np.ones((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 3))
    # key on the rank of each valence among the distinct ones (a few dozen even with a
    # pole of valence 1000): the triple keys then fit the dense look-up below
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
    # group the (few hundred) distinct valence triples: a dense look-up when the
    # key range is small (the usual case), else sort-and-mask
    if base**3 <= 1 << 22:
        present = np.zeros(base**3, dtype=bool)
        for i in range(0, len(keys), 1 << 16):  # in blocks: the int32 keys are converted to intp
            present[keys[i : i + (1 << 16)]] = True
        distinct = np.flatnonzero(present)
        slot = np.zeros(base**3, dtype=key_type)
        slot[distinct] = np.arange(len(distinct), dtype=key_type)
        group = gather(slot, keys, out=spare)
    else:  # sort-and-mask (the topology module's)
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
    solution = np.linalg.solve(kkt, rhs)  # (g, 4, 4): rows 0..2 are [M | u]
    return group, table, solution[:, :3, :3], solution[:, :3, 3]


@dataclass(frozen=True)
class LocalOperator:
    """One iteration of the paper's local operator (section 3.2) as fixed sparse matrices.

    For an interior triangle ``t = (i_0, i_1, i_2)`` eq. 7 gives
    ``P_a = sum_b M_ab q_b + u_a C`` with ``q_b = (S_{i_b} - x_{i_{b+1}} - x_{i_{b+2}}) / n_b``,
    ``S = W X`` the sum of each vertex's neighbours and ``C = sum_c x^0_{i_c}``.
    So a vertex's average over its interior triangles is ::

        X_new = E1 @ (W @ X) + E2 @ X + E3 @ X0,

    where ``E1, E2, E3`` have the pattern of the 1-ring (edges plus diagonal)
    and already hold the ``1/count`` of the averaging (``E3[i_a, i_c]`` sums
    the ``u_a`` of the triangles on ``i_a`` and ``i_c``); the four matrices
    share one index array (int32 where it fits). ``E3 @ X0`` (the constraint
    part) is computed once per set of targets by :meth:`constant`. Vertices
    with no interior triangle (boundary and isolated vertices, or interior
    vertices whose every triangle touches the boundary) get an identity row
    in ``E2`` and zero rows in ``E1`` and ``E3``. One iteration costs three
    sparse mat-vecs on ``(n, 3)`` over the 1-ring pattern (about 7 entries
    per row; the one 2-ring matrix ``E1 W + E2`` has about 19 and would cost
    a sparse product to set up). The object only holds arrays: it pickles and
    may be shared between threads.
    """

    adjacency: sp.csr_matrix
    e1: sp.csr_matrix
    e2: sp.csr_matrix
    e3: sp.csr_matrix | None  # None when built with keep_constraint=False
    initial: np.ndarray | None = None  # E3 @ X0 of the positions0 given to local_operator

    def constant(self, positions0: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
        """``E3 @ X0``, the constraint part, ``(n, 3)`` float64 (one sparse mat-vec; into ``out`` if given)."""
        if self.e3 is None:
            raise ValueError("this LocalOperator was built with keep_constraint=False: it has no E3")
        out = np.zeros((self.e3.shape[0], 3)) if out is None else out
        out.fill(0.0)
        _accumulate_block(self.e3.indptr, self.e3.indices, self.e3.data, positions0, out)
        return out

    def step(
        self,
        positions: np.ndarray,
        constant: np.ndarray,
        *,
        out: np.ndarray | None = None,
        work: np.ndarray | None = None,
    ) -> np.ndarray:
        """``E1 @ (W @ X) + E2 @ X + constant``, ``(n, 3)``.

        ``out`` and ``work`` (``(n, 3)`` float64, C-order, not ``positions``) are reused when
        given: above about a million vertices an ``(n, 3)`` array exceeds the allocator's reuse
        threshold, so every fresh temporary is mapped and faulted in anew at every iteration.
        """
        from .. import _block_kernel  # compiled by the package's build: imported where used

        positions = np.ascontiguousarray(positions, dtype=np.float64)
        out = np.empty_like(constant) if out is None else out
        work = np.empty_like(out) if work is None else work
        indptr = self.e1.indptr.astype(self.e1.indices.dtype, copy=False)  # the four share one pattern
        _block_kernel.block_product(indptr, self.e1.indices, self.adjacency.data, positions, work)
        # E2 X and E1 (W X) in one pass over the pattern, on top of the constant
        _block_kernel.pair_product(
            indptr, self.e1.indices, self.e2.data, positions, self.e1.data, work, constant, out
        )
        return out


def _accumulate_block(
    indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, x: np.ndarray, out: np.ndarray
) -> None:
    """``out += A @ x`` for the CSR rows ``(indptr, indices, data)`` of a block, ``x (n, 3)``, ``out (rows, 3)``
    C-ordered: ``_block_kernel.block_product`` with ``out`` as its own offset (SciPy's ``csr_matvecs``, the
    same sums in the same order, runs on one core: Open3D's Laplacian filter runs on every one)."""
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
    triangles: np.ndarray,
    topo: FairingTopology | VertexRings,
    *,
    positions0: np.ndarray | None = None,
    keep_constraint: bool = True,
) -> LocalOperator:
    """Assemble the :class:`LocalOperator` of the interior triangles of ``triangles``.

    With ``positions0 (n, 3)`` the constraint part ``E3 @ X0`` is computed
    during the assembly, block by block, into :attr:`LocalOperator.initial`;
    ``keep_constraint=False`` then drops ``E3`` (an ``nnz`` float64 array)
    when no later :meth:`~LocalOperator.constant` call needs it.

    ``topo``: the mesh's :class:`~o3d_lsmesh.topology.VertexRings` (what
    local fairing builds), or a :class:`FairingTopology` (its rings are then
    built here). Every coefficient depends only on a triangle's valence
    triple and on the two corners of an entry, so it is read from a
    ``(7 g + 7,)`` table per matrix (``g`` distinct triples, plus zero rows
    for the triangles that are not interior). A slot ``(v, w)`` off the
    diagonal of a vertex that is not on the boundary lies on an edge of
    exactly two triangles (an edge with one, or more than two, has boundary
    ends), so its coefficient is the sum of the table rows of the slot's two
    entries: gathers over the ``nnz`` slots, no scatter, nothing sorted
    beyond the rings' one sort. The slots are filled in blocks of rows, so
    that the temporaries stay a few megabytes at any size. The diagonal sums
    each corner's entry onto its vertex.
    """
    rings = vertex_rings(triangles, topo.n) if isinstance(topo, FairingTopology) else topo
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
        group, table, M, u = _valence_tables(triangles[interior], rings.valence)
    else:  # a closed mesh: every triangle is interior
        interior = None
        group, table, M, u = _valence_tables(triangles, rings.valence)
    g = len(table)
    alpha = M / table[:, None, :]  # (g, 3, 3): coefficient of S_{i_b} in P_a
    beta = alpha - alpha.sum(axis=2, keepdims=True)  # coefficient of x_{i_c}: -sum_{b != c} alpha_ab
    share = np.repeat(u[:, :, None], 3, axis=2)  # (g, 3, 3): u_a, whatever the column's corner
    del M
    # Entry d of a triangle of group q reads row 7 q + d of the tables (row corner a =
    # RING_ROW_SLOT[d], column corner b = RING_COLUMN_SLOT[d]): the triangle's coefficient of
    # column b in row a for E1, E2, E3, then E1's diagonal one (a, a). Group g (not an interior
    # triangle) reads zeros, and so does entry 6 of every group (a diagonal marker 6 m: d = 6, t = 0).
    rows, cols = list(RING_ROW_SLOT), list(RING_COLUMN_SLOT)
    by_entry = np.zeros((4, g + 1, 7))  # entry 6 of every group: zeros, what a diagonal marker reads
    for j, c in enumerate((alpha, beta, share)):
        by_entry[j, :g, :6] = c[:, rows, cols]
    by_entry[3, :g, :6] = alpha[:, rows, rows]
    columns = by_entry.reshape(4, -1)  # (4, 7 g + 7): a 1-D table per column
    # estimates per vertex: its interior triangles. Off the boundary every edge has two triangles,
    # so a vertex has as many triangles as neighbours; on it, every triangle touches the boundary.
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

    # One pass over the slots, in blocks of rows (temporaries of a few megabytes at any size). Off
    # the diagonal of a row that is not on the boundary, every slot holds exactly the two triangles
    # on its edge, and every triangle on the row's vertex lies in exactly two of its slots; so a
    # slot's coefficient is the sum of its two entries' table values, and half the row sum of an
    # entry's diagonal coefficient (E1: alpha_aa) is the diagonal. The others need no gather of
    # their own: E3's entries hold u_a for both the diagonal and the column, so its diagonal is half
    # its row sum, and beta_aa = -(alpha_ab + alpha_ac) makes E2's diagonal minus E1's row sum.
    pairs, diagonal = rings.pairs, rings.diagonal
    data = [np.empty(len(indices)) for _ in range(4 if keep_constraint else 3)]  # E1, E2, W, E3
    if positions0 is not None:
        positions0 = np.ascontiguousarray(positions0, dtype=np.float64)
        initial = np.zeros((n, 3))
    block = BLOCK_ROWS  # rows per block
    for r0 in range(0, n, block):
        r1 = min(n, r0 + block)
        s0, s1 = int(indptr[r0]), int(indptr[r1])
        # a slot of one (a diagonal, or a boundary edge) or of more (a fin, whose ends are on the
        # boundary) holds its first entry twice: it lies in a row whose every entry reads zeros
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
        # vertices without estimates stay put
        part[1][local_diagonal[count[r0:r1] == 0]] = 1.0
        adjacency = data[2][s0:s1]
        adjacency.fill(1.0)
        adjacency[local_diagonal] = 0.0
        if positions0 is not None:  # the block's rows of E3 @ X0
            block_indptr = indptr[r0 : r1 + 1] - indptr[r0]
            _accumulate_block(block_indptr, indices[s0:s1], part[2], positions0, initial[r0:r1])
    del triangle_group
    e1, e2, adjacency = (_csr(values, indices, indptr, n) for values in data[:3])
    e3 = _csr(data[3], indices, indptr, n) if keep_constraint else None
    return LocalOperator(adjacency, e1, e2, e3, initial if positions0 is not None else None)


def _slot_sums(
    column: np.ndarray, first: np.ndarray, second: np.ndarray, out: np.ndarray | None, spare: np.ndarray
) -> np.ndarray:
    """One table column's value at every slot: its two entries' (table rows ``first``, ``second``) summed."""
    out = gather(column, first, out=out)
    out += gather(column, second, out=spare)
    return out


def _half_row_sums(values: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Half the sum of ``values`` over each row (rows starting at ``starts``)."""
    sums = np.add.reduceat(values, starts)
    sums *= 0.5  # exact
    return sums


def _entry_rows(entry: np.ndarray, triangle_group: np.ndarray, m: int) -> np.ndarray:
    """Table row ``7 * group + d`` of ring entries ``d * m + t`` (in place); a diagonal marker ``6 m`` reads a zero row."""
    d = entry // m
    entry -= d * m  # the triangle (of a marker: triangle 0)
    row = gather(triangle_group, entry)
    row *= 7
    row += d
    return row


def _csr(data: np.ndarray, indices: np.ndarray, indptr: np.ndarray, n: int) -> sp.csr_matrix:
    """A canonical ``(n, n)`` CSR matrix on the given arrays (shared, not copied or re-checked)."""
    matrix = sp.csr_matrix((n, n), dtype=np.float64)
    matrix.data, matrix.indices, matrix.indptr = data, indices, indptr
    matrix.has_canonical_format = True  # sorted columns, no duplicates: vertex_rings built it so
    return matrix


class GlobalSolver:
    """Penalty form of eq. 5, factored once: ``min |K_I X|^2 + mu |H_I (X - X0)|^2``.

    ``K_I`` holds the uniform-Laplacian rows of the interior vertices and
    ``H_I`` the rows of the interior triangles (no boundary vertex); the
    boundary (and isolated) vertices are known values, eliminated from the
    unknowns. The normal equations
    ``(K_F^T K_F + mu H_F^T H_F) X_F = mu H_F^T H_F X0_F - K_F^T K_B X_B``
    are factored once through :class:`~o3d_lsmesh._solvers.SPDSolver`; each
    :meth:`solve` is one back-substitution for all three coordinates.

    The matrix is positive definite: ``K_F`` is non-singular on every
    component that touches the boundary (diagonally dominant rows next to
    fixed vertices), and on a closed component its only null vector, the
    constant, has ``H 1 = 3 != 0``.
    """

    def __init__(
        self,
        triangles: np.ndarray,
        topo: FairingTopology,
        mu: float,
        *,
        solver: str = "auto",
        progress: bool = False,
    ) -> None:
        from scipy.sparse import csgraph

        from ..laplacian import uniform_laplacian

        n = topo.n
        referenced = topo.valence > 0
        free = referenced & ~topo.boundary
        self.free = np.flatnonzero(free)
        self.known = np.flatnonzero(~free)
        self.mu = float(mu)
        K = uniform_laplacian(triangles, n, edges=topo.edges)
        if len(self.free) < n:  # the rows of the interior vertices, their columns (none to cut when closed)
            K = K[self.free]
        K_F = K if len(self.free) == n else K[:, self.free]
        # the known vertices' pull on the free ones, K_F^T K_B (nonzero only next to the boundary)
        self._pull = (K_F.T @ K[:, self.known]).tocsr() if len(self.known) else None
        tri = triangles[topo.interior_triangles]
        k = len(tri)
        # reduced column of each free vertex; interior triangles only touch free vertices
        index = K_F.indices.dtype  # one index type for both blocks: a mixed stack goes to int64
        reduced = np.full(n, -1, dtype=index)
        reduced[self.free] = np.arange(len(self.free), dtype=index)
        # sqrt(mu) H: the rows stacked below, and the targets' rows (rhs mu H^T H X0 = (sqrt(mu) H)^T ...)
        self._H = sp.csr_matrix(
            (np.full(3 * k, np.sqrt(self.mu)), reduced[tri].ravel(), np.arange(0, 3 * k + 1, 3, dtype=index)),
            shape=(k, len(self.free)),
        )
        # H^T H's largest entry is the most triangles at a free vertex
        most = np.bincount(self._H.indices, minlength=1).max()
        check_finite(lambda: np.array([self.mu * most]), name="mu", what="mu * H^T H")
        # K_F^T K_F + mu H^T H as one product of the stacked rows (no sum of two 2-ring matrices), sorted:
        # canonical, so the solver keeps it without a copy
        rows = sp.vstack([K_F, self._H], format="csr")
        normal = gram_matrix(rows.T)
        scale = operator_scale(K_F)
        del rows, K, K_F
        if len(self.free):
            # a closed component is held in place only by mu |H 1|^2: a tiny mu lets it drift
            # the system couples two free vertices exactly when a path of free-free mesh edges joins them
            # (a row of K_F spans a free vertex and its neighbours): components of that graph, not of the
            # 2-ring matrix (whose undirected search transposes it)
            both = free[topo.edges[:, 0]] & free[topo.edges[:, 1]]
            coupled = reduced[topo.edges[both]]
            graph = sp.csr_matrix(
                (np.ones(len(coupled), dtype=np.int8), (coupled[:, 0], coupled[:, 1])), shape=normal.shape
            )
            labels = csgraph.connected_components(graph, directed=True, connection="weak")[1]
            check_constant_modes(
                normal @ np.ones(len(self.free)),
                labels,
                scale=scale,
                name="mu",
                value=mu,
                what="the barycenter penalty",
                vertex_of=self.free,
            )
        backend = solver_backend(solver)
        self._solver = SPDSolver(normal, backend=backend, progress=progress) if len(self.free) else None

    def solve(self, positions: np.ndarray, positions0: np.ndarray) -> np.ndarray:
        """New ``(n, 3)`` positions: free vertices solved with targets ``positions0``, known ones from ``positions``."""
        out = np.array(positions, dtype=np.float64)
        if self._solver is None:
            return out
        # solved about the targets' centroid (the energy is translation-invariant): the iterative path's
        # relative residual then measures the shape, not the distance to the origin
        targets = positions0[self.free]
        centre = targets.mean(axis=0)
        rhs = self._H.T @ (self._H @ (targets - centre))  # mu H^T H X0
        if self._pull is not None:
            rhs -= self._pull @ (out[self.known] - centre)
        # the iterative path starts from the current positions (direct solvers ignore x0)
        out[self.free] = self._solver.solve(rhs, x0=out[self.free] - centre) + centre
        return out

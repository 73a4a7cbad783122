"""Barycenter-constrained fairing (Liu et al. 2001, sections 3.1-3.2): local operator, global solver.

Both minimize ``|K X|^2`` subject to ``H (X - X0) = 0`` (eq. 5) over the interior triangles:
:class:`LocalOperator` iterates eq. 7 as ``X <- E1 W X + E2 X + E3 X0``, :class:`GlobalSolver` solves
the penalty form once (matrices: :mod:`o3d_lsmesh.core.operators`; the boundary: :mod:`.boundary_curve`).
Docs: ``docs/algorithms/constrained_fairing.rst``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..core.connectivity import Connectivity
from ..core.liu import accumulate_block
from ..core.liu import local_operator as local_matrices
from ..core.operators import penalty_matrix
from ..core.solve import SPDSolver, check_constant_modes, check_finite, operator_scale, solver_backend
from .tuning import BLOCK_ROWS

__all__ = ["GlobalSolver", "LocalOperator", "local_operator"]


@dataclass(frozen=True)
class LocalOperator:
    """One iteration of the paper's local operator: ``X_new = E1 @ (W @ X) + E2 @ X + E3 @ X0``.

    The four ``(n, n)`` CSR share the 1-ring pattern (:func:`o3d_lsmesh.core.liu.local_operator`);
    ``e3`` is None when built with ``keep_constraint=False``; ``initial`` is ``E3 @ X0`` of the
    ``positions0`` given to :func:`local_operator`. The object pickles.
    """

    adjacency: sp.csr_matrix
    e1: sp.csr_matrix
    e2: sp.csr_matrix
    e3: sp.csr_matrix | None
    initial: np.ndarray | None = None

    def constant(self, positions0: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
        """``E3 @ X0``, the constraint part, ``(n, 3)`` float64 (into ``out`` if given)."""
        if self.e3 is None:
            raise ValueError("this LocalOperator was built with keep_constraint=False: it has no E3")
        out = np.zeros((self.e3.shape[0], 3)) if out is None else out
        out.fill(0.0)
        accumulate_block(self.e3.indptr, self.e3.indices, self.e3.data, positions0, out)
        return out

    def step(
        self,
        positions: np.ndarray,
        constant: np.ndarray,
        *,
        out: np.ndarray | None = None,
        work: np.ndarray | None = None,
    ) -> np.ndarray:
        """``E1 @ (W @ X) + E2 @ X + constant``, ``(n, 3)``, into ``out`` with scratch ``work`` when given."""
        from .._block_kernel import block_product, pair_product  # compiled: imported where used

        positions = np.ascontiguousarray(positions, dtype=np.float64)
        out = np.empty_like(constant) if out is None else out
        work = np.empty_like(out) if work is None else work
        indptr = self.e1.indptr.astype(self.e1.indices.dtype, copy=False)  # the four share one pattern
        block_product(indptr, self.e1.indices, self.adjacency.data, positions, work)
        # E2 X and E1 (W X) in one pass over the pattern, on top of the constant
        pair_product(indptr, self.e1.indices, self.e2.data, positions, self.e1.data, work, constant, out)
        return out


def local_operator(
    conn: Connectivity, *, positions0: np.ndarray | None = None, keep_constraint: bool = True
) -> LocalOperator:
    """The :class:`LocalOperator` of the mesh's interior triangles (``E3 @ X0`` formed with ``positions0``).

    >>> tetra = Connectivity(np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]]))
    >>> local_operator(tetra).e1.shape
    (4, 4)
    """
    return LocalOperator(
        *local_matrices(conn, positions0=positions0, keep_constraint=keep_constraint, block_rows=BLOCK_ROWS)
    )


class GlobalSolver:
    """Penalty form of eq. 5, factored once: ``min |K_I X|^2 + mu |H_I (X - X0)|^2``.

    Boundary and isolated vertices are known and eliminated; the normal matrix
    (:func:`o3d_lsmesh.core.operators.penalty_matrix`) is positive definite (``K_F`` is non-singular
    next to the boundary, and on a closed component ``H 1 = 3 != 0``). Each :meth:`solve` is one
    back-substitution for the three coordinates.
    """

    def __init__(
        self, conn: Connectivity, mu: float, *, solver: str = "auto", progress: bool = False
    ) -> None:
        from scipy.sparse import csgraph

        self.mu = float(mu)
        system = penalty_matrix(conn, self.mu)
        self.free, self.known, self._H, self._pull = system.free, system.known, system.incidence, system.pull
        normal = system.normal
        # H^T H's largest entry is the most triangles at a free vertex
        most = np.bincount(self._H.indices, minlength=1).max()
        check_finite(lambda: np.array([self.mu * most]), name="mu", what="mu * H^T H")
        if len(self.free):
            # a closed component is held in place only by mu |H 1|^2: a tiny mu lets it drift. Two free
            # vertices are coupled exactly when a path of free-free mesh edges joins them
            reduced = np.full(conn.n, -1, dtype=np.int64)
            reduced[self.free] = np.arange(len(self.free))
            coupled = reduced[conn.edges]
            coupled = coupled[(coupled >= 0).all(axis=1)]
            graph = sp.csr_matrix(
                (np.ones(len(coupled), dtype=np.int8), (coupled[:, 0], coupled[:, 1])), shape=normal.shape
            )
            labels = csgraph.connected_components(graph, directed=True, connection="weak")[1]
            check_constant_modes(
                normal @ np.ones(len(self.free)),
                labels,
                scale=operator_scale(system.laplacian),
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

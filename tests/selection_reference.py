"""Reference path of the greedy selection for tests and benchmarks: the LS system refactored at every step.

Same normal matrix as :class:`o3d_lsmesh.lsmesh.LSMeshSystem` (``L^T L + w^2 sum e_s e_s^T``, uniform
``L``), numerically refactored with the kept symbolic analysis instead of updated by rank-1 steps.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from o3d_lsmesh import SPDSolver
from o3d_lsmesh.laplacian import uniform_laplacian
from o3d_lsmesh.selection import start_vertices


class RefactoringSystem:
    """The relaxed LS system of ``start`` at weight ``weight``, refactored by :meth:`add_anchors`."""

    def __init__(
        self,
        vertices: np.ndarray,
        triangles: np.ndarray,
        start: np.ndarray,
        weight: float,
        ordering: str = "default",
    ) -> None:
        n = len(vertices)
        L = uniform_laplacian(triangles, n).tocsc()
        self._ltl = (L.T @ L).tocsc()
        self._diagonal = np.zeros(n)
        self._diagonal[start] = weight**2
        self._weight = weight
        self._vertices = vertices
        self._solver = SPDSolver(self._normal(), ordering=ordering)

    def _normal(self) -> sp.csc_matrix:
        return (self._ltl + sp.diags(self._diagonal, format="csc")).tocsc()

    def add_anchors(self, indices: np.ndarray) -> None:
        self._diagonal[indices] = self._weight**2
        self._solver.refactor(self._normal())

    def solve(self) -> np.ndarray:
        return self._solver.solve(self._diagonal[:, None] * self._vertices)


def greedy_by_refactoring(
    vertices: np.ndarray, triangles: np.ndarray, count: int, weight: float
) -> np.ndarray:
    """The greedy selection (LS meshes section 4) as a plain loop: the largest error, a refactoring, again."""
    start = start_vertices(vertices, triangles)
    system = RefactoringSystem(vertices, triangles, start, weight)
    order = list(start)
    for _ in range(len(start), count):
        errors = ((system.solve() - vertices) ** 2).sum(axis=1)
        errors[order] = -np.inf
        order.append(int(np.argmax(errors)))
        system.add_anchors(np.array(order[-1:]))
    return np.array(order)

"""Greedy selection (LS meshes section 4) as a plain loop: dense solves of the relaxed LS system.

The uniform Laplacian is written down from the triangles by loops, the normal matrix ``L^T L + w^2
sum e_s e_s^T`` is solved afresh by ``np.linalg.solve`` at every step: no factor, no update, no code of
the package but the start rule (one vertex per component, tested on its own). For ``n <= 300``.
"""

from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_limits

from o3d_lsmesh.lsmesh.selection import start_vertices


def dense_uniform_laplacian(triangles: np.ndarray, n: int) -> np.ndarray:
    """``I - D^-1 A`` of the mesh's edge graph, ``(n, n)`` dense, by loops (isolated vertices: a zero row)."""
    neighbours: list[set[int]] = [set() for _ in range(n)]
    for triangle in triangles.tolist():
        for a in triangle:
            neighbours[a].update(b for b in triangle if b != a)
    L = np.zeros((n, n))
    for i, ring in enumerate(neighbours):
        if ring:
            L[i, i] = 1.0
            for j in ring:
                L[i, j] -= 1.0 / len(ring)
    return L


def greedy_dense(vertices: np.ndarray, triangles: np.ndarray, count: int, weight: float) -> np.ndarray:
    """The greedy order: the start vertices, then each time the vertex of largest error, by dense solves."""
    n = len(vertices)
    assert n <= 300, "a dense reference"
    L = dense_uniform_laplacian(triangles, n)
    normal = L.T @ L
    order = [int(s) for s in start_vertices(vertices, triangles)]
    with threadpool_limits(limits=1, user_api="blas"):  # small solves: threads only wait on a busy machine
        while len(order) < count:
            pinned = np.zeros(n)
            pinned[order] = weight**2
            X = np.linalg.solve(normal + np.diag(pinned), pinned[:, None] * vertices)
            errors = ((X - vertices) ** 2).sum(axis=1)
            errors[order] = -np.inf
            order.append(int(np.argmax(errors)))
    return np.array(order)

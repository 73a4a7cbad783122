"""Area-weighted vertex normals: each vertex sums the cross products of its triangles' edges."""

from __future__ import annotations

import numpy as np

__all__ = ["area_weighted_normals"]


def area_weighted_normals(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Unnormalized vertex normals, ``(n, 3)``: the sum over each vertex's triangles of twice their area
    times their unit normal (a vertex on no triangle gets zero).

    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> area_weighted_normals(V, np.array([[0, 1, 2]])).tolist()
    [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]]
    """
    n = len(positions)
    p0 = positions[triangles[:, 0]]
    face = np.cross(positions[triangles[:, 1]] - p0, positions[triangles[:, 2]] - p0)
    del p0  # at 10M vertices each (m, 3) temporary is 480 MB
    normal = np.empty((n, 3))
    for k in range(3):
        normal[:, k] = sum(np.bincount(triangles[:, i], face[:, k], minlength=n) for i in range(3))
    return normal

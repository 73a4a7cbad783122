"""Collapsed triangles: those that name one vertex twice (after a collapse, a weld or in bad input)."""

from __future__ import annotations

import numpy as np

__all__ = ["collapsed_triangles"]


def collapsed_triangles(triangles: np.ndarray) -> np.ndarray:
    """``(m,) bool``: which rows of ``triangles (m, 3)`` repeat a vertex index.

    >>> collapsed_triangles(np.array([[0, 1, 2], [3, 3, 4], [5, 6, 5]])).tolist()
    [False, True, True]
    """
    return (
        (triangles[:, 0] == triangles[:, 1])
        | (triangles[:, 1] == triangles[:, 2])
        | (triangles[:, 2] == triangles[:, 0])
    )

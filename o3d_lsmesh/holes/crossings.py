"""The crossing check: new triangles that meet the mesh anywhere but at the corners and edges they share.

See docs/algorithms/hole_filling.rst.
"""

from __future__ import annotations

from typing import Any

import numpy as np


class _TriangleIndex:
    """Bounding spheres (about the centroids) of a mesh's triangles in three uniform grids (radius at most
    1.5 and 4 times the median, and the rest; docs page) by the compiled
    :func:`o3d_lsmesh._patch_kernel.triangle_grids`, for :func:`o3d_lsmesh._patch_kernel.patch_crossings`
    (thread-safe queries; the grids pickle)."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray) -> None:
        from .._patch_kernel import triangle_grids  # compiled: imported where used

        self.centre, self.radius, self.grids = triangle_grids(
            np.ascontiguousarray(vertices, dtype=np.float64), np.ascontiguousarray(triangles, dtype=np.int64)
        )


def _crossings(
    vertices: np.ndarray, triangles: np.ndarray, first_new: int, index: Any, owner: Any = None
) -> np.ndarray:
    """For each new triangle (from ``first_new`` on), the number of triangles it meets beyond the corners
    and edge they share (:func:`o3d_lsmesh._patch_kernel.patch_crossings`), against those of ``index`` (a
    :class:`_TriangleIndex` of ``triangles[:first_new]``; if None, of those in the new triangles' box) and
    the new ones. With ``owner`` (each new triangle's hole), nonzero counts only mark the crossing holes."""
    from .._patch_kernel import patch_crossings  # compiled: imported where used

    if len(triangles) == first_new:
        return np.zeros(0)
    new = _TriangleIndex(vertices, triangles[first_new:])
    if index is None:
        # the input triangles with a vertex in the new triangles' box grown by twice the largest of them
        p_new = vertices[triangles[first_new:]].reshape(-1, 3)
        low, high = p_new.min(0) - 2.0 * new.radius.max(), p_new.max(0) + 2.0 * new.radius.max()
        in_box = ((vertices >= low) & (vertices <= high)).all(axis=1)
        boxed = np.flatnonzero(in_box[triangles[:first_new]].any(axis=1))
        index = _TriangleIndex(vertices, triangles[boxed])
        triangles, first_new = np.concatenate([triangles[boxed], triangles[first_new:]]), len(boxed)
    return patch_crossings(
        vertices,
        triangles,
        first_new,
        index.grids,
        index.centre,
        index.radius,
        new.grids,
        new.centre,
        new.radius,
        owner,
    )

"""The crossing check: new triangles that meet the mesh anywhere but at the corners and edges they share.

See docs/algorithms/hole_filling.rst.
"""

from __future__ import annotations

from typing import Any

import numpy as np


class _TriangleIndex:
    """Bounding spheres (about the centroids) of a mesh's triangles in two uniform grids (radius at most 4
    times the median, and the rest; docs page), each cell's triangles listed by one stable sort, for the
    compiled :func:`o3d_lsmesh._patch_kernel.patch_crossings` (thread-safe queries; the grids pickle)."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray) -> None:
        p = vertices[triangles]
        self.centre = p.sum(axis=1) / 3.0  # the bits of p.mean(axis=1), np.linalg.norm and np.median, quicker
        offset = p - self.centre[:, None, :]
        self.radius = np.sqrt((offset * offset).sum(axis=2)).max(axis=1)
        small = self.radius <= (4.0 * _median(self.radius) if len(self.radius) else 0.0)
        self.grids = [self._grid(g) for g in (np.flatnonzero(small), np.flatnonzero(~small)) if len(g)]

    def _grid(self, members: np.ndarray) -> tuple:
        centre = self.centre[members]
        reach = float(self.radius[members].max())
        origin = centre.min(axis=0)
        extent = centre.max(axis=0) - origin
        cell = reach if reach > 0 else max(float(extent.max()), 1.0)
        budget = 4 * len(members) + 64
        while np.prod(np.floor(extent / cell) + 1) > budget:  # the grid stays linear in the triangles
            cell *= 1.5
        dims = (np.floor(extent / cell) + 1).astype(np.int64)
        xyz = np.minimum(np.floor((centre - origin) / cell).astype(np.int64), dims - 1)
        key = (xyz[:, 0] * dims[1] + xyz[:, 1]) * dims[2] + xyz[:, 2]
        order = np.argsort(key, kind="stable")
        indptr = np.zeros(int(np.prod(dims)) + 1, dtype=np.int64)
        np.cumsum(np.bincount(key, minlength=len(indptr) - 1), out=indptr[1:])
        return origin, cell, dims, indptr, members[order], reach


def _median(values: np.ndarray) -> float:
    """``np.median`` of a non-empty 1-D array: the middle value, or the mean of the middle two."""
    half = len(values) // 2
    part = np.partition(values, [half - 1, half] if len(values) % 2 == 0 else [half])
    if np.isnan(part[-1]):
        return float("nan")
    return float(part[half]) if len(values) % 2 else float((part[half - 1] + part[half]) / 2.0)


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

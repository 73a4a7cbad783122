"""Attributes extended to vertices and triangles appended after the input's (hole filling's patches).

Per-vertex values are harmonic in the new vertices (cotangent weights: affine data on a flat patch
stays affine), per-corner values (UVs) likewise where the chart is continuous around the patch, else
a texel next to the hole; per-triangle values are a neighbouring triangle's (docs/api/attributes).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..core.connectivity import Connectivity
from ..core.operators import cotangent_laplacian
from ..core.solve import solve_spd

if TYPE_CHECKING:
    from . import MeshData


class Appended:
    """A result whose vertices and triangles are ``data``'s, then new ones (welded numbering): its arrays
    in the source's layout and each kind of attribute extended to the new elements."""

    def __init__(self, data: MeshData, vertices: np.ndarray, triangles: np.ndarray) -> None:
        nw, m, total = len(data.vertices), len(data.triangles), len(vertices)
        old, new = data.triangles, np.asarray(triangles[m:], dtype=np.int64)
        source_triangles = old if data.split_triangles is None else data.split_triangles
        n_source = nw if data.split is None else len(data.split)
        # the loop corners: both ends of each old triangle's edge that a new triangle shares (only
        # triangles with two corners on new triangles can have one: no sort of the whole mesh's edges)
        touched = np.zeros(total, dtype=bool)
        touched[new] = True
        near = np.flatnonzero(touched[old].sum(axis=1) >= 2)
        # edge c of a triangle runs from corner c to c + 1: half-edge row c * k + t of its triangle t
        inverse = Connectivity(np.concatenate([old[near], new]), total).halfedge_edge
        shared = np.zeros(inverse.max(initial=-1) + 1, dtype=bool)
        k = len(near)
        shared[inverse.reshape(3, -1)[:, k:]] = True
        row, corner = np.nonzero(shared[inverse.reshape(3, -1)[:, :k]].T)
        self.corner = np.concatenate([corner, (corner + 1) % 3])
        self.vertex = old[np.concatenate([near[row], near[row]]), self.corner]
        # the loop triangles as rows of the source (its attributes' rows; the weld may have left some out)
        near = near if data.rows is None else data.rows[near]
        self.tri = np.concatenate([near[row], near[row]])
        self.loop, self.first = np.unique(self.vertex, return_index=True)
        # each new patch (vertex-connected new triangles: a hole, or holes touching at a vertex) takes
        # its per-triangle defaults from the triangle of its first loop corner
        patches = Connectivity(new, total)
        self.patch = patches.components[1]
        reference = np.zeros(total, dtype=np.int64)
        labels, first_corner = np.unique(self.patch[self.vertex], return_index=True)
        reference[labels] = first_corner
        self.owner = reference[self.patch[new[:, 0]]]  # (q,) the reference loop corner of each new triangle
        # an old vertex of a new triangle is the copy its loop triangle uses: the hole's side of a seam
        self.copy = np.asarray(data.source_indices(np.arange(nw)), dtype=np.int64).copy()
        self.copy[self.loop] = source_triangles[self.tri[self.first], self.corner[self.first]]
        to_source = np.concatenate([self.copy, np.arange(n_source, n_source + total - nw)])
        self.vertices = np.concatenate([data.source_positions(vertices[:nw]), vertices[nw:]])
        self.triangles = np.concatenate([source_triangles, to_source[new]])
        self.new, self.nw, self.inner = new, nw, None
        if total > nw:
            # harmonic values of the new vertices, L_uu x_u = -L_ub x_b with the cotangent Laplacian of
            # the new triangles (a new vertex has no other; numbered among their vertices alone, the new
            # ones last). L is not symmetric (rows scaled by 1/D): its normal equations
            local_triangles, local = patches.submesh(np.arange(len(new)))
            k = int(np.searchsorted(local, nw))
            laplacian = cotangent_laplacian(vertices[local], Connectivity(local_triangles, len(local)))
            self.around, self.inner, self.coupling = local[:k], laplacian[k:, k:], laplacian[k:, :k]
            self.normal = (self.inner.T @ self.inner).tocsc()

    def extend(self, follows: str, values: np.ndarray) -> np.ndarray:
        """``values`` of an attribute that follows ``"vertex"``, ``"triangle"`` or ``"corner"`` (``(m, 3, d)``;
        other shapes per triangle), followed by the new elements' values."""
        if follows == "vertex":
            return self.per_vertex(values)
        if follows == "corner" and values.ndim == 3 and values.shape[1] == 3:
            return self.per_corner(values)
        return self.per_triangle(values)

    def harmonic(self, values: np.ndarray) -> np.ndarray:
        """Values ``(nw, k)`` of the welded vertices extended harmonically to the new ones, ``(p, k)``."""
        if self.inner is None:
            return np.zeros((0, values.shape[1]))
        rim = values[self.around]
        unknown = ~np.isfinite(rim)  # (a NaN at the rim: "no value", as a scan's missing confidence)
        rhs = self.inner.T @ -(self.coupling @ np.where(unknown, 0.0, rim))
        solution = np.asarray(solve_spd(self.normal, rhs)).reshape(-1, values.shape[1])
        # a patch with an unknown value at its rim has none inside either (per column)
        patch = self.patch[self.nw :]
        for column in np.flatnonzero(unknown.any(axis=0)):
            solution[np.isin(patch, self.patch[self.around[unknown[:, column]]]), column] = np.nan
        return solution

    def per_vertex(self, values: np.ndarray) -> np.ndarray:
        """Per-vertex values ``(n_source, ...)`` followed by the new vertices' (clipped to the input's range;
        integers rounded)."""
        flat = values.reshape(len(values), -1)
        if flat.shape[1] == 0:  # an attribute of no values a vertex
            return np.zeros((len(self.vertices),) + values.shape[1:], dtype=values.dtype)
        if not np.issubdtype(values.dtype, np.floating):
            # integers as differences from their least (exact in float64 up to 2**53: a 64-bit id or sentinel
            # is not rounded), in wrapping unsigned arithmetic (an int64's range spans more than an int64)
            base = flat.min(axis=0).astype(np.uint64)
            offset = (flat.astype(np.uint64) - base).astype(np.float64)
            extra = np.rint(np.clip(self.harmonic(offset[self.copy]), 0.0, offset.max(axis=0)))
            extra = (extra.astype(np.uint64) + base).astype(values.dtype)
            return np.concatenate([values, extra.reshape((-1,) + values.shape[1:])])
        finite = np.isfinite(flat)
        low, high = np.where(finite, flat, np.inf).min(axis=0), np.where(finite, flat, -np.inf).max(axis=0)
        extra = np.clip(self.harmonic(flat[self.copy].astype(np.float64)), low, high)
        return np.concatenate([values, extra.reshape((-1,) + values.shape[1:]).astype(values.dtype)])

    def per_triangle(self, values: np.ndarray) -> np.ndarray:
        """Per-triangle values ``(m, ...)`` followed by the new triangles': their reference triangle's."""
        return np.concatenate([values, values[self.tri[self.owner]]])

    def per_corner(self, values: np.ndarray) -> np.ndarray:
        """Per-corner values ``(m, 3, d)`` (UVs) followed by the new triangles'."""
        at_corner = values[self.tri, self.corner].astype(np.float64)  # (c, d) the loop corners'
        at = np.zeros((self.nw, values.shape[2]))
        at[self.loop] = at_corner[self.first]
        # a chart is continuous around a patch when every loop vertex has one value in its loop triangles
        torn = np.zeros(len(self.patch), dtype=bool)
        torn[self.patch[self.vertex[(at_corner != at[self.vertex]).any(axis=1)]]] = True
        extended = np.concatenate([at, self.harmonic(at)])[self.new]  # (q, 3, d)
        fallback = torn[self.patch[self.new[:, 0]]]
        extended[fallback] = at_corner[self.owner[fallback]][:, None]
        return np.concatenate([values, extended.astype(values.dtype)])

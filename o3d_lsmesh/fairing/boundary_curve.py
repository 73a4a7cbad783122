"""Boundary-curve fairing with segment-midpoint constraints (Liu et al. 2001, section 3.3).

For each boundary segment the curve Laplacian energy is minimized with the segment's midpoint
held (the section's local closed form); every point averages its two estimates, a fixed linear
map of the current curve and the constraint curve assembled once (:class:`CurveOperator`).
Loops pass through pinch vertices fan by fan; chains end at fins, whose vertices are held.
Docs page: ``docs/algorithms/boundary_curves.rst``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from .._o3d import new_mesh, read_mesh
from ..core.arrays import concatenated_ranges
from ..core.boundary import BoundaryCurves, boundary_curves
from ..core.validate import as_count, as_iterations, mesh_arrays

if TYPE_CHECKING:
    from .._types import MeshT

__all__ = [
    "MIN_LOOP_LENGTH",
    "CurveOperator",
    "curve_operator",
    "smooth_boundary_curves",
    "smooth_boundary_curves_arrays",
]

#: Closed loops shorter than this are held fixed: three segment midpoints fix a triangle, but the
#: per-segment relaxation degenerates on a 3-loop (both outer neighbours are one vertex) and would
#: shrink the hole, each corner moving three quarters of the way to the centroid in one step.
MIN_LOOP_LENGTH = 4


@dataclass(frozen=True)
class CurveOperator:
    """One averaged relaxation step of every boundary curve as two fixed sparse matrices.

    ``vertex (b,)`` are the boundary vertices that move and ``support (s,)`` those their
    estimates read; row ``j`` of ``moving (b, s)`` and ``targets (b, s)`` averages the estimates
    of ``vertex[j]``: one step is ``X[vertex] <- moving @ X[support] + targets @ X0[support]``.
    Arrays only: it pickles and may be shared between threads.
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


def curve_operator(curves: BoundaryCurves | list) -> CurveOperator:
    """Build the :class:`CurveOperator` of boundary curves.

    ``curves`` is a :class:`~o3d_lsmesh.topology.BoundaryCurves` (loops and open chains; its
    ``junctions`` and the chains' ends are held) or a list of ordered closed loops (``(l,)``
    vertex indices). A vertex visited several times (a pinch) averages all its estimates. Loops
    of fewer than :data:`MIN_LOOP_LENGTH` vertices and chains of fewer edges are held.

    Every segment ``(a, b)`` with outer neighbours ``a'`` (before ``a``) and
    ``b'`` (after ``b``) gives the section 3.3 estimates
    ``a <- (a' - b') / 6 + (a0 + b0) / 2`` and ``b <- (b' - a') / 6 + (a0 + b0) / 2``.
    A segment with a held end ``a`` keeps its midpoint by
    ``b <- (a0 + b0) - a`` (the constraint alone determines ``b``; the energy
    term of the held end is a constant).

    Parameters
    ----------
    curves : BoundaryCurves or list of (l,) int64

    Examples
    --------
    >>> import numpy as np
    >>> op = curve_operator([np.array([5, 6, 7, 8])])
    >>> op.vertex.tolist(), (op.moving.toarray()[0] * 12).round().tolist()  # (p6 + p8 - 2 p7) / 12
    ([5, 6, 7, 8], [0.0, 1.0, -2.0, 1.0])
    """
    if isinstance(curves, BoundaryCurves):
        loops, chains, held = list(curves.loops), list(curves.chains), curves.junctions
    else:
        loops, chains, held = list(curves), [], np.zeros(0, dtype=np.int64)
    loops = [np.asarray(loop, dtype=np.int64) for loop in loops if len(loop) >= MIN_LOOP_LENGTH]
    # a chain of k edges has k + 1 vertices; like a short loop, a chain of fewer than MIN_LOOP_LENGTH edges
    # (such as a triangular hole through a pinch, whose two ends are the same vertex) would only shrink
    chains = [np.asarray(chain, dtype=np.int64) for chain in chains if len(chain) > MIN_LOOP_LENGTH]
    ends = [chain[[0, -1]] for chain in chains]
    held = np.unique(np.concatenate([np.asarray(held, dtype=np.int64).ravel(), *ends]))
    a, b, outer_a, outer_b = _segments(loops, closed=True)
    ca, cb, couter_a, couter_b = _segments(chains, closed=False)
    a, b = np.concatenate([a, ca]), np.concatenate([b, cb])
    outer_a, outer_b = np.concatenate([outer_a, couter_a]), np.concatenate([outer_b, couter_b])
    a_held, b_held = np.isin(a, held), np.isin(b, held)
    # every estimate: (vertex, [(column, weight)] of the moving part, [(column, weight)] of the target part)
    blocks = []
    # both ends free (then both have outer neighbours: only held chain ends lack one)
    inner = ~a_held & ~b_held
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
    """Segments ``(a, b)`` of every curve with their outer neighbours ``(a', b')`` (``-1`` past a chain end)."""
    if not curves:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty, empty
    lengths = np.array([len(c) for c in curves], dtype=np.int64)
    vertex = np.concatenate(curves)
    position = concatenated_ranges(0, lengths)  # within its curve
    start = np.arange(len(vertex)) - position
    length = np.repeat(lengths, lengths)
    if closed:
        # e.g. loop [5, 6, 7, 8]: segment (5, 6) has outer neighbours (8, 7)
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


def smooth_boundary_curves_arrays(
    vertices: np.ndarray,
    triangles: np.ndarray,
    number_of_iterations: int = 10,
    *,
    reimpose_every: int | None = None,
) -> np.ndarray:
    """Array core of :func:`smooth_boundary_curves`: new ``(n, 3)`` positions, interior vertices unchanged.

    Parameters
    ----------
    vertices : (n, 3) float64
    triangles : (m, 3) int64
    number_of_iterations : int
        Steps of the section 3.3 update; 0 returns a copy.
    reimpose_every : int or None
        Re-take the midpoint constraints from the current curve every this many
        steps (stronger smoothing); ``None`` keeps the input curve as ``p^0``.

    Works on any boundary, walked as :func:`~o3d_lsmesh.topology.boundary_curves`.
    """
    vertices, triangles = mesh_arrays(vertices, triangles)
    number_of_iterations = as_iterations(number_of_iterations)
    if reimpose_every is not None:
        reimpose_every = as_count(reimpose_every, name="reimpose_every", minimum=1)
    if number_of_iterations == 0:
        return vertices
    op = curve_operator(boundary_curves(triangles, len(vertices)))
    return run_curve_iterations(vertices, op, number_of_iterations, reimpose_every=reimpose_every)


def run_curve_iterations(
    vertices: np.ndarray, op: CurveOperator, number_of_iterations: int, *, reimpose_every: int | None = None
) -> np.ndarray:
    """Apply ``number_of_iterations`` curve steps of ``op`` to a copy of ``vertices`` (``(n, 3)``)."""
    out = np.array(vertices, dtype=np.float64)
    if len(op) == 0:
        return out
    target = op.target(out)
    for iteration in range(number_of_iterations):
        if reimpose_every is not None and iteration and iteration % reimpose_every == 0:
            target = op.target(out)
        out[op.vertex] = op.step(out, target)
    return out


def smooth_boundary_curves(mesh: MeshT, number_of_iterations: int = 10) -> MeshT:
    """Smooth every boundary loop of an open mesh with midpoint-constrained curve fairing.

    The local curve equation of Liu et al. 2001, section 3.3 (module docstring): each boundary
    segment is relaxed with its midpoint held at the input and a point's estimates are averaged.
    Interior vertices do not move; a closed mesh comes back unchanged. A pinch (holes touching at
    a vertex) averages its estimates from every passage; a fin's vertices, the ends of the open
    chains there, 3-loops and chains of fewer than four edges (:data:`MIN_LOOP_LENGTH`) are held.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
    number_of_iterations : int
        Smoothing steps; 0 returns an unchanged copy.

    Returns
    -------
    mesh
        A new mesh of the input's kind with the same triangles; vertex colors
        and other per-vertex attributes are kept, normals recomputed if present.

    Raises
    ------
    TypeError
        ``mesh`` is not a mesh, or ``number_of_iterations`` is not an integer.
    ValueError
        Negative ``number_of_iterations``; an invalid mesh.

    See Also
    --------
    smooth_boundary_curves_arrays : the array core.
    o3d_lsmesh.fairing.constrained_fairing : surface fairing that calls this for the boundary.

    Examples
    --------
    >>> import numpy as np, open3d as o3d
    >>> box = o3d.geometry.TriangleMesh.create_box()
    >>> box.triangles = o3d.utility.Vector3iVector(np.asarray(box.triangles)[2:])  # open one face
    >>> out = smooth_boundary_curves(box, number_of_iterations=3)
    >>> len(out.vertices) == len(box.vertices)
    True
    """
    number_of_iterations = as_iterations(number_of_iterations)
    data = read_mesh(mesh, weld=True)
    return new_mesh(data, smooth_boundary_curves_arrays(data.vertices, data.triangles, number_of_iterations))

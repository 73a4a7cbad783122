"""Boundary-curve fairing with segment-midpoint constraints (Liu et al. 2001, section 3.3).

Every boundary loop of an open mesh is a closed polygon ``p_0 .. p_{l-1}``.
For each segment ``(p_{i-1}, p_i)`` the paper minimizes the curve Laplacian
energy ``|L(p_{i-1})|^2 + |L(p_i)|^2`` (weights 1/2) with the segment's
midpoint held at its position in the constraint curve ``p^0``; the closed form
is the section 3.3 local equation::

    [p_{i-1}]   [2/3 1/3] [p_{i-2}]   [d]
    [p_i    ] = [1/3 2/3] [p_{i+1}] + [d],
    d = ((p^0_{i-1} + p^0_i) - (p_{i-2} + p_{i+1})) / 2.

Every point lies on two segments and so gets two estimates; their average is

    p_i <- (p_{i-1} + p_{i+1} - p_{i-2} - p_{i+2}) / 12 + (p^0_{i-1} + 2 p^0_i + p^0_{i+1}) / 4,

a fixed linear map of the current curve and of ``p^0``. All loops are
concatenated and stepped at once through four index arrays (previous, next,
second previous, second next), so an iteration is a handful of gathers.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._o3d import new_mesh, read_mesh
from .._validate import as_count
from ..topology import boundary_loops, nonmanifold_edges

__all__ = [
    "CurveOperator",
    "curve_operator",
    "smooth_boundary_curves_arrays",
    "smooth_boundary_curves",
    "MIN_LOOP_LENGTH",
]

#: Loops shorter than this are held fixed. In a 3-loop the two outer
#: neighbours of every segment are the same vertex, the energy of section 3.3
#: degenerates and the update moves each corner three quarters of the way to
#: the centroid in one step, so such small holes would be shrunk, not smoothed.
MIN_LOOP_LENGTH = 4


@dataclass(frozen=True)
class CurveOperator:
    """Index arrays that step every boundary loop at once (all ``(b,) int64``).

    ``vertex[j]`` is a boundary vertex; ``prev``/``next`` and
    ``prev2``/``next2`` are its neighbours one and two steps along its loop.
    Only loops with at least :data:`MIN_LOOP_LENGTH` vertices are included.
    """

    vertex: np.ndarray
    prev: np.ndarray
    next: np.ndarray
    prev2: np.ndarray
    next2: np.ndarray

    def __len__(self) -> int:
        return len(self.vertex)

    def target(self, positions0: np.ndarray) -> np.ndarray:
        """The constant part ``(p^0_{i-1} + 2 p^0_i + p^0_{i+1}) / 4``, ``(b, 3)``."""
        return 0.25 * (positions0[self.prev] + 2.0 * positions0[self.vertex] + positions0[self.next])

    def step(self, positions: np.ndarray, target: np.ndarray) -> np.ndarray:
        """New positions ``(b, 3)`` of :attr:`vertex` after one averaged relaxation of every segment."""
        return (
            positions[self.prev] + positions[self.next] - positions[self.prev2] - positions[self.next2]
        ) / 12.0 + target


def curve_operator(loops: list[np.ndarray]) -> CurveOperator:
    """Build the :class:`CurveOperator` of ordered closed ``loops`` (each an ``(l,)`` vertex index array).

    Examples
    --------
    >>> import numpy as np
    >>> op = curve_operator([np.array([5, 6, 7, 8])])
    >>> op.prev.tolist(), op.next2.tolist()
    ([8, 5, 6, 7], [7, 8, 5, 6])
    """
    loops = [np.asarray(loop, dtype=np.int64) for loop in loops if len(loop) >= MIN_LOOP_LENGTH]
    if not loops:
        empty = np.zeros(0, dtype=np.int64)
        return CurveOperator(empty, empty, empty, empty, empty)
    lengths = np.array([len(loop) for loop in loops], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    vertex = np.concatenate(loops)  # (b,)
    length = np.repeat(lengths, lengths)  # (b,) length of the loop of each entry
    start = np.repeat(offsets, lengths)  # (b,) where that loop starts in ``vertex``
    position = np.arange(len(vertex)) - start  # (b,) position along its loop

    def shifted(by: int) -> np.ndarray:
        # e.g. loop [5, 6, 7, 8], by=-1 -> positions [3, 0, 1, 2] -> [8, 5, 6, 7]
        return vertex[start + (position + by) % length]

    return CurveOperator(vertex, shifted(-1), shifted(1), shifted(-2), shifted(2))


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

    Raises
    ------
    ValueError
        An edge shared by more than two triangles, or a boundary vertex on
        other than two boundary edges (a boundary bow-tie): the boundary is
        then not a set of simple loops.
    """
    vertices = np.array(vertices, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64)
    number_of_iterations = as_count(number_of_iterations, name="number_of_iterations")
    if reimpose_every is not None:
        reimpose_every = as_count(reimpose_every, name="reimpose_every", minimum=1)
    if number_of_iterations == 0:
        return vertices
    _check_boundary_manifold(triangles, len(vertices))
    op = curve_operator(boundary_loops(triangles, len(vertices)))
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


def _check_boundary_manifold(triangles: np.ndarray, n: int) -> None:
    bad = nonmanifold_edges(triangles, n)
    if len(bad):
        raise ValueError(
            f"mesh must be edge-manifold, got edge ({int(bad[0, 0])}, {int(bad[0, 1])}) shared by more than "
            f"two triangles ({len(bad)} such edges)"
        )


def smooth_boundary_curves(mesh: Any, number_of_iterations: int = 10) -> Any:
    """Smooth every boundary loop of an open mesh with midpoint-constrained curve fairing.

    Implements the local curve equation of Liu et al. 2001, section 3.3 (see
    the module docstring): each boundary segment is relaxed with its midpoint
    held at the input, and a point's two estimates are averaged. Interior
    vertices do not move; a closed mesh comes back unchanged. Loops with fewer
    than four vertices are held fixed (:data:`MIN_LOOP_LENGTH`).

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
        Negative ``number_of_iterations``; an edge shared by more than two
        triangles; a boundary vertex on other than two boundary edges.

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
    number_of_iterations = as_count(number_of_iterations, name="number_of_iterations")
    data = read_mesh(mesh, weld=True)
    return new_mesh(data, smooth_boundary_curves_arrays(data.vertices, data.triangles, number_of_iterations))

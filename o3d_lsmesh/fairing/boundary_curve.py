"""Boundary-curve fairing with segment-midpoint constraints (Liu et al. 2001, section 3.3).

Each segment's curve Laplacian energy is minimized with its midpoint held; every point averages its
two estimates, a fixed linear map assembled once (:class:`CurveOperator`). Loops pass pinches fan by
fan; chains end at fins, which are held. Docs: ``docs/algorithms/boundary_curves.rst``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .._o3d import new_mesh, read_mesh
from ..core.boundary import BoundaryCurves, boundary_curves
from ..core.liu import CurveOperator, curve_laplacian
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

#: Closed loops shorter than this are held: on a 3-loop the per-segment relaxation degenerates (both
#: outer neighbours are one vertex) and would shrink the hole (docs/algorithms/boundary_curves.rst).
MIN_LOOP_LENGTH = 4


def curve_operator(curves: BoundaryCurves | list) -> CurveOperator:
    """The :class:`~o3d_lsmesh.core.liu.CurveOperator` of boundary curves (loops or ``BoundaryCurves``).

    Loops of fewer than :data:`MIN_LOOP_LENGTH` vertices and chains of fewer edges are held
    (:func:`o3d_lsmesh.core.liu.curve_laplacian`).

    >>> curve_operator([np.array([5, 6, 7, 8])]).vertex.tolist()
    [5, 6, 7, 8]
    """
    return curve_laplacian(curves, MIN_LOOP_LENGTH)


def smooth_boundary_curves_arrays(
    vertices: np.ndarray,
    triangles: np.ndarray,
    number_of_iterations: int = 10,
    *,
    reimpose_every: int | None = None,
) -> np.ndarray:
    """Array core of :func:`smooth_boundary_curves`: new ``(n, 3)`` positions, interior vertices unchanged.

    ``reimpose_every``: re-take the midpoint constraints from the current curve every this many steps
    (stronger smoothing); ``None`` keeps the input curve as ``p^0``.
    """
    vertices, triangles = mesh_arrays(vertices, triangles)
    number_of_iterations = as_iterations(number_of_iterations)
    if reimpose_every is not None:
        reimpose_every = as_count(reimpose_every, name="reimpose_every", minimum=1)
    return _smooth(vertices, triangles, number_of_iterations, reimpose_every)


def _smooth(
    vertices: np.ndarray, triangles: np.ndarray, iterations: int, reimpose_every: int | None
) -> np.ndarray:
    # checked arrays and options in, new (n, 3) positions out
    if iterations == 0:
        return vertices
    op = curve_operator(boundary_curves(triangles, len(vertices)))
    return run_curve_iterations(vertices, op, iterations, reimpose_every=reimpose_every)


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
    """Smooth every boundary loop of an open mesh with midpoint-constrained curve fairing (section 3.3).

    Interior vertices do not move; a closed mesh comes back unchanged. Pinches average their
    passages; fins, 3-loops and chains under :data:`MIN_LOOP_LENGTH` edges are held
    (``docs/algorithms/boundary_curves.rst``). Returns a new mesh of the input's kind, same
    triangles, attributes kept, normals recomputed.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
    number_of_iterations : int
        Smoothing steps; 0 returns an unchanged copy.

    Raises
    ------
    InputError
        An invalid mesh or a negative ``number_of_iterations`` (``InputTypeError``: a wrong type).

    Examples
    --------
    >>> import open3d as o3d
    >>> box = o3d.geometry.TriangleMesh.create_box()
    >>> box.triangles = o3d.utility.Vector3iVector(np.asarray(box.triangles)[2:])  # open one face
    >>> len(smooth_boundary_curves(box, number_of_iterations=3).vertices)
    8
    """
    number_of_iterations = as_iterations(number_of_iterations)
    data = read_mesh(mesh, weld=True)
    return new_mesh(data, _smooth(data.vertices, data.triangles, number_of_iterations, None))

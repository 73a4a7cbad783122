"""Multiresolution fairing (Liu et al. 2001, section 4.2): fair a coarse level, split back up, repeat.

Docs: ``docs/algorithms/multiresolution.rst``.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np

from .._o3d import new_mesh, read_mesh
from ..core.boundary import boundary_curves
from ..core.connectivity import Connectivity, VertexRings
from ..core.errors import InputError, InputTypeError
from ..core.progress import Progress
from ..core.validate import as_bool, as_choice, as_count, as_iterations
from ..hierarchy.hierarchy import ALPHA, BETA, MeshHierarchy, boundary_degree, collapse_hierarchy
from .boundary_curve import curve_operator, run_curve_iterations
from .constrained import _fair, fair_local
from .tuning import DEFAULT_MU

if TYPE_CHECKING:
    from .._types import MeshT

__all__ = ["multiresolution_fairing", "multiresolution_fairing_arrays"]


def multiresolution_fairing_arrays(
    hierarchy: MeshHierarchy,
    level: int,
    *,
    number_of_iterations: int = 5,
    final_iterations: int | None = None,
    method: str = "local",
    progress: bool = False,
) -> np.ndarray:
    """Array core of :func:`multiresolution_fairing`: faired ``(n_0, 3)`` positions of level 0 (each
    level's Connectivity built once; the rounds on ``M_0`` run on one operator)."""
    if not isinstance(hierarchy, MeshHierarchy):
        raise InputTypeError(
            f"hierarchy must be a MeshHierarchy, got {type(hierarchy).__name__}", param="hierarchy"
        )
    level, number_of_iterations, final_iterations, method, progress = _checked(
        level, number_of_iterations, final_iterations, method, progress
    )
    if level >= len(hierarchy):
        raise InputError(f"level must be < len(hierarchy) = {len(hierarchy)}, got {level}", param="level")
    triangles = hierarchy.triangles
    conn = Connectivity(triangles[level], len(hierarchy.representatives[level]))
    positions = hierarchy.vertices[hierarchy.representatives[level]]  # a copy: fairing writes to it
    if level == 0:
        return _fair_level(positions, conn, number_of_iterations, method)
    with Progress(progress, "multiresolution fairing").bar(level, unit="level") as bar:
        for i in range(level, 0, -1):
            positions = _fair_level(positions, conn, number_of_iterations, method)
            conn = Connectivity(triangles[i - 1], len(hierarchy.representatives[i - 1]))
            positions = hierarchy.refine_with_rings(i, positions, conn.rings)
            bar.update(1)
    # M_0 in rounds, barycenters re-imposed after each (the docstring says why): one fairing of M_0 holds
    # the barycenters where the splits put them, and more iterations of it change nothing (measured)
    remaining = number_of_iterations * (level + 1) if final_iterations is None else final_iterations
    if remaining == 0:
        return positions
    # the boundary curves are put where level 0 puts them and held: re-faired round after round, their
    # midpoint constraints are a curve-shortening flow that closes holes (docs/algorithms/multiresolution.rst)
    boundary, placed = _input_boundary(hierarchy.vertices, conn, number_of_iterations, method)
    positions[boundary] = placed
    # the connectivity is fixed: one operator for all rounds ("global" re-takes its targets at every solve)
    rounds = method == "local" and 0 < number_of_iterations < remaining
    reimpose = number_of_iterations if rounds else None
    return _fair_level(positions, conn, remaining, method, smooth_boundary=False, reimpose_every=reimpose)


def _checked(level: Any, iterations: Any, final: Any, method: Any, progress: Any) -> tuple:
    """The options of :func:`multiresolution_fairing`, checked (``level`` against a hierarchy: its caller)."""
    final = None if final is None else as_iterations(final, name="final_iterations")
    # Liu's per-level operators only: the scan energy and the feature mode are not per-level fairings
    # (refused, not run as the local operator)
    method = as_choice(method, ("local", "global"), name="method")
    return (
        as_count(level, name="level"),
        as_iterations(iterations),
        final,
        method,
        as_bool(progress, name="progress"),
    )


def _fair_level(
    positions: np.ndarray,
    conn: Connectivity,
    iterations: int,
    method: str,
    *,
    smooth_boundary: bool = True,
    reimpose_every: int | None = None,
) -> np.ndarray:
    """Constrained fairing of a level, ``positions (n, 3)`` overwritten; a pinched boundary is held."""
    if iterations == 0:
        return positions
    smooth_boundary = smooth_boundary and _is_simple(conn.rings)
    if method == "global":
        options = {"number_of_iterations": iterations, "mu": DEFAULT_MU, "smooth_boundary": smooth_boundary}
        return _fair(positions, conn, "global", {**options, "progress": False})
    return fair_local(positions, conn, iterations, smooth_boundary, reimpose_every, False)


def _input_boundary(
    vertices: np.ndarray, conn: Connectivity, iterations: int, method: str
) -> tuple[np.ndarray, np.ndarray]:
    """The sorted boundary vertices ``(b,)`` and the positions ``(b, 3)`` ``_fair_level`` gives them on
    the input (its boundary steps read boundary vertices only, so they run alone)."""
    degree = boundary_degree(conn.rings)
    boundary = np.flatnonzero(degree)
    if len(boundary) == 0 or not _is_simple(conn.rings, degree):
        return boundary, vertices[boundary]
    smoothed = run_curve_iterations(
        vertices,
        curve_operator(boundary_curves(conn.triangles, len(vertices), conn=conn)),
        iterations,
        reimpose_every=1 if method == "global" else None,
    )
    return boundary, smoothed[boundary]


def _is_simple(rings: VertexRings, degree: np.ndarray | None = None) -> bool:
    """Whether every boundary vertex has two edges of one triangle (always so on a volume-cost hierarchy level)."""
    if not rings.boundary.any():
        return True
    degree = boundary_degree(rings) if degree is None else degree
    return bool(np.all((degree == 0) | (degree == 2)))


def multiresolution_fairing(
    mesh: MeshT,
    level: int,
    *,
    hierarchy: MeshHierarchy | None = None,
    number_of_iterations: int = 5,
    final_iterations: int | None = None,
    method: str = "local",
    progress: bool = False,
) -> MeshT:
    """Smooth a mesh at a chosen scale by fairing a coarse level and splitting back up (Liu et al. 2001, 4.2).

    From ``level`` down to 1: fair ``M_i`` (section 3, its own barycenters held), then split to
    ``M_{i-1}`` (:meth:`MeshHierarchy.refine`); then ``M_0`` is faired in rounds, barycenters
    re-imposed, boundary held where ``level=0`` puts it. Any mesh; a pinched boundary is held.
    Returns a new mesh of the input's kind and connectivity. Why the rounds:
    ``docs/algorithms/multiresolution.rst``.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
    level : int
        Starting level, ``0 <= level < len(hierarchy)``.
    hierarchy : MeshHierarchy, optional
        Built from ``mesh`` (reuse it across calls); default ``build_hierarchy(mesh, min_vertices=4)``
        up to ``level``.
    number_of_iterations : int
        Fairing iterations on every level.
    final_iterations : int, optional
        Iterations on ``M_0`` after the last split, in rounds of ``number_of_iterations`` (``None``:
        ``number_of_iterations * (level + 1)``; 0: the paper's loop, boundary included).
    method : {"local", "global"}
        Constrained fairing operator.
    progress : bool
        Bars for the hierarchy build and the levels.

    Raises
    ------
    InputError
        Invalid mesh, ``level`` out of range, a hierarchy of another mesh (``InputTypeError``: a wrong type).

    Examples
    --------
    >>> import numpy as np, open3d as o3d
    >>> sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=20)
    >>> len(multiresolution_fairing(sphere, 3).triangles) == len(sphere.triangles)
    True
    """
    level, number_of_iterations, final_iterations, method, progress = _checked(
        level, number_of_iterations, final_iterations, method, progress
    )
    # a given hierarchy indexes the mesh's own vertices (build_hierarchy does not weld): weld only
    # when the hierarchy is built here, on the welded surface
    data = read_mesh(mesh, weld=hierarchy is None)
    if hierarchy is None:
        options: dict[str, Any] = dict(
            alpha=ALPHA, beta=BETA, min_vertices=4, max_levels=level, progress=progress
        )
        hierarchy = collapse_hierarchy(data.vertices, data.triangles, **options)  # read_mesh's checked copies
        levels = f"{len(hierarchy)} (the levels build_hierarchy reaches for this mesh)"
    else:
        if not isinstance(hierarchy, MeshHierarchy):
            raise InputTypeError(
                f"hierarchy must be a MeshHierarchy, got {type(hierarchy).__name__}", param="hierarchy"
            )
        if len(hierarchy.vertices) != len(data.vertices) or not np.array_equal(
            hierarchy.triangles[0], data.triangles
        ):
            raise InputError(
                f"hierarchy must be built from mesh, got one of {len(hierarchy.vertices)} vertices and "
                f"{len(hierarchy.triangles[0])} triangles for a mesh of {len(data.vertices)} and {len(data.triangles)}",
                param="hierarchy",
            )
        levels = f"len(hierarchy) = {len(hierarchy)}"
        if not np.array_equal(hierarchy.vertices, data.vertices):
            # same connectivity, new positions: the coarse levels take their positions from this mesh
            hierarchy = dataclasses.replace(hierarchy, vertices=data.vertices)
    if level >= len(hierarchy):
        raise InputError(f"level must be < {levels}, got {level}", param="level")
    positions = multiresolution_fairing_arrays(
        hierarchy,
        level,
        number_of_iterations=number_of_iterations,
        final_iterations=final_iterations,
        method=method,
        progress=progress,
    )
    return new_mesh(data, positions)

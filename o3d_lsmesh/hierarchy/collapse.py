"""One level of the volume-cost mesh hierarchy (Liu et al. 2001, section 4.1).

A level removes a set of vertices, each by a half-edge collapse ``x -> k``
into the 1-ring neighbour ``k`` of least cone volume

    V(x -> k) = | sum_j (x_j - x_k) x (x_{j+1} - x_k) . (x - x_k) | = | N_x . (x_k - x) |,

``N_x`` being the sum of the (doubled-area) normals of the triangles around
``x`` (each term is six times the volume of the tetrahedron ``(x, x_j,
x_{j+1}, x_k)``, affine in ``x_k``). Ties within a relative ``1e-9`` go to
the shortest edge, then to the first neighbour in index order.

The loop (compiled, ``_kernel.pyx``; the same loop in plain Python is the
oracle of the tests) visits the vertices in increasing
``cost(x) = alpha * min_edge(x) + beta * max_edge(x)`` (ties by index) and
skips ``x`` when ``x`` or its target lies in the closed 1-ring of a vertex
already removed in this level. A collapse reads only the 1-rings of ``x`` and
``k``, and changes only the 1-rings of ``N(x)``, so with this rule every
collapse of the level is valid on the level's mesh as well as after the ones
before it, and the removed vertices are pairwise non-adjacent (what
:meth:`MeshHierarchy.refine` needs to split them back in closed form).

A target is tried in that order, at most ``max_tries`` of them, and taken when
the collapse is valid:

* link condition: ``x`` and ``k`` have exactly the common neighbours of the
  edge's triangles (2 inside, 1 on a boundary edge). With a virtual vertex
  coning off each boundary loop this is the link condition of Dey et al., and
  it keeps the Euler characteristic and the boundary loops;
* a boundary vertex collapses only along a boundary edge, an interior one
  only along an interior edge;
* no closed tetrahedron (``x`` and ``k`` interior of valence 3) and no
  isolated triangle (``x`` and ``k`` on the boundary, of valence 2);
* every triangle of the star of ``x`` that survives keeps its orientation and
  turns its normal by less than ``max_normal_angle``, and its
  ``2 * area / (sum of squared edge lengths)`` stays above ``min_quality``;
* locked vertices are never removed and never a target.

Locked are the vertices the caller names (non-manifold ones: several fans of
triangles, see :func:`o3d_lsmesh.topology.nonmanifold_vertices`, and
unreferenced ones) and every vertex on an edge of more than two triangles.
Every other vertex has a disk or half-disk for its star, so the rules above
are those of a manifold mesh, and the set of non-manifold vertices stays the
same at every level.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["LevelCollapse", "collapse_level", "workspace"]


@dataclass(frozen=True)
class LevelCollapse:
    """The collapses of one level, in the indices of the finer level ``i - 1``.

    Attributes
    ----------
    removed : (r,) int64
        Vertices removed, sorted.
    targets : (r,) int64
        The vertex each one was merged into (kept at level ``i``).
    ring_offsets : (r + 1,) int64
        CSR offsets into ``ring``.
    ring : (sum of valences,) int64
        The 1-ring of each removed vertex at level ``i - 1``, sorted.
    parent : (n_{i-1},) int64
        Index at level ``i`` of every vertex of level ``i - 1``.
    triangles : (m_i, 3) int64
        Triangles of level ``i`` (those of level ``i - 1`` mapped by ``parent``,
        in order, collapsed ones dropped).
    """

    removed: np.ndarray
    targets: np.ndarray
    ring_offsets: np.ndarray
    ring: np.ndarray
    parent: np.ndarray
    triangles: np.ndarray


def _kernel():
    try:
        from . import _kernel
    except ImportError as error:  # a source tree used without building it
        raise ImportError(
            "o3d_lsmesh's compiled hierarchy kernel is not built: install the package with "
            "`pip install .` (or `pip install -e .`), or run `python setup.py build_ext --inplace` "
            "in a source tree (needs Cython and a C compiler)"
        ) from error
    return _kernel


def workspace():
    """Buffers the kernel reuses from level to level (fresh pages cost more than the loop on them)."""
    return _kernel().Workspace()


def collapse_level(
    vertices: np.ndarray,
    triangles: np.ndarray,
    *,
    alpha: float = 1.0,
    beta: float = 0.01,
    max_removals: int | None = None,
    max_normal_angle: float = 60.0,
    min_quality: float = 1e-3,
    max_tries: int = 3,
    locked: np.ndarray | None = None,
    workspace: object | None = None,
) -> LevelCollapse | None:
    """Select and apply one level of volume-cost half-edge collapses (module docstring).

    Parameters
    ----------
    vertices : (n, 3) float64
        Positions of the level's vertices.
    triangles : (m, 3) int64
        Triangles with three distinct vertices each.
    alpha, beta : float
        Non-negative weights of the shortest and longest incident edge in the cost.
    max_removals : int, optional
        Remove at most this many vertices (the first ones in cost order).
    max_normal_angle : float
        Angle in degrees a surviving triangle's normal must turn less than (90 or more: it
        must only not flip).
    min_quality : float
        ``2 * area / (sum of squared edge lengths)`` a new triangle must stay
        above (an equilateral triangle has ``1/sqrt(3)``).
    max_tries : int
        Targets tried per vertex, in the order above, before it waits for the next level.
    locked : (n,) bool, optional
        Vertices never removed and never a target.
    workspace : optional
        A :func:`workspace` to reuse between the levels of one hierarchy (one thread at a time).

    Returns
    -------
    LevelCollapse or None
        ``None`` when no valid collapse remains.
    """
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    triangles = np.ascontiguousarray(triangles, dtype=np.int64)
    n = len(vertices)
    locked = np.zeros(n, dtype=np.uint8) if locked is None else np.ascontiguousarray(locked, dtype=np.uint8)
    limit = n if max_removals is None else max(int(max_removals), 0)
    # at 90 degrees or more only the flip test (a positive dot product of the normals) remains
    cos_sq = float(np.cos(np.deg2rad(max_normal_angle)) ** 2) if max_normal_angle < 90 else 0.0
    if workspace is None:
        workspace = _kernel().Workspace()
    result = workspace.collapse_level(
        vertices,
        triangles,
        locked,
        float(alpha),
        float(beta),
        limit,
        cos_sq,
        float(min_quality),
        int(max_tries),
    )
    return None if result is None else LevelCollapse(*result)

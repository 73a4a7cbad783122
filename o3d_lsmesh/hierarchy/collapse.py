"""Levels of the volume-cost mesh hierarchy (Liu et al. 2001, section 4.1).

A level removes vertices by half-edge collapses ``x -> k`` into the 1-ring
neighbour of least cone volume ``V(x -> k) = |N_x . (x_k - x)|``, ``N_x`` the
sum of the doubled-area normals around ``x`` (ties within a relative ``1e-9``
to the shortest edge, then the first in index order). The compiled loop
(``_kernel.pyx``; the same loop in plain Python is the tests' oracle) visits
the vertices in increasing ``cost(x) = alpha * min_edge(x) + beta * max_edge(x)``
(ties by index) and skips ``x`` when ``x`` or its target lies in the closed
1-ring of a vertex already removed in this level: a collapse reads the 1-rings
of ``x`` and ``k`` and changes only those of ``N(x)``, so every collapse stays
valid and the removed vertices are pairwise non-adjacent (as
:meth:`MeshHierarchy.refine` needs). At most ``max_tries`` targets are tried;
one is taken when

* the link condition holds: ``x`` and ``k`` share exactly the opposite
  vertices of their edge's triangles (this keeps Euler characteristic and
  boundary loops);
* a boundary ``x`` collapses along a boundary edge (an interior ``x`` has only
  edges of two triangles: one of one triangle makes it boundary, one of three
  locks it);
* no isolated triangle or closed tetrahedron would remain;
* every surviving triangle of the star of ``x`` keeps its orientation, turns
  its normal by less than ``max_normal_angle``, and keeps
  ``2 * area / (sum of squared edge lengths)`` above ``min_quality``;
* ``k`` is not locked. Locked are the caller's vertices and every vertex on an
  edge of more than two triangles (with ``lock_fans``: also unreferenced
  vertices and those whose triangles form several fans), so every other star
  is a disk or half-disk and the non-manifold vertices stay at every level.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

__all__ = ["LevelCollapse", "collapse_level", "collapse_levels"]


class LevelCollapse(NamedTuple):
    """One level's collapses in level ``i - 1`` indices: ``removed``/``targets`` (r,), CSR ``ring_offsets``/``ring``
    (sorted 1-rings of the removed), ``parent`` (n_{i-1},) to level ``i``, its ``triangles`` (m_i, 3)
    (mapped in order, collapsed ones dropped), ``kept`` (n_i,) indices at level 0; int64."""

    removed: np.ndarray
    targets: np.ndarray
    ring_offsets: np.ndarray
    ring: np.ndarray
    parent: np.ndarray
    triangles: np.ndarray
    kept: np.ndarray


def collapse_levels(
    vertices: np.ndarray,
    triangles: np.ndarray,
    *,
    alpha: float = 1.0,
    beta: float = 0.01,
    min_vertices: int = 0,
    max_levels: int | None = None,
    max_normal_angle: float = 60.0,
    min_quality: float = 1e-3,
    max_tries: int = 3,
    locked: np.ndarray | None = None,
    lock_fans: bool = False,
    report: Callable[[int], Any] | None = None,
) -> tuple[np.ndarray, list[LevelCollapse]]:
    """``(locked (n,) bool, levels)``: levels until ``min_vertices`` or no valid collapse (module docstring).

    ``alpha, beta >= 0`` weigh the shortest and longest edge of the cost; a level removes at most
    ``n_i - min_vertices``; ``report(removed)`` is called after each level. The returned lock is ``locked``
    with what the kernel locks at level 0.
    """
    try:
        from . import _kernel
    except ImportError as error:  # a source tree used without building it
        raise ImportError(
            "o3d_lsmesh's compiled hierarchy kernel is not built: `pip install .` (or `pip install -e .`), or "
            "`python setup.py build_ext --inplace` in a source tree (needs Cython and a C compiler)"
        ) from error
    n = len(vertices)
    lock = np.zeros(n, np.uint8) if locked is None else np.array(locked, dtype=bool).view(np.uint8)
    # at 90 degrees or more only the flip test (a positive dot product of the normals) remains
    cos_sq = float(np.cos(np.deg2rad(max_normal_angle)) ** 2) if max_normal_angle < 90 else 0.0
    first, levels = _kernel.hierarchy(
        np.array(vertices, dtype=np.float64, order="C"),  # positions and lock: compacted in place
        np.ascontiguousarray(triangles, dtype=np.int64),
        lock,
        float(alpha),
        float(beta),
        int(min_vertices),
        n + 1 if max_levels is None else int(max_levels),
        cos_sq,
        float(min_quality),
        int(max_tries),
        bool(lock_fans),
        report,
    )
    return first, [LevelCollapse(*t) for t in levels]


def collapse_level(
    vertices: np.ndarray, triangles: np.ndarray, *, max_removals: int | None = None, **options: Any
) -> LevelCollapse | None:
    """One level of at most ``max_removals`` collapses (options of :func:`collapse_levels`), or ``None``."""
    n = len(vertices)
    limit = n if max_removals is None else max(int(max_removals), 0)
    levels = collapse_levels(vertices, triangles, min_vertices=n - limit, max_levels=1, **options)[1]
    return levels[0] if levels else None

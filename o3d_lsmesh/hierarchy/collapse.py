"""Levels of the volume-cost hierarchy (Liu et al. 2001, section 4.1): the rules of the compiled loop.

The loop (``_kernel.pyx``; ``tests/_hierarchy_oracle.py`` is the same loop in plain Python) visits the
unlocked vertices in increasing ``cost(x) = alpha * min_edge(x) + beta * max_edge(x)`` (ties by index) and
skips ``x`` when ``x`` is in the closed 1-ring of a vertex already removed in this level. ``x`` tries its
neighbours ``k`` in increasing cone volume ``|N_x . (x_k - x)|`` (``N_x`` the summed doubled-area normals
around ``x``; ties within a relative 1e-9 to the shortest edge, then the first in index order), at most
``max_tries`` of them; a ``k`` in such a closed 1-ring ends the search. A collapse reads the 1-rings of
``x`` and ``k`` and changes only those of ``N(x)``, so every collapse stays valid and the removed vertices
are pairwise non-adjacent (:meth:`MeshHierarchy.refine` needs it). ``x`` collapses into the first ``k``
for which

* ``k`` is not locked, a boundary ``x`` moves along a boundary edge, and no isolated triangle or closed
  tetrahedron would remain;
* every surviving triangle of the star of ``x`` keeps its orientation, turns its normal by less than
  ``max_normal_angle`` and keeps ``2 * area / (sum of squared edge lengths)`` above ``min_quality``;
* the link condition holds: ``x`` and ``k`` share only the opposite vertices of their edge (Euler
  characteristic and boundary loops stay).

Locked is every vertex on an edge of more than two triangles (``lock_fans``: also unreferenced vertices and
those whose triangles form several fans), so every other star is a disk or half-disk, and every level keeps
the input's non-manifold vertices.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

__all__ = ["LevelCollapse", "collapse_levels"]


class LevelCollapse(NamedTuple):
    """A level in level ``i - 1`` indices (int64): ``removed`` and their ``targets``, their sorted 1-rings
    (CSR ``ring_offsets``, ``ring``), ``parent`` (index at level ``i``), the level's ``triangles`` (mapped in
    order, collapsed ones dropped), and ``kept``: the input index of each vertex of level ``i``."""

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
    lock_fans: bool = False,
    report: Callable[[int], Any] | None = None,
) -> tuple[np.ndarray, list[LevelCollapse]]:
    """``(locked vertices of level 0 (n,) bool, levels)``, a level removing at most ``n_i - min_vertices``
    vertices, until ``max_levels`` or no valid collapse; ``report(removed count)`` after each level."""
    from ._kernel import hierarchy  # built by the package's build (``pip install .``, ``setup.py build_ext``)

    # at 90 degrees or more only the flip test (a positive dot product of the normals) remains
    cos_sq = float(np.cos(np.deg2rad(max_normal_angle)) ** 2) if max_normal_angle < 90 else 0.0
    P, T = np.array(vertices, dtype=np.float64, order="C"), np.ascontiguousarray(triangles, dtype=np.int64)
    limit, lock = len(P) + 1 if max_levels is None else max_levels, np.zeros(len(P), np.uint8)
    options = (alpha, beta, min_vertices, limit, cos_sq, min_quality, max_tries, lock_fans)
    levels = hierarchy(P, T, lock, *options, report or (lambda _: None))
    return lock.view(bool), [LevelCollapse(*level) for level in levels]

"""Tuned constants of hole filling, each with the benchmark result that set it (docs: algorithms/hole_filling)."""

import numpy as np

# loops with more edges are cut by chords before the O(k^3) programme: benchmarks/results/fill_holes.md
DP_MAX_EDGES = 200
# outer border: less than this fraction of the component's area faces away: benchmarks/results/border.md
BORDER_FACING_AWAY = 0.25
# "sideways" to the loop: cosine below this (a box with a hole in its top): benchmarks/results/border.md
SIDEWAYS = 0.2
# the largest density; not fitted: the refinement's budget stops at about density 2 (see the docs page)
DENSITY_MAX = 4.0
# Liepa's density factor (SGP 2003, section 4; CGAL's default), not fitted: benchmarks/results/fill_holes.md
ALPHA = float(np.sqrt(2.0))
# Delaunay restriction: a point this near (relative) a circumsphere is on it; a tolerance, not fitted
COSPHERICAL = 1e-9
# a cotangent solve that moves a vertex by more than this fraction of its patch's size from the uniform
# one is taken for ill-conditioned and not kept: leave one mesh out in benchmarks/results/fill_holes_study.md
COTANGENT_LEAP = 0.1

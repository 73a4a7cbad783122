"""Our volume-cost hierarchy against fast-simplification's QEM at the same triangle count.

The bounds come from measurement on the horse (benchmarks/bench_hierarchy.py has the full
tables): ours is closer on average at fine levels, its Hausdorff distance and volume loss
are larger (half-edge collapses keep input positions, QEM moves them), and every one of
our levels keeps the input's topology.
"""

import fast_simplification
import numpy as np
import pytest
from conftest import load_mesh

from o3d_lsmesh import build_hierarchy, metrics

LEVELS = [2, 4, 8, 12]  # 13,021 down to 1,590 vertices
# measured ratios ours / fast-simplification on the horse at these levels: mean distance
# 0.71-1.19, Hausdorff 1.5-2.7, volume change 1.6-2.0; bounds leave 20-30% headroom
MEAN_RATIO, HAUSDORFF_RATIO, VOLUME_RATIO = 1.5, 3.5, 2.4


@pytest.fixture(scope="module")
def horse_levels():
    mesh = load_mesh("horse.ply")
    V = np.asarray(mesh.vertices)
    F = np.asarray(mesh.triangles)
    hierarchy = build_hierarchy(mesh)
    rows = []
    for i in LEVELS:
        ours = hierarchy.level(i)
        target = len(ours.triangles)
        fv, ff = fast_simplification.simplify(V.astype(np.float32), F.astype(np.int32), target_count=target)
        rows.append((i, ours, (fv.astype(np.float64), ff.astype(np.int64))))
    return mesh, rows


def test_distances_and_volume_within_measured_bounds(horse_levels):
    mesh, rows = horse_levels
    diagonal = np.linalg.norm(np.ptp(np.asarray(mesh.vertices), axis=0))
    volume = metrics.signed_volume(mesh)
    for level, ours, theirs in rows:
        d_ours = metrics.surface_distance(mesh, ours, number_of_points=20_000)
        d_theirs = metrics.surface_distance(mesh, theirs, number_of_points=20_000)
        assert d_ours["mean"] <= MEAN_RATIO * d_theirs["mean"], level
        assert d_ours["hausdorff"] <= HAUSDORFF_RATIO * d_theirs["hausdorff"], level
        assert d_ours["hausdorff"] < 0.01 * diagonal, level
        change_ours = abs(metrics.signed_volume(ours) / volume - 1)
        change_theirs = abs(metrics.signed_volume(theirs) / volume - 1)
        assert change_ours <= VOLUME_RATIO * change_theirs + 1e-4, level


def test_our_levels_keep_topology_and_quality(horse_levels):
    _mesh, rows = horse_levels
    for level, ours, theirs in rows:
        summary = metrics.topology_summary(ours)
        assert summary["vertex_manifold"] and summary["euler"] == 2 and summary["boundary_loops"] == 0, level
        # fewer slivers than QEM at every measured level but the coarsest (0.085 vs 0.075 there)
        assert (
            metrics.triangle_angles(ours)["share_under_10"]
            <= 1.2 * metrics.triangle_angles(theirs)["share_under_10"]
        )

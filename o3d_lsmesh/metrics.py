"""Moved to :mod:`o3d_lsmesh.app.metrics` (silent re-export)."""

from .app.metrics import (
    MAX_SAMPLE_POINTS,
    normal_deviation,
    raycasting_scene,
    shape_change,
    signed_volume,
    surface_distance,
    topology_summary,
    triangle_angles,
    vertex_error,
)

__all__ = [
    "MAX_SAMPLE_POINTS",
    "normal_deviation",
    "raycasting_scene",
    "shape_change",
    "signed_volume",
    "surface_distance",
    "topology_summary",
    "triangle_angles",
    "vertex_error",
]

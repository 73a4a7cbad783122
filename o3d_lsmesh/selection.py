"""Old path of :mod:`o3d_lsmesh.lsmesh.selection`."""

from .lsmesh.selection import (
    SELECTION_METHODS,
    approximate,
    control_point_selection,
    select_control_points,
    start_vertices,
)

__all__ = [
    "SELECTION_METHODS",
    "approximate",
    "control_point_selection",
    "select_control_points",
    "start_vertices",
]

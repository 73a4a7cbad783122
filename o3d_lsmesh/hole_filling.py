"""The hole filling's old module path: its names now live in :mod:`o3d_lsmesh.holes`."""

from .holes.crossings import _crossings, _TriangleIndex
from .holes.fill import FilledHoles, FillReport, HoleFiller, HoleOutcome, fill_holes, fill_holes_arrays
from .holes.find import Hole, find_holes
from .holes.tuning import BORDER_FACING_AWAY, DENSITY_MAX, DP_MAX_EDGES

__all__ = [
    "BORDER_FACING_AWAY",
    "DENSITY_MAX",
    "DP_MAX_EDGES",
    "FillReport",
    "FilledHoles",
    "Hole",
    "HoleFiller",
    "HoleOutcome",
    "_TriangleIndex",
    "_crossings",
    "fill_holes",
    "fill_holes_arrays",
    "find_holes",
]

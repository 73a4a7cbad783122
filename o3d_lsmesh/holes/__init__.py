"""Hole filling (Liepa 2003 with least-squares-mesh fairing): find, triangulate, fair, check, fill.

See docs/algorithms/hole_filling.rst.
"""

from .fill import FilledHoles, FillReport, HoleFiller, HoleOutcome, fill_holes, fill_holes_arrays
from .find import Hole, find_holes
from .tuning import BORDER_FACING_AWAY, DENSITY_MAX, DP_MAX_EDGES

__all__ = [
    "BORDER_FACING_AWAY",
    "DENSITY_MAX",
    "DP_MAX_EDGES",
    "FillReport",
    "FilledHoles",
    "Hole",
    "HoleFiller",
    "HoleOutcome",
    "fill_holes",
    "fill_holes_arrays",
    "find_holes",
]

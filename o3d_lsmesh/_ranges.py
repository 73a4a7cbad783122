"""Moved to :mod:`o3d_lsmesh.core.arrays` (silent re-export)."""

from .core.arrays import concatenated_ranges

__all__ = ["concatenated_ranges"]

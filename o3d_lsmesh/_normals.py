"""Moved to :mod:`o3d_lsmesh.core.arrays` (silent re-export)."""

from .core.arrays import area_weighted_normals

__all__ = ["area_weighted_normals"]

"""Moved to :mod:`o3d_lsmesh.core.validate` (#36); this path re-exports it."""

from .core.validate import collapsed_triangles

__all__ = ["collapsed_triangles"]

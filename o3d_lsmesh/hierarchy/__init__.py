"""Mesh hierarchies for multiresolution fairing (Liu et al. 2001, section 4)."""

from .fast_simplification import from_fast_simplification
from .hierarchy import MeshHierarchy, build_hierarchy

__all__ = ["MeshHierarchy", "build_hierarchy", "from_fast_simplification"]

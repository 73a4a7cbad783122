"""Moved to :mod:`o3d_lsmesh.core.progress` (#36); this path re-exports it."""

from .core.progress import check_progress, decades_bar, iterate, progress_bar, stages, write

__all__ = ["check_progress", "decades_bar", "iterate", "progress_bar", "stages", "write"]

"""Moved to :mod:`o3d_lsmesh.app.demo` (silent re-export)."""

from .app.demo import METHODS, SLIVER_QUALITY, run_demo

__all__ = ["METHODS", "SLIVER_QUALITY", "run_demo"]

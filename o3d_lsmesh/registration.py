"""Moved to :mod:`o3d_lsmesh.app.registration` (silent re-export)."""

from .app.registration import METHOD_NAMES, register, registered_methods, unregister

__all__ = ["METHOD_NAMES", "register", "registered_methods", "unregister"]

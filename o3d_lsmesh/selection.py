"""Deprecated path of :mod:`o3d_lsmesh.lsmesh.selection` (0.2's layout; it goes in 0.4)."""

from ._compat import deprecated_module

__getattr__ = deprecated_module(__name__, "o3d_lsmesh.lsmesh.selection")

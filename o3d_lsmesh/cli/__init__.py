"""Deprecated path of :mod:`o3d_lsmesh.app.cli` (``python -m o3d_lsmesh.cli`` still runs the command line)."""

from .._compat import deprecated_module

__getattr__ = deprecated_module(__name__, "o3d_lsmesh.app.cli", "o3d_lsmesh.app.commands")

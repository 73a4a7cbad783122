"""Moved to :mod:`o3d_lsmesh.core.errors` (#36); this path re-exports it."""

from .core.errors import ConvergenceError, O3DLSMeshWarning, SingularSystemError

__all__ = ["ConvergenceError", "O3DLSMeshWarning", "SingularSystemError"]

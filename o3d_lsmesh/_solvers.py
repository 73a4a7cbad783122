"""Moved to :mod:`o3d_lsmesh.core.solve` (#36); this path re-exports the names still imported from it."""

from .core._iterative import aggregation_levels as _aggregation_levels
from .core._iterative import block_cg as _block_cg
from .core._iterative import preconditioner
from .core._iterative import splu_spd as _splu_spd
from .core.solve import SPDSolver, cholmod_available


def _amg_preconditioner(matrix):
    return preconditioner(matrix, "amg")


__all__ = [
    "SPDSolver",
    "_aggregation_levels",
    "_amg_preconditioner",
    "_block_cg",
    "_splu_spd",
    "cholmod_available",
]

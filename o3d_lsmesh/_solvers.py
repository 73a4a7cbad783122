"""Moved to :mod:`o3d_lsmesh.core.solve` (#36, with :mod:`~o3d_lsmesh.core._iterative` and
:mod:`~o3d_lsmesh.core.tuning`); this path re-exports the names still imported from it."""

from .core import _direct, _iterative
from .core.solve import (
    BACKENDS,
    NO_CHOLMOD_ENV,
    ORDERINGS,
    PRECONDITIONERS,
    SOLVERS,
    SPDSolver,
    _cholmod_disabled,
    check_constant_modes,
    check_finite,
    check_weight_pins_components,
    cholmod_available,
    default_memory_budget,
    estimate_factor_bytes,
    gram_matrix,
    operator_scale,
    single_threaded_blas,
    solve_spd,
    solver_backend,
)
from .core.tuning import COARSE_UNKNOWNS, DEFAULT_TOLERANCE, DENSE_UNKNOWNS, NEGLIGIBLE, STRENGTH

_Woodbury, _VCycle, _splu_spd = _direct.Woodbury, _iterative.VCycle, _iterative.splu_spd
_aggregation_levels, _block_cg = _iterative.aggregation_levels, _iterative.block_cg
_csr_parts, _sweep_blocks = _iterative.csr_parts, _iterative.sweep_blocks


def _amg_preconditioner(matrix):
    return _iterative.preconditioner(matrix, "amg")


__all__ = [
    "BACKENDS",
    "COARSE_UNKNOWNS",
    "DEFAULT_TOLERANCE",
    "DENSE_UNKNOWNS",
    "NEGLIGIBLE",
    "NO_CHOLMOD_ENV",
    "ORDERINGS",
    "PRECONDITIONERS",
    "SOLVERS",
    "STRENGTH",
    "SPDSolver",
    "_VCycle",
    "_Woodbury",
    "_aggregation_levels",
    "_amg_preconditioner",
    "_block_cg",
    "_cholmod_disabled",
    "_csr_parts",
    "_splu_spd",
    "_sweep_blocks",
    "check_constant_modes",
    "check_finite",
    "check_weight_pins_components",
    "cholmod_available",
    "default_memory_budget",
    "estimate_factor_bytes",
    "gram_matrix",
    "operator_scale",
    "single_threaded_blas",
    "solve_spd",
    "solver_backend",
]

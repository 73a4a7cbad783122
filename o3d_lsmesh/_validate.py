"""Moved to :mod:`o3d_lsmesh.core.validate` (#36); this path re-exports it."""

from .core.validate import (
    COORDINATE_LIMIT,
    MAX_ITERATIONS,
    as_bool,
    as_choice,
    as_count,
    as_indices,
    as_iterations,
    as_positions,
    as_positive_float,
    as_real_vector,
    as_triangle_array,
    as_vertex_array,
    as_weights,
    as_workers,
    mesh_arrays,
)

__all__ = [
    "COORDINATE_LIMIT",
    "MAX_ITERATIONS",
    "as_bool",
    "as_choice",
    "as_count",
    "as_indices",
    "as_iterations",
    "as_positions",
    "as_positive_float",
    "as_real_vector",
    "as_triangle_array",
    "as_vertex_array",
    "as_weights",
    "as_workers",
    "mesh_arrays",
]

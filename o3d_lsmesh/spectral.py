"""Old path of :mod:`o3d_lsmesh.lsmesh.spectral`."""

from .lsmesh.spectral import (
    SPECTRAL_MAX_VERTICES,
    combinatorial_laplacian,
    null_space_basis,
    spectral_approximation,
)

__all__ = ["SPECTRAL_MAX_VERTICES", "combinatorial_laplacian", "null_space_basis", "spectral_approximation"]

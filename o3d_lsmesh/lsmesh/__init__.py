"""Least-squares meshes (Sorkine and Cohen-Or 2004) and their uses: control-point selection, geometry
encoding with geometry-aware bases (Sorkine et al.) and the spectral baseline (Karni and Gotsman 2000)."""

from .encoding import decode_geometry, encode_geometry, iter_decode_geometry
from .lsmesh import LSMeshSolver, LSMeshSystem, check_components_constrained, ls_mesh, reconstruct_geometry
from .selection import SELECTION_METHODS, approximate, control_point_selection, select_control_points
from .spectral import spectral_approximation

__all__ = [
    "SELECTION_METHODS",
    "LSMeshSolver",
    "LSMeshSystem",
    "approximate",
    "check_components_constrained",
    "control_point_selection",
    "decode_geometry",
    "encode_geometry",
    "iter_decode_geometry",
    "ls_mesh",
    "reconstruct_geometry",
    "select_control_points",
    "spectral_approximation",
]

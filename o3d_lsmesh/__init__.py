"""o3d_lsmesh: least-squares meshes, constrained fairing and multiresolution fairing for Open3D."""

__version__ = "0.1.0"

from ._errors import O3DLSMeshWarning, SingularSystemError
from ._solvers import SPDSolver
from .laplacian import laplacian
from .lsmesh import LSMeshSolver, ls_mesh, reconstruct_geometry

__all__ = [
    "O3DLSMeshWarning",
    "SingularSystemError",
    "SPDSolver",
    "laplacian",
    "LSMeshSolver",
    "ls_mesh",
    "reconstruct_geometry",
]

"""o3d_lsmesh: least-squares meshes, constrained fairing and multiresolution fairing for Open3D.

Every public function takes an ``open3d.geometry.TriangleMesh``, an
``open3d.t.geometry.TriangleMesh`` or a ``(vertices, triangles)`` tuple and
returns a new mesh of the same kind; the input is never modified.
"""

__version__ = "0.2.0"

import os

# OpenMP threads that wait at a barrier sleep instead of spinning: libgomp spins 300k rounds by default, so
# beside other busy processes a team whose partner was descheduled burnt its time slices in every CG
# iteration (benchmarks/results/under_load.md). libgomp reads this once, when it loads (CHOLMOD's import
# below, or the compiled kernels'): a value the user set is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from .app import metrics
from .app.registration import register, unregister
from .app.render import render
from .core.errors import ConvergenceError, InputError, InputTypeError, O3DLSMeshWarning, SingularSystemError
from .core.solve import SPDSolver
from .fairing import constrained_fairing, multiresolution_fairing, smooth_boundary_curves
from .fairing.features import detect_creases
from .hierarchy import MeshHierarchy, build_hierarchy, from_fast_simplification
from .holes import FillReport, HoleFiller, HoleOutcome, fill_holes
from .laplacian import laplacian
from .lsmesh import LSMeshSolver, ls_mesh, reconstruct_geometry
from .lsmesh.encoding import decode_geometry, encode_geometry, iter_decode_geometry
from .lsmesh.selection import approximate, select_control_points
from .lsmesh.spectral import spectral_approximation
from .summary import topology_summary

__all__ = [
    "ConvergenceError",
    "FillReport",
    "HoleFiller",
    "HoleOutcome",
    "InputError",
    "InputTypeError",
    "LSMeshSolver",
    "MeshHierarchy",
    "O3DLSMeshWarning",
    "SPDSolver",
    "SingularSystemError",
    "approximate",
    "build_hierarchy",
    "constrained_fairing",
    "decode_geometry",
    "detect_creases",
    "encode_geometry",
    "fill_holes",
    "from_fast_simplification",
    "iter_decode_geometry",
    "laplacian",
    "ls_mesh",
    "metrics",
    "multiresolution_fairing",
    "reconstruct_geometry",
    "register",
    "render",
    "select_control_points",
    "smooth_boundary_curves",
    "spectral_approximation",
    "topology_summary",
    "unregister",
]

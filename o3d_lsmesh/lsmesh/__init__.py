"""Least-squares meshes (Sorkine and Cohen-Or 2004) and their uses: control-point selection (selection),
geometry encoding with geometry-aware bases (encoding) and the spectral baseline (spectral)."""

from .lsmesh import LSMeshSolver, LSMeshSystem, check_components_constrained, ls_mesh, reconstruct_geometry

__all__ = ["LSMeshSolver", "LSMeshSystem", "check_components_constrained", "ls_mesh", "reconstruct_geometry"]

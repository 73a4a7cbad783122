"""Least-squares meshes (Sorkine and Cohen-Or 2004) and their uses: control-point selection, geometry
encoding with geometry-aware bases (Sorkine et al.), and the spectral baseline (Karni and Gotsman 2000)."""

from .lsmesh import LSMeshSolver, LSMeshSystem, check_components_constrained, ls_mesh, reconstruct_geometry

__all__ = ["LSMeshSolver", "LSMeshSystem", "check_components_constrained", "ls_mesh", "reconstruct_geometry"]

"""Moved to :mod:`o3d_lsmesh.app.shapes` (silent re-export)."""

from .app.shapes import add_noise, demo_mesh, mean_edge_length, simulated_range_scan

__all__ = ["add_noise", "demo_mesh", "mean_edge_length", "simulated_range_scan"]

"""Moved to :mod:`o3d_lsmesh.app.render` (silent re-export)."""

from .app.render import MAX_PIXELS, VIRIDIS, RenderedImage, error_colors, render

__all__ = ["MAX_PIXELS", "VIRIDIS", "RenderedImage", "error_colors", "render"]

"""Moved to :mod:`o3d_lsmesh.app.render` (silent re-export)."""

from .app.render import (  # noqa: F401
    MAX_PIXELS,
    VIRIDIS,
    RenderedImage,
    _filament_worker,
    _matplotlib,
    error_colors,
    render,
)

__all__ = ["MAX_PIXELS", "VIRIDIS", "RenderedImage", "error_colors", "render"]

"""Moved to :mod:`o3d_lsmesh.core.arrays` (silent re-export)."""

from .core.arrays import dequantize, quantize

__all__ = ["dequantize", "quantize"]

"""Uniform scalar quantization of coordinates or coefficients to ``bits`` bits in a box ``[lower, upper]``."""

from __future__ import annotations

import numpy as np

__all__ = ["dequantize", "quantize"]


def quantize(values: np.ndarray, lower: np.ndarray, upper: np.ndarray, bits: int) -> np.ndarray:
    """``round((x - lower) / (upper - lower) * (2^bits - 1))`` per column, as int64 codes in ``[0, 2^bits - 1]``.

    A column of zero extent quantizes to 0.

    >>> quantize(np.array([[0.0, 5.0], [1.0, 5.0], [0.5, 5.0]]), np.array([0.0, 5.0]), np.array([1.0, 5.0]), 2)
    array([[0, 0],
           [3, 0],
           [2, 0]])
    """
    levels = (1 << bits) - 1
    extent = np.asarray(upper, dtype=np.float64) - lower
    scale = np.divide(levels, extent, out=np.zeros_like(extent), where=extent > 0)
    return np.clip(np.rint((values - lower) * scale), 0, levels).astype(np.int64)


def dequantize(codes: np.ndarray, lower: np.ndarray, upper: np.ndarray, bits: int) -> np.ndarray:
    """The values that :func:`quantize` codes stand for: ``lower + codes * (upper - lower) / (2^bits - 1)``."""
    levels = (1 << bits) - 1
    return lower + codes * ((np.asarray(upper, dtype=np.float64) - lower) / levels)

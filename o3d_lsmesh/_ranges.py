"""Concatenated integer ranges, the index arithmetic behind CSR row gathers and per-run positions."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["concatenated_ranges"]


def concatenated_ranges(starts: ArrayLike, counts: ArrayLike) -> np.ndarray:
    """``concatenate([arange(s, s + c) for s, c in zip(starts, counts)])`` as one vectorized pass.

    ``starts`` may be a scalar (every range starts there: ``0`` gives each
    element's position within its run); ``counts`` are ``>= 0``. Returns an
    ``(sum(counts),) int64`` array.

    >>> concatenated_ranges([10, 0, 5], [2, 0, 3]).tolist()
    [10, 11, 5, 6, 7]
    >>> concatenated_ranges(0, [3, 1, 2]).tolist()
    [0, 1, 2, 0, 0, 1]
    """
    counts = np.asarray(counts, dtype=np.int64)
    starts = np.broadcast_to(np.asarray(starts, dtype=np.int64), counts.shape)
    first = np.cumsum(counts) - counts  # where each range begins in the output
    return np.arange(int(counts.sum()), dtype=np.int64) + np.repeat(starts - first, counts)

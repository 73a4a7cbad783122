"""Array helpers of the core: ranges, runs and sort-and-mask grouping, gathers, quantization, normals."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "area_weighted_normals",
    "concatenated_ranges",
    "dequantize",
    "face_normals",
    "gather",
    "in_sorted",
    "mean_edge_length",
    "quantize",
    "run_heads",
]


def concatenated_ranges(starts: ArrayLike, counts: ArrayLike) -> np.ndarray:
    """``concatenate([arange(s, s + c) for s, c in zip(starts, counts)])`` in one pass, ``(sum(counts),) int64``.

    ``starts`` may be a scalar (``0`` gives each element's position within its run).

    >>> concatenated_ranges([10, 0, 5], [2, 0, 3]).tolist()
    [10, 11, 5, 6, 7]
    """
    counts = np.asarray(counts, dtype=np.int64)
    starts = np.broadcast_to(np.asarray(starts, dtype=np.int64), counts.shape)
    first = np.cumsum(counts) - counts  # where each range begins in the output
    return np.arange(int(counts.sum()), dtype=np.int64) + np.repeat(starts - first, counts)


def in_sorted(sorted_values: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``np.isin(values, sorted_values)`` for an ascending 1-D ``sorted_values``, by one binary search each
    (no sort of either), boolean of ``values``' shape.

    >>> in_sorted(np.array([2, 5, 9]), np.array([[5, 3], [9, 10]])).tolist()
    [[True, False], [True, False]]
    """
    if not len(sorted_values):
        return np.zeros(np.shape(values), dtype=bool)
    found = np.minimum(np.searchsorted(sorted_values, values), len(sorted_values) - 1)
    return sorted_values[found] == values


def mean_edge_length(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """Mean length of the triangles' edges ``(n, 3)``, ``(m, 3)`` (an interior edge counted twice).

    >>> round(mean_edge_length(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]])), 3)
    1.138
    """
    sides = vertices[triangles[:, [1, 2, 0]]] - vertices[triangles]
    return float(np.linalg.norm(sides, axis=2).mean())


def quantize(values: np.ndarray, lower: np.ndarray, upper: np.ndarray, bits: int) -> np.ndarray:
    """``round((x - lower) / (upper - lower) * (2^bits - 1))`` per column as int64 codes; zero extent gives 0.

    >>> quantize(np.array([[0.0], [1.0], [0.5]]), np.array([0.0]), np.array([1.0]), 2).ravel().tolist()
    [0, 3, 2]
    """
    levels = (1 << bits) - 1
    extent = np.asarray(upper, dtype=np.float64) - lower
    scale = np.divide(levels, extent, out=np.zeros_like(extent), where=extent > 0)
    return np.clip(np.rint((values - lower) * scale), 0, levels).astype(np.int64)


def dequantize(codes: np.ndarray, lower: np.ndarray, upper: np.ndarray, bits: int) -> np.ndarray:
    """The values that :func:`quantize` codes stand for: ``lower + codes * (upper - lower) / (2^bits - 1)``."""
    levels = (1 << bits) - 1
    return lower + codes * ((np.asarray(upper, dtype=np.float64) - lower) / levels)


def kernel_index(rows: ArrayLike, width: int) -> np.ndarray:
    """``rows`` as a C-contiguous ``(k, width)`` int32 or int64 array (their own type where it is one of the
    two), the index types the compiled kernels are built for.

    >>> kernel_index(np.array([[0, 1, 2]], dtype=np.uint16), 3).dtype
    dtype('int64')
    """
    rows = np.asarray(rows)
    index = rows.dtype if rows.dtype in (np.int32, np.int64) else np.int64
    return np.ascontiguousarray(rows, dtype=index).reshape(-1, width)


def face_normals(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit face normals ``(m, 3)`` (zero on a degenerate face) and face areas ``(m,)``.

    One compiled pass over the triangles (``_block_kernel.triangle_normals``), in float64 whatever the
    positions' dtype.

    >>> face_normals(np.eye(3), np.array([[0, 1, 2]]))[1].round(4).tolist()
    [0.866]
    """
    from .._block_kernel import triangle_normals  # compiled by the package's build: imported where used

    positions = np.ascontiguousarray(vertices, dtype=np.float64)
    normals, area, _ = triangle_normals(positions, kernel_index(triangles, 3))
    return normals, area


def area_weighted_normals(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Unnormalized vertex normals ``(n, 3)``: the sum of the cross products of each vertex's triangles.

    One compiled pass over the triangles (``_block_kernel.area_normals``).

    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> area_weighted_normals(V, np.array([[0, 1, 2]])).tolist()
    [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]]
    """
    from .._block_kernel import area_normals  # compiled by the package's build: imported where used

    return area_normals(np.ascontiguousarray(positions, dtype=np.float64), kernel_index(triangles, 3))


def _runs(sorted_keys: np.ndarray):
    """Runs of equal values in sorted ``keys``: (first-of-run mask, run starts, run lengths)."""
    first = run_heads(sorted_keys)
    starts = np.flatnonzero(first)
    return first, starts, _run_lengths(starts, len(sorted_keys))


def run_heads(values: np.ndarray) -> np.ndarray:
    """``(k,) bool``: True where ``values`` differs from the value before it (and at the first)."""
    first = np.empty(len(values), dtype=bool)
    first[:1] = True
    np.not_equal(values[1:], values[:-1], out=first[1:])
    return first


def _run_lengths(starts: np.ndarray, count: int) -> np.ndarray:
    """Lengths of the runs starting at ``starts`` in ``count`` items, in ``starts``' dtype."""
    # written in place (np.diff with append copies ``starts`` first)
    lengths = np.empty(len(starts), dtype=starts.dtype)
    np.subtract(starts[1:], starts[:-1], out=lengths[:-1])
    lengths[-1:] = count - starts[-1:]
    return lengths


#: Indices per call of :func:`gather` (numpy converts an index to intp first: a temporary this size).
_GATHER_BLOCK = 1 << 16


def gather(values: np.ndarray, index: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``values[index]`` for a 1-D in-range ``index`` of any integer dtype (into ``out`` if given).

    ``np.take(mode="wrap")`` in blocks when the index is not intp, so that numpy's intp copy of
    the index stays small.
    """
    if out is None:
        out = np.empty(np.shape(index), dtype=values.dtype)
    if index.dtype == np.intp or len(index) <= _GATHER_BLOCK:
        return np.take(values, index, out=out, mode="wrap")
    for i in range(0, len(index), _GATHER_BLOCK):
        np.take(values, index[i : i + _GATHER_BLOCK], out=out[i : i + _GATHER_BLOCK], mode="wrap")
    return out

"""Input checks shared by every public function.

Messages follow "`<param>` must <rule>, got <observed>" so that the caller can
see at once which argument is wrong and why.
"""

from __future__ import annotations

import numbers
import os
from typing import Any, Sequence

import numpy as np

__all__ = [
    "check_mesh_arrays",
    "as_indices",
    "as_positions",
    "as_weights",
    "as_count",
    "as_workers",
    "as_positive_float",
    "as_choice",
    "isolated_vertices",
]


def _describe(value: Any) -> str:
    if isinstance(value, np.ndarray):
        return f"array of shape {value.shape} and dtype {value.dtype}"
    text = repr(value)
    return text if len(text) < 60 else text[:57] + "..."


def check_mesh_arrays(
    vertices: np.ndarray,
    triangles: np.ndarray,
    *,
    name: str = "mesh",
    allow_isolated: bool = True,
) -> None:
    """Raise ``ValueError`` unless ``(vertices, triangles)`` is a usable mesh.

    Checks: at least one vertex and one triangle, finite coordinates, triangle
    indices in ``[0, n)``, no triangle repeating a vertex and, unless
    ``allow_isolated``, no vertex left unreferenced by every triangle.
    """
    n = len(vertices)
    if n == 0:
        raise ValueError(f"{name} must have vertices, got an empty mesh")
    if len(triangles) == 0:
        raise ValueError(f"{name} must have triangles, got {n} vertices and no triangles")
    finite = np.isfinite(vertices).all(axis=1)
    if not finite.all():
        bad = int(np.flatnonzero(~finite)[0])
        raise ValueError(
            f"{name} vertices must be finite, got {vertices[bad].tolist()} at vertex {bad}"
        )
    low, high = int(triangles.min()), int(triangles.max())
    if low < 0 or high >= n:
        row = int(np.flatnonzero(((triangles < 0) | (triangles >= n)).any(axis=1))[0])
        raise ValueError(
            f"{name} triangle indices must lie in [0, {n}), got {triangles[row].tolist()} "
            f"at triangle {row}"
        )
    repeated = (
        (triangles[:, 0] == triangles[:, 1])
        | (triangles[:, 1] == triangles[:, 2])
        | (triangles[:, 2] == triangles[:, 0])
    )
    if repeated.any():
        row = int(np.flatnonzero(repeated)[0])
        raise ValueError(
            f"{name} triangles must have three distinct vertices, got {triangles[row].tolist()} "
            f"at triangle {row} ({int(repeated.sum())} such triangles; "
            "remove_degenerate_triangles() drops them)"
        )
    if not allow_isolated:
        isolated = isolated_vertices(triangles, n)
        if len(isolated):
            raise ValueError(
                f"{name} must not have unreferenced vertices, got {len(isolated)} "
                f"(first: vertex {int(isolated[0])}); remove_unreferenced_vertices() drops them"
            )


def isolated_vertices(triangles: np.ndarray, n: int) -> np.ndarray:
    """Indices of the vertices that no triangle references, ``(k,) int64``."""
    used = np.zeros(n, dtype=bool)
    used[triangles.ravel()] = True
    return np.flatnonzero(~used)


def as_indices(
    indices: Any,
    n: int,
    *,
    name: str,
    allow_empty: bool = False,
) -> np.ndarray:
    """Return ``indices`` as a unique ``(k,) int64`` array of vertex indices in ``[0, n)``."""
    if isinstance(indices, (str, bytes)) or indices is None:
        raise TypeError(f"{name} must be a sequence of integer vertex indices, got {_describe(indices)}")
    try:
        array = np.asarray(indices)
    except Exception as error:  # ragged input and the like: report it as a type problem
        raise TypeError(f"{name} must be a sequence of integer vertex indices, got {_describe(indices)}") from error
    if array.ndim == 0:
        array = array.reshape(1)
    if array.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {array.shape}")
    if array.size == 0:
        if allow_empty:
            return np.zeros(0, dtype=np.int64)
        raise ValueError(f"{name} must hold at least one vertex index, got none")
    if array.dtype == bool or not np.issubdtype(array.dtype, np.integer):
        if np.issubdtype(array.dtype, np.floating) and np.all(np.isfinite(array)) and np.all(array == np.round(array)):
            raise TypeError(
                f"{name} must have an integer dtype, got {array.dtype} (cast with astype(int) if these are indices)"
            )
        raise TypeError(f"{name} must hold integer vertex indices, got dtype {array.dtype}")
    array = array.astype(np.int64)
    bad = (array < 0) | (array >= n)
    if bad.any():
        raise ValueError(
            f"{name} must lie in [0, {n}), got {int(array[bad][0])} at position {int(np.flatnonzero(bad)[0])}"
        )
    order = np.sort(array)
    dup = order[1:] == order[:-1]
    if dup.any():
        raise ValueError(f"{name} must not repeat an index, got {int(order[1:][dup][0])} more than once")
    return array


def as_positions(positions: Any, count: int, *, name: str) -> np.ndarray:
    """Return ``positions`` as a finite ``(count, 3) float64`` array (a copy)."""
    try:
        array = np.array(positions, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise TypeError(f"{name} must be an array of shape ({count}, 3), got {_describe(positions)}") from error
    if array.shape != (count, 3):
        raise ValueError(f"{name} must have shape ({count}, 3), got {array.shape}")
    finite = np.isfinite(array).all(axis=1)
    if not finite.all():
        row = int(np.flatnonzero(~finite)[0])
        raise ValueError(f"{name} must be finite, got {array[row].tolist()} at row {row}")
    return array


def as_weights(weights: Any, count: int, *, name: str = "weights") -> np.ndarray:
    """Return a scalar or per-item weight as a positive finite ``(count,) float64`` array."""
    if isinstance(weights, bool):
        raise TypeError(f"{name} must be a positive number or an array of them, got {weights!r}")
    try:
        array = np.array(weights, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise TypeError(f"{name} must be a positive number or an array of them, got {_describe(weights)}") from error
    if array.ndim == 0:
        array = np.full(count, float(array))
    if array.shape != (count,):
        raise ValueError(f"{name} must be a scalar or have shape ({count},), got {array.shape}")
    bad = ~np.isfinite(array) | (array <= 0)
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{name} must be positive and finite, got {array[row]} at position {row}")
    return array


def as_count(value: Any, *, name: str, minimum: int = 0, maximum: int | None = None) -> int:
    """Return ``value`` as a Python int in ``[minimum, maximum]``; bools and floats are rejected."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer, got {_describe(value)}")
    value = int(value)
    if value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    if maximum is not None and value > maximum:
        raise ValueError(f"{name} must be <= {maximum}, got {value}")
    return value


def as_workers(value: Any, *, name: str = "workers") -> int:
    """Return a thread count: ``None`` means every CPU this process may run on, else an int >= 1."""
    if value is None:
        try:
            return max(1, len(os.sched_getaffinity(0)))
        except AttributeError:  # not on Linux
            return max(1, os.cpu_count() or 1)
    return as_count(value, name=name, minimum=1)


def as_positive_float(value: Any, *, name: str, allow_zero: bool = False) -> float:
    """Return ``value`` as a finite float that is positive (or non-negative)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a number, got {_describe(value)}")
    value = float(value)
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        rule = "non-negative" if allow_zero else "positive"
        raise ValueError(f"{name} must be {rule} and finite, got {value}")
    return value


def as_choice(value: Any, choices: Sequence[str], *, name: str) -> str:
    """Return ``value`` if it is one of ``choices``."""
    if not isinstance(value, str):
        raise TypeError(f"{name} must be one of {list(choices)}, got {_describe(value)}")
    if value not in choices:
        raise ValueError(f"{name} must be one of {list(choices)}, got {value!r}")
    return value

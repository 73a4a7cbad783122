"""Input checks shared by every public function, and :func:`check_options` for per-method option tables.

Messages follow "`<param>` must <rule>, got <observed>"; every check raises an
:class:`~o3d_lsmesh.core.errors.InputError` (``InputTypeError`` for a wrong type) whose ``param``
names the Python parameter.
"""

from __future__ import annotations

import numbers
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal, overload

import numpy as np
import scipy.sparse as sp

from .errors import InputError, InputTypeError

__all__ = [
    "COORDINATE_LIMIT",
    "MAX_ITERATIONS",
    "Option",
    "as_bool",
    "as_choice",
    "as_count",
    "as_csc",
    "as_indices",
    "as_iterations",
    "as_positions",
    "as_positive_float",
    "as_real_vector",
    "as_triangle_array",
    "as_vertex_array",
    "as_weights",
    "as_workers",
    "check_finite",
    "check_options",
    "collapsed_triangles",
    "mesh_arrays",
]


#: Largest coordinate magnitude accepted: lengths are raised up to the sixth power (the hierarchy's
#: volume cost) and Open3D's raycasting works in float32; the algorithms are scale-free.
COORDINATE_LIMIT = 1e30

# dtype kinds of real numbers (not bool, complex, strings or objects, which a float cast would convert)
_REAL_KINDS = "iuf"


def collapsed_triangles(triangles: np.ndarray) -> np.ndarray:
    """``(m,) bool``: which rows of ``triangles (m, 3)`` repeat a vertex index.

    >>> collapsed_triangles(np.array([[0, 1, 2], [3, 3, 4], [5, 6, 5]])).tolist()
    [False, True, True]
    """
    return (
        (triangles[:, 0] == triangles[:, 1])
        | (triangles[:, 1] == triangles[:, 2])
        | (triangles[:, 2] == triangles[:, 0])
    )


def _open3d_tensor_to_numpy(value: Any) -> Any:
    """An ``open3d.core.Tensor`` as a numpy array (numpy alone sees it as one opaque object); else ``value``."""
    if (
        (type(value).__module__ or "").startswith("open3d")
        and hasattr(value, "numpy")
        and hasattr(value, "cpu")
    ):
        return value.cpu().numpy()
    return value


def _describe(value: Any) -> str:
    if isinstance(value, np.ndarray):
        return f"array of shape {value.shape} and dtype {value.dtype}"
    text = repr(value)
    return text if len(text) < 60 else text[:57] + "..."


def mesh_arrays(
    vertices: Any, triangles: Any, *, name: str = "mesh", narrow: bool = False, collapsed: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """The one check of a mesh given as arrays: new ``(n, 3) float64`` vertices and ``(m, 3) int64`` triangles.

    Every array function and ``read_mesh`` go through it: :func:`as_vertex_array`,
    :func:`as_triangle_array`, then the checks below. The results are copies (``narrow=True``: the
    triangles may be the given int32 array, for callers that only read them). ``collapsed=True`` lets
    triangles repeat a vertex (``read_mesh`` leaves them out of the computation).

    Raises
    ------
    InputTypeError
        Positions that are not real numbers, indices that are not integers.
    InputError
        A shape not ``(k, 3)``, an empty mesh, no triangles, coordinates not finite or beyond
        :data:`COORDINATE_LIMIT`, a mesh spanning less than its inverse, indices out of range, triangles
        repeating a vertex.

    Examples
    --------
    >>> v, f = mesh_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    >>> v.dtype, f.dtype, f.shape
    (dtype('float64'), dtype('int64'), (1, 3))
    """
    vertices = as_vertex_array(vertices, name=name)
    n = len(vertices)
    triangles = as_triangle_array(triangles, n, name=name, narrow=narrow)
    if n == 0:
        raise InputError(f"{name} must have vertices, got an empty mesh", param=name)
    if len(triangles) == 0:
        raise InputError(f"{name} must have triangles, got {n} vertices and no triangles", param=name)
    # two whole-array reductions (max and min carry NaN and inf) clear the usual mesh; rows are
    # looked at only to name a bad one
    smallest, largest = float(vertices.min()), float(vertices.max())
    if not (-COORDINATE_LIMIT <= smallest and largest <= COORDINATE_LIMIT):
        _check_coordinates(vertices, what=f"{name} vertices", row="vertex", param=name)
    if 0.0 < largest - smallest < 1.0 / COORDINATE_LIMIT:  # powers of its lengths would underflow
        raise InputError(
            f"{name} vertices must span at least {1 / COORDINATE_LIMIT:.0e} (cotangents, areas and the "
            f"hierarchy's costs would underflow to zero), got a mesh of extent {largest - smallest:.3g}; "
            "scale the mesh up first",
            param=name,
        )
    repeated = collapsed_triangles(triangles)
    if repeated.any() and not collapsed:
        row = int(np.flatnonzero(repeated)[0])
        raise InputError(
            f"{name} triangles must have three distinct vertices, got {triangles[row].tolist()} "
            f"at triangle {row} ({int(repeated.sum())} such triangles; "
            "remove_degenerate_triangles() drops them)",
            param=name,
        )
    return vertices, triangles


def _check_coordinates(array: np.ndarray, *, what: str, row: str, param: str, limit: bool = True) -> None:
    """Raise if a coordinate of ``array (k, 3)`` is not finite, or (``limit``) beyond :data:`COORDINATE_LIMIT`."""
    finite = np.isfinite(array).all(axis=1)
    if not finite.all():
        first = int(np.flatnonzero(~finite)[0])
        raise InputError(f"{what} must be finite, got {array[first].tolist()} at {row} {first}", param=param)
    if not limit:
        return
    big = np.abs(array).max(axis=1) > COORDINATE_LIMIT
    if big.any():
        first = int(np.flatnonzero(big)[0])
        raise InputError(
            f"{what} must have coordinates of magnitude at most {COORDINATE_LIMIT:.0e} (areas, volumes "
            f"and normal equations would overflow), got {array[first].tolist()} at {row} {first}; "
            "scale the mesh down first",
            param=param,
        )


def _array(value: Any, *, name: str, expected: str, param: str | None = None) -> np.ndarray:
    """``np.asarray(value)`` (an Open3D tensor converted first); ``TypeError`` for strings, None, ragged input."""
    if isinstance(value, (str, bytes)) or value is None:
        raise InputTypeError(f"{name} must be {expected}, got {_describe(value)}", param=param or name)
    if isinstance(value, (list, tuple)):
        value = _plain_numbers(value, name=name, expected=expected, param=param or name)
    try:
        return np.asarray(_open3d_tensor_to_numpy(value))
    except Exception as error:  # ragged input and the like: a type problem
        raise InputTypeError(
            f"{name} must be {expected}, got {_describe(value)}", param=param or name
        ) from error


def _plain_numbers(values: list | tuple, *, name: str, expected: str, param: str) -> Any:
    """A flat sequence as numpy should read it: bools among numbers refused (numpy reads ``[True, 5]`` as
    ``[1, 5]``), integers of mixed kinds as Python ints (numpy reads ``[int64, uint64]`` as floats)."""
    bools = [isinstance(v, (bool, np.bool_)) for v in values]
    if any(bools) and not all(bools):
        raise InputTypeError(f"{name} must be {expected}, got bools among numbers", param=param)
    if values and not any(bools) and all(isinstance(v, (int, np.integer)) for v in values):
        return [int(v) for v in values]
    return values


def _real_array(value: Any, *, name: str, expected: str, param: str | None = None) -> np.ndarray:
    """:func:`_array` if it holds real numbers, else ``TypeError`` (bool, complex, strings, objects)."""
    array = _array(value, name=name, expected=expected, param=param)
    if array.dtype.kind not in _REAL_KINDS:
        raise InputTypeError(
            f"{name} must be {expected} of real numbers, got dtype {array.dtype}", param=param or name
        )
    return array


def as_vertex_array(value: Any, *, name: str = "mesh") -> np.ndarray:
    """Vertex positions as a new ``(n, 3) float64`` array (integers converted exactly, never reshaped)."""
    array = _real_array(value, name=f"{name} vertices", expected="an (n, 3) array", param=name)
    if array.size == 0 and array.ndim <= 2:
        return np.zeros((0, 3))  # an empty mesh: mesh_arrays says so
    if array.ndim != 2 or array.shape[1] != 3:
        raise InputError(f"{name} vertices must have shape (n, 3), got {array.shape}", param=name)
    return np.array(array, dtype=np.float64, order="C")  # C order: the compiled kernel reads rows


def as_triangle_array(value: Any, n: int, *, name: str = "mesh", narrow: bool = False) -> np.ndarray:
    """Triangle indices as a new ``(m, 3) int64`` array, checked against ``n`` vertices before any cast
    (an empty array of any dtype means no triangles). ``narrow=True``: int32 when ``n`` fits, the given
    array itself when it is int32 in C order already (an Open3D mesh's triangles)."""
    array = _array(value, name=f"{name} triangles", expected="an (m, 3) integer array", param=name)
    if array.size == 0 and array.ndim <= 2 and (array.ndim < 2 or array.shape[1] in (0, 3)):
        return np.zeros((0, 3), dtype=np.int64)
    if array.dtype == bool or array.dtype.kind not in "iu":
        raise InputTypeError(
            f"{name} triangles must be an (m, 3) integer array, got dtype {array.dtype}", param=name
        )
    if array.ndim != 2 or array.shape[1] != 3:
        raise InputError(f"{name} triangles must have shape (m, 3), got {array.shape}", param=name)
    # compared in the given dtype (no wrap-around); the mask only to name a bad row
    if n > 0 and (array.min() < 0 or array.max() >= n):  # (no vertices: mesh_arrays says so)
        bad = (array < 0) | (array >= n)
        row = int(np.flatnonzero(bad.any(axis=1))[0])
        raise InputError(
            f"{name} triangle indices must lie in [0, {n}), got {[int(i) for i in array[row]]} at triangle {row}",
            param=name,
        )
    if narrow and n <= np.iinfo(np.int32).max:
        return np.ascontiguousarray(array, dtype=np.int32)
    return array.astype(np.int64, order="C")


@overload
def as_bool(value: Any, *, name: str, allow_none: Literal[False] = False) -> bool: ...


@overload
def as_bool(value: Any, *, name: str, allow_none: bool) -> bool | None: ...


def as_bool(value: Any, *, name: str, allow_none: bool = False) -> bool | None:
    """Return ``value`` as a bool; anything but ``True``/``False`` (or ``None`` if allowed) is a ``TypeError``."""
    if value is None and allow_none:
        return None
    if not isinstance(value, (bool, np.bool_)):
        rule = "a bool or None" if allow_none else "a bool"
        raise InputTypeError(
            f"{name} must be {rule}, got {type(value).__name__} {_describe(value)}", param=name
        )
    return bool(value)


def as_real_vector(
    value: Any, length: int, *, name: str, low: float | None = None, high: float | None = None
) -> np.ndarray:
    """Return ``value`` as a finite ``(length,) float64`` array within ``[low, high]`` (an RGB triple...)."""
    expected = f"a sequence of {length} numbers"
    array = _real_array(value, name=name, expected=expected)
    if array.shape != (length,):
        raise InputError(
            f"{name} must be {expected}, got shape {array.shape}: {_describe(value)}", param=name
        )
    array = np.array(array, dtype=np.float64)
    outside = ~np.isfinite(array)
    if low is not None:
        outside |= array < low
    if high is not None:
        outside |= array > high
    if outside.any():
        rule = "finite" if low is None and high is None else f"in [{low:g}, {high:g}]"
        raise InputError(f"{name} must have {length} entries {rule}, got {array.tolist()}", param=name)
    return array


def as_indices(indices: Any, n: int, *, name: str, allow_repeats: bool = False) -> np.ndarray:
    """Return ``indices`` as a unique ``(k,) int64`` array of vertex indices in ``[0, n)`` (repeats if allowed)."""
    array = _array(indices, name=name, expected="a sequence of integer vertex indices")
    if array.ndim == 0:
        array = array.reshape(1)
    if array.ndim != 1:
        raise InputError(f"{name} must be one-dimensional, got shape {array.shape}", param=name)
    if array.size == 0:
        raise InputError(f"{name} must hold at least one vertex index, got none", param=name)
    if array.dtype == bool or not np.issubdtype(array.dtype, np.integer):
        if (
            np.issubdtype(array.dtype, np.floating)
            and np.all(np.isfinite(array))
            and np.all(array == np.round(array))
        ):
            raise InputTypeError(
                f"{name} must have an integer dtype, got {array.dtype} (cast with astype(int) if these are indices)",
                param=name,
            )
        raise InputTypeError(f"{name} must hold integer vertex indices, got dtype {array.dtype}", param=name)
    bad = (array < 0) | (array >= n)  # in the given dtype: a uint64 index is not wrapped to -1
    if bad.any():
        raise InputError(
            f"{name} must lie in [0, {n}), got {int(array[bad][0])} at position {int(np.flatnonzero(bad)[0])}",
            param=name,
        )
    array = array.astype(np.int64)
    if allow_repeats:
        return array
    order = np.sort(array)
    dup = order[1:] == order[:-1]
    if dup.any():
        raise InputError(
            f"{name} must not repeat an index, got {int(order[1:][dup][0])} more than once", param=name
        )
    return array


def as_positions(positions: Any, count: int, *, name: str, limit: bool = False) -> np.ndarray:
    """Return ``positions`` as a finite ``(count, 3) float64`` copy; ``limit=True`` (a user's coordinates)
    also refuses coordinates beyond :data:`COORDINATE_LIMIT` (computed ones may overshoot slightly)."""
    array = _real_array(positions, name=name, expected=f"an array of shape ({count}, 3)")
    if array.shape != (count, 3):
        raise InputError(f"{name} must have shape ({count}, 3), got {array.shape}", param=name)
    array = np.array(array, dtype=np.float64)
    _check_coordinates(array, what=name, row="row", param=name, limit=limit)
    return array


def as_weights(weights: Any, count: int, *, name: str = "weights") -> np.ndarray:
    """Return a scalar or per-item weight as a positive finite ``(count,) float64`` array."""
    if isinstance(weights, (bool, np.bool_)):
        raise InputTypeError(
            f"{name} must be a positive number or an array of them, got {weights!r}", param=name
        )
    array = np.array(
        _real_array(weights, name=name, expected="a positive number or an array"), dtype=np.float64
    )
    if array.ndim == 0:
        array = np.full(count, float(array))
    if array.shape != (count,):
        raise InputError(f"{name} must be a scalar or have shape ({count},), got {array.shape}", param=name)
    bad = ~np.isfinite(array) | (array <= 0)
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise InputError(
            f"{name} must be positive and finite, got {array[row]} at position {row}", param=name
        )
    return array


def as_count(value: Any, *, name: str, minimum: int = 0, maximum: int | None = None) -> int:
    """Return ``value`` as a Python int in ``[minimum, maximum]``; bools and floats are rejected."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise InputTypeError(f"{name} must be an integer, got {_describe(value)}", param=name)
    value = int(value)
    if value < minimum:
        raise InputError(f"{name} must be >= {minimum}, got {value}", param=name)
    if maximum is not None and value > maximum:
        raise InputError(f"{name} must be <= {maximum}, got {value}", param=name)
    return value


#: Most iterations a fairing call takes (every method, boundary curves, each level of multiresolution fairing,
#: the CLI and batch): the paper's operators settle within tens; a mistyped 10**9 would run for days.
MAX_ITERATIONS = 10_000


def as_iterations(value: Any, *, name: str = "number_of_iterations") -> int:
    """Return an iteration count in ``[0, MAX_ITERATIONS]`` (:func:`as_count`), the bound named when exceeded."""
    return as_count(value, name=name, maximum=MAX_ITERATIONS)


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
        raise InputTypeError(f"{name} must be a number, got {_describe(value)}", param=name)
    value = float(value)
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        rule = "non-negative" if allow_zero else "positive"
        raise InputError(f"{name} must be {rule} and finite, got {value}", param=name)
    return value


def as_choice(value: Any, choices: Sequence[str], *, name: str) -> str:
    """Return ``value`` if it is one of ``choices``."""
    if not isinstance(value, str):
        raise InputTypeError(f"{name} must be one of {list(choices)}, got {_describe(value)}", param=name)
    if value not in choices:
        raise InputError(f"{name} must be one of {list(choices)}, got {value!r}", param=name)
    return value


@dataclass(frozen=True)
class Option:
    """One row of a per-method option table for :func:`check_options`.

    ``check(value, name=...)`` validates a given value and returns it converted (an ``as_*`` function,
    or a ``functools.partial`` of one); ``default`` stands for an option not given (or given as
    None); ``why`` says what the option is for, in the message of a method it does not apply to.
    """

    check: Callable[..., Any] | None = None
    default: Any = None
    why: str = ""


def check_options(
    table: Mapping[str, Mapping[str, Option]], method: Any, given: Mapping[str, Any], *, name: str = "method"
) -> tuple[str, dict[str, Any]]:
    """Check the options ``given`` for ``method`` against ``table`` (method -> option name -> :class:`Option`).

    An option given as None counts as not given. Returns ``(method, options)`` with every option of the
    method, checked or defaulted. Raises :class:`InputError` naming the option when it is not in the
    table at all, or not None for a method it does not apply to; ``method`` itself is
    :func:`as_choice`-checked (``param=name``).

    >>> table = {"a": {"k": Option(as_count, 1)}, "b": {}}
    >>> check_options(table, "a", {"k": None})
    ('a', {'k': 1})
    >>> check_options(table, "b", {"k": 2})
    Traceback (most recent call last):
    ...
    o3d_lsmesh.core.errors.InputError: k does not apply to method='b' (it applies to method='a'), got 2
    """
    method = as_choice(method, tuple(table), name=name)
    row = table[method]
    for key, value in given.items():
        if key in row or value is None:
            continue
        users = [other for other, options in table.items() if key in options]
        if not users:
            raise InputError(f"{key} is not an option of any {name}, got {key}={_describe(value)}", param=key)
        why = table[users[0]][key].why or "it applies to " + " or ".join(f"{name}={m!r}" for m in users)
        raise InputError(
            f"{key} does not apply to {name}={method!r} ({why}), got {_describe(value)}", param=key
        )
    options = {}
    for key, option in row.items():
        value = given.get(key)
        if value is None:
            options[key] = option.default
        else:
            options[key] = value if option.check is None else option.check(value, name=key)
    return method, options


def as_csc(matrix: Any, *, name: str = "matrix", square: bool = True) -> sp.csc_matrix:
    """``matrix`` as canonical float64 CSC with CHOLMOD's 32-bit indices where they fit (a copy if needed)."""
    if not sp.issparse(matrix):
        raise InputTypeError(f"{name} must be a scipy sparse matrix, got {type(matrix).__name__}", param=name)
    if square and matrix.shape[0] != matrix.shape[1]:
        raise InputError(f"{name} must be square, got shape {matrix.shape}", param=name)
    if matrix.dtype.kind not in "biuf":
        raise InputTypeError(f"{name} must have real entries, got {matrix.dtype}", param=name)
    csc = sp.csc_matrix(matrix, dtype=np.float64)
    if not np.isfinite(csc.data).all():
        first = int(np.flatnonzero(~np.isfinite(csc.data))[0])
        raise InputError(
            f"{name} must have finite entries, got {csc.data[first]} (an overflowing weight or a NaN input?)",
            param=name,
        )
    if not csc.has_canonical_format:
        csc = csc.copy()
        csc.sum_duplicates()
    if csc.indices.dtype != np.int32 and max(csc.nnz, *csc.shape) < np.iinfo(np.int32).max:
        # CHOLMOD's int interface: the long one would copy and store 64-bit indices
        csc = sp.csc_matrix(
            (csc.data, csc.indices.astype(np.int32), csc.indptr.astype(np.int32)), shape=csc.shape
        )
    return csc


def check_finite(values: Any, *, name: str, what: str) -> None:
    """Raise :class:`InputError` naming ``name`` when ``values`` (built from it) holds inf or NaN.

    ``values`` may be a callable, run with overflow warnings off (the overflow is what this reports).
    """
    if callable(values):
        with np.errstate(over="ignore", invalid="ignore"):
            values = values()
    finite = np.isfinite(values)
    if not finite.all():
        first = int(np.flatnonzero(~finite.ravel())[0])
        raise InputError(
            f"{name} must be small enough that {what} is finite, got {np.ravel(values)[first]} "
            f"(overflow) at entry {first}",
            param=name,
        )

"""Exception and warning classes of o3d_lsmesh, and :func:`warn`.

Every error a caller's input causes is an :class:`InputError` (a ``ValueError``) naming the Python
parameter it is about in ``param``; the command line maps it to its flag by class, never by message.
"""

from __future__ import annotations

import inspect
import os
import sys
import warnings

__all__ = [
    "ConvergenceError",
    "InputError",
    "InputTypeError",
    "O3DLSMeshWarning",
    "SingularSystemError",
    "called_from_outside",
    "warn",
]


class InputError(ValueError):
    """A bad argument: ``param`` is the Python parameter it is about (or None when none is to blame alone).

    >>> InputError("count must be >= 1, got 0", param="count").param
    'count'
    """

    def __init__(self, message: str = "", *, param: str | None = None) -> None:
        super().__init__(message)
        self.param = param


class InputTypeError(InputError, TypeError):
    """An argument of the wrong type: both an :class:`InputError` and a ``TypeError``."""


class SingularSystemError(InputError):
    """The linear system cannot be solved as posed (a component without constraint, or the factorization's)."""


class O3DLSMeshWarning(UserWarning):
    """A warning about a fallback or about data that was dropped."""


class ConvergenceError(RuntimeError):
    """An iterative solve did not reach its tolerance within its iteration limit."""


#: The package's folder (with its separator): frames of files under it are skipped by :func:`warn`.
_PACKAGE = os.path.dirname(os.path.dirname(os.path.abspath(__file__))) + os.sep


def _outside(frame: object) -> bool:
    return frame is None or not os.path.abspath(frame.f_code.co_filename).startswith(_PACKAGE)  # type: ignore[attr-defined]


def warn(message: str, category: type[Warning] = O3DLSMeshWarning) -> None:
    """``warnings.warn`` pointing at the first caller outside o3d_lsmesh, whatever the call path."""
    if sys.version_info >= (3, 12):
        warnings.warn(message, category, skip_file_prefixes=(_PACKAGE,))  # type: ignore[call-arg]
        return
    frame, level = inspect.currentframe(), 1  # this function's frame: stacklevel 1
    try:
        while not _outside(frame):
            frame, level = frame.f_back, level + 1  # type: ignore[union-attr]
    finally:
        del frame
    warnings.warn(message, category, stacklevel=level)


def called_from_outside(depth: int = 1) -> bool:
    """Whether the function ``depth`` calls above this one's caller was called from outside the package."""
    frame = inspect.currentframe()
    try:
        for _ in range(depth + 1):
            frame = frame.f_back if frame is not None else None
        return _outside(frame)
    finally:
        del frame

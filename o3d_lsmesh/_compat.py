"""Old module paths of 0.2, kept for one release: each forwards to its new home with a warning."""

from __future__ import annotations

import importlib
import warnings
from typing import Any, Callable


def deprecated_module(
    old: str, *new: str, replaced: dict[str, tuple[Any, str]] | None = None
) -> Callable[[str], Any]:
    """Return a module ``__getattr__`` that forwards ``old.name`` to the first of ``new`` holding it, warning.

    Parameters
    ----------
    old : str
        The deprecated module's path (its ``__name__``).
    *new : str
        The modules its names moved to, searched in order.
    replaced : dict, optional
        Names with no counterpart of that name: ``{name: (object, "what to use instead")}``.

    Examples
    --------
    >>> import warnings
    >>> forward = deprecated_module("old.place", "math")
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     forward("pi") > 3, caught[0].category.__name__
    (True, 'DeprecationWarning')
    """

    def __getattr__(name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        if replaced and name in replaced:
            value, instead = replaced[name]
        else:
            for path in new:
                module = importlib.import_module(path)
                if hasattr(module, name):
                    value, instead = getattr(module, name), f"{path}.{name}"
                    break
            else:
                raise AttributeError(
                    f"module {old!r} has no attribute {name!r} (it moved to {', '.join(new)})"
                )
        warnings.warn(
            f"{old}.{name} is deprecated: use {instead} ({old} goes in 0.4)", DeprecationWarning, stacklevel=2
        )
        return value

    return __getattr__

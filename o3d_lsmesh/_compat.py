"""Old module paths of 0.2, kept for one release: each forwards to its new home with a warning."""

from __future__ import annotations

import importlib
import warnings
from typing import Any, Callable


def deprecated_module(old: str, new: str) -> Callable[[str], Any]:
    """Return a module ``__getattr__`` that forwards ``old.name`` to ``new.name`` with a warning.

    Parameters
    ----------
    old, new : str
        Dotted module paths: the deprecated one (usually ``__name__``) and its replacement.

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
        value = getattr(importlib.import_module(new), name)  # AttributeError names the new module
        warnings.warn(
            f"{old}.{name} moved to {new}.{name}; import it from there ({old} goes in 0.4)",
            DeprecationWarning,
            stacklevel=2,
        )
        return value

    return __getattr__

"""Progress bars of every long operation (``progress=True`` in the API): the package's only tqdm import.

:class:`Progress` makes every bar (work units, a loop, named stages, an iterative solve's decades);
each ends at its total when the work completes. :func:`close_all` ends the open ones (the command line
does before it prints an error). With ``progress=False`` tqdm is not even imported.
"""

from __future__ import annotations

import contextlib
import math
import sys
import weakref
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any, TypeVar

from .validate import as_bool

__all__ = ["Progress", "close_all"]

T = TypeVar("T")

#: The bars made by :class:`Progress` and not yet garbage (closed ones included: closing twice is harmless).
_OPEN: weakref.WeakSet[Any] = weakref.WeakSet()


def close_all() -> None:
    """Close every open bar (each ends its line), so that a message printed next starts on its own line."""
    for bar in list(_OPEN):
        with contextlib.suppress(Exception):
            bar.close()


class _Silent:
    """Stand-in for a disabled bar: tqdm's methods (``update``, ``set_postfix_str``, ``close``...), doing nothing."""

    n = 0

    def __getattr__(self, name: str) -> Callable[..., None]:
        return lambda *args, **kwargs: None

    def __enter__(self) -> _Silent:
        return self

    def __exit__(self, *exc: object) -> None:
        pass


class _Decades:
    """:meth:`Progress.decades`' bar: ``reached(to_go)`` sets it to the decades fallen since the start."""

    def __init__(self, bar: Any, to_go: float) -> None:
        self.bar, self.start = bar, to_go

    def reached(self, to_go: float, postfix: str = "") -> None:
        fallen = math.log10(self.start / to_go) if to_go > 0 else math.inf
        self.bar.update(min(self.bar.total, max(0, math.floor(fallen))) - self.bar.n)
        self.bar.set_postfix_str(postfix, refresh=False)

    def finish(self) -> None:
        self.bar.update(self.bar.total - self.bar.n)

    def close(self) -> None:
        self.bar.close()

    def __enter__(self) -> _Decades:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Progress:
    """The bars of one operation named ``desc``, shown when ``enabled`` (a bool, checked) is True.

    >>> progress = Progress(False, "levels")
    >>> list(progress.over(range(3)))
    [0, 1, 2]
    """

    def __init__(self, enabled: Any, desc: str) -> None:
        self.enabled, self.desc = as_bool(enabled, name="progress"), desc

    @staticmethod
    def write(text: str) -> None:
        """Print one line on stderr above any open bar (a plain print would land in the bar's line)."""
        from tqdm.auto import tqdm

        tqdm.write(text, file=sys.stderr)

    def _tqdm(self, *args: Any, **options: Any) -> Any:
        from tqdm.auto import tqdm

        bar = tqdm(*args, desc=self.desc, **options)
        _OPEN.add(bar)
        return bar

    def bar(self, total: int, **options: Any) -> Any:
        """A bar over ``total`` units (a silent stand-in when disabled); a context manager, or ``close()`` it.

        ``options`` go to tqdm: ``unit``; ``initial`` (work done before the bar starts, so that it still
        ends at ``total``); ``file`` (default stderr); ``leave=False`` to erase it when it closes.
        """
        return self._tqdm(total=int(total), **options) if self.enabled else _Silent()

    def over(self, items: Iterable[T]) -> Iterator[T]:
        """``items`` with a bar that advances as each is taken, over ``len(items)`` when they have one."""
        return iter(self._tqdm(items) if self.enabled else items)

    @contextlib.contextmanager
    def stages(self, names: Sequence[str]) -> Iterator[Callable[[str], None]]:
        """A bar over the named stages of one operation; yields ``begin(name)``, called as each starts.

        ``begin`` completes the previous stage; a normal exit completes the last (the bar ends at
        ``len(names)``), an error leaves the bar where it happened.
        """
        bar = self.bar(len(names), unit="stage")
        started = 0

        def begin(name: str) -> None:
            nonlocal started
            if started:
                bar.update(1)
            started += 1
            bar.set_postfix_str(name)

        try:
            yield begin
            if started:
                bar.update(1)
        finally:
            bar.close()

    def decades(self, to_go: float) -> Any:
        """A bar over the decades an iterative solve's residual has to fall, ``to_go`` times in all.

        The iterations a solve takes are not known before it ends, the residual's way to its target is.
        ``reached(to_go, postfix)`` with what is left moves it, ``finish()`` completes it at convergence.
        """
        if not self.enabled:
            return _Silent()
        decades = max(1, math.ceil(math.log10(to_go))) if math.isfinite(to_go) and to_go > 1 else 1
        return _Decades(self.bar(decades, unit="decade"), to_go)

"""The one tqdm gateway: progress bars of every long operation (``progress=True`` in the API).

:func:`progress_bar` counts work the caller reports; :func:`iterate` wraps a
loop; :func:`stages` names the steps of one operation.

Every bar ends at its total when the work completes (tests check it) and counts units of the
work (vertices, anchors) or named stages. With ``progress=False`` tqdm is not even imported.
"""

from __future__ import annotations

import contextlib
import math
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence, Sized
from typing import Any, TypeVar

from ._validate import as_bool

__all__ = ["check_progress", "decades_bar", "iterate", "progress_bar", "stages"]

T = TypeVar("T")


def check_progress(progress: Any) -> bool:
    """``progress`` as a bool; ``TypeError`` naming ``progress`` for anything else (1, "yes", None)."""
    return bool(as_bool(progress, name="progress"))


class _Silent:
    """Stand-in for a disabled bar: tqdm's methods (``update``, ``set_postfix_str``, ``close``...), doing nothing."""

    n = 0

    def __getattr__(self, name: str) -> Callable[..., None]:
        return lambda *args, **kwargs: None

    def __enter__(self) -> _Silent:
        return self

    def __exit__(self, *exc: object) -> None:
        pass


def progress_bar(progress: Any, *, total: int, desc: str, **options: Any) -> Any:
    """A tqdm bar over ``total`` units (a silent stand-in when ``progress`` is False).

    ``options`` go to tqdm: ``unit``; ``initial``, the work done before the bar
    starts (the per-component seeds of a selection, the files a resumed batch
    already did), so that the bar still ends at ``total``; ``file`` (default
    stderr); ``leave=False`` to erase it when it closes (an inner bar). Use as
    a context manager, or call ``close()``.

    >>> with progress_bar(False, total=3, desc="work") as bar:
    ...     bar.update(3)
    """
    if not check_progress(progress):
        return _Silent()
    from tqdm.auto import tqdm

    return tqdm(total=int(total), desc=desc, **options)


class _Decades:
    """:func:`decades_bar`'s bar: ``reached(to_go)`` sets it to the decades fallen since the start."""

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


def decades_bar(progress: Any, *, to_go: float, desc: str) -> Any:
    """A bar over the decades (factors of ten) an iterative solve's residual has to fall, ``to_go`` times
    in all (its start over its target): the iterations a solve takes are not known before it ends (an
    iteration cap as the total would show ``3/5000`` and an ETA of minutes for a one-second solve),
    the residual's way to its target is. ``reached(to_go)`` with what is left moves it, ``finish()``
    completes it at convergence; the ETA follows the decades' pace.

    >>> with decades_bar(False, to_go=1e6, desc="solve") as bar:
    ...     bar.reached(1e3, "residual=1e-3")
    ...     bar.finish()
    """
    if not check_progress(progress):
        return _Silent()
    decades = max(1, math.ceil(math.log10(to_go))) if math.isfinite(to_go) and to_go > 1 else 1
    return _Decades(progress_bar(True, total=decades, desc=desc, unit="decade"), to_go)


def iterate(
    progress: Any, items: Iterable[T], *, desc: str, unit: str = "it", total: int | None = None
) -> Iterator[T]:
    """``items`` with a tqdm bar that advances as each is taken (``items`` itself when ``progress`` is False).

    ``total`` defaults to ``len(items)`` when it has one, so the bar ends at its total.

    >>> list(iterate(False, range(3), desc="levels"))
    [0, 1, 2]
    """
    if not check_progress(progress):
        return iter(items)
    from tqdm.auto import tqdm

    if total is None and isinstance(items, Sized):
        total = len(items)
    return iter(tqdm(items, total=total, desc=desc, unit=unit))


def write(text: str) -> None:
    """Print one line on stderr above any open bar (a plain print would land in the bar's line)."""
    from tqdm.auto import tqdm

    tqdm.write(text, file=sys.stderr)


@contextlib.contextmanager
def stages(progress: Any, desc: str, names: Sequence[str]) -> Iterator[Callable[[str], None]]:
    """A bar over the named stages of one operation (e.g. factor, solve).

    Yields ``begin(name)``: call it as each stage starts; it completes the
    previous stage and shows ``name``. On a normal exit the last stage is
    completed, so the bar ends at ``len(names)``; after an error it stays where
    the error happened.

    >>> with stages(False, "ls_mesh", ("factor", "solve")) as begin:
    ...     begin("factor")
    ...     begin("solve")
    """
    bar = progress_bar(progress, total=len(names), desc=desc, unit="stage")
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

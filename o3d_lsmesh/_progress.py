"""The one tqdm gateway: progress bars of every long operation (``progress=True`` in the API).

:func:`progress_bar` counts work the caller reports; :func:`iterate` wraps a
loop; :func:`stages` names the steps of one operation.

Every bar ends at its total when the work completes (tests check it) and counts units of the
work (vertices, anchors) or named stages. With ``progress=False`` tqdm is not even imported.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence, Sized
from typing import Any, TypeVar

from ._validate import as_bool

__all__ = ["check_progress", "iterate", "progress_bar", "stages"]

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

"""Progress reporting for the loops a user waits for (frames, cameras, iterations, passes,
planes, sweep points), through one argument that library functions accept.

``progress`` may be

- ``None`` or ``False``: silent (the default of library functions);
- ``True``: a tqdm bar on stderr when it is a terminal, unless progress is switched off globally
  (:func:`set_quiet`, the CLI's ``--quiet``, or ``MITPIV_QUIET=1``, which the test suite sets);
- a callable ``progress(done, total, desc)``: called after each step (``total`` may be None).

Library code never prints: messages go through :mod:`logging` (logger names under
``mitpiv``), bars through :func:`track` / :func:`bar`. tqdm is the kept library that draws
the bars; this module only routes the argument.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Iterator
from typing import TypeVar

__all__ = ["Progress", "track", "bar", "set_quiet", "quiet", "ProgressBar"]

T = TypeVar("T")
Progress = bool | Callable[[int, int | None, str], None] | None

_quiet: bool | None = None


def set_quiet(value: bool = True) -> None:
    """Switch every ``progress=True`` bar off (``True``) or back on (``False``)."""
    global _quiet
    _quiet = bool(value)


def quiet() -> bool:
    """Whether bars are switched off globally (:func:`set_quiet` or ``MITPIV_QUIET=1``)."""
    if _quiet is not None:
        return _quiet
    return os.environ.get("MITPIV_QUIET", "").strip().lower() not in ("", "0", "false", "no")


class ProgressBar:
    """A progress reporter with ``update(n=1)``, ``set_description(text)`` and ``close()``,
    usable as a context manager; silent, a tqdm bar, or a callback (see the module notes)."""

    def __init__(self, total: int | None = None, *, desc: str = "", progress: Progress = None, unit: str = "it"):
        self.total, self.desc, self.done = total, desc, 0
        self._callback = progress if callable(progress) else None
        self._bar = None
        if progress is True and not quiet():
            from tqdm.auto import tqdm

            # disable=None: no bar when stderr is not a terminal (a log file gets no \r noise)
            self._bar = tqdm(total=total, desc=desc, unit=unit, leave=False, dynamic_ncols=True, disable=None)

    def update(self, n: int = 1) -> None:
        self.done += n
        if self._bar is not None:
            self._bar.update(n)
        if self._callback is not None:
            self._callback(self.done, self.total, self.desc)

    def set_description(self, desc: str) -> None:
        self.desc = desc
        if self._bar is not None:
            self._bar.set_description(desc)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def bar(total: int | None = None, *, desc: str = "", progress: Progress = None, unit: str = "it") -> ProgressBar:
    """A :class:`ProgressBar` for loops that are not a simple iteration."""
    return ProgressBar(total, desc=desc, progress=progress, unit=unit)


def track(iterable: Iterable[T], *, total: int | None = None, desc: str = "", progress: Progress = None,
          unit: str = "it") -> Iterator[T]:
    """Iterate over ``iterable``, reporting one step per item (see the module notes)."""
    if total is None and hasattr(iterable, "__len__"):
        total = len(iterable)  # type: ignore[arg-type]
    with ProgressBar(total, desc=desc, progress=progress, unit=unit) as b:
        for item in iterable:
            yield item
            b.update()

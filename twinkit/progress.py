"""Progress on a terminal, plain quiet output elsewhere.

On a terminal the engine shows one live line per running step (spinner, name, elapsed time);
bars from ``ctx.progress(...)`` inside the step join the same display. Off a terminal (CI, logs,
pipes) nothing is drawn.
"""
from __future__ import annotations

import contextlib
import sys
from typing import Iterable, Iterator, TypeVar

T = TypeVar("T")

_ACTIVE = None  # the rich Progress of the running step, when on a terminal


def is_interactive() -> bool:
    return sys.stderr.isatty()


def _new_progress(transient: bool = True):
    from rich.console import Console
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TextColumn,
                               TimeElapsedColumn, TimeRemainingColumn)

    return Progress(SpinnerColumn(), TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                    TimeElapsedColumn(), TimeRemainingColumn(), transient=transient,
                    console=Console(file=sys.stderr))


@contextlib.contextmanager
def step_status(description: str):
    """A live line for a running step (terminal only)."""
    global _ACTIVE
    if not is_interactive() or _ACTIVE is not None:
        yield
        return
    progress = _new_progress()
    progress.add_task(description, total=None)
    _ACTIVE = progress
    try:
        with progress:
            yield
    finally:
        _ACTIVE = None


def track(iterable: Iterable[T], total: int | None = None, desc: str = "") -> Iterator[T]:
    """Yield from ``iterable``; draw a progress bar only when stderr is a terminal."""
    if not is_interactive():
        yield from iterable
        return
    if total is None:
        try:
            total = len(iterable)  # type: ignore[arg-type]
        except TypeError:
            total = None
    if _ACTIVE is not None:
        task = _ACTIVE.add_task(desc, total=total)
        try:
            for item in iterable:
                yield item
                _ACTIVE.advance(task)
        finally:
            _ACTIVE.remove_task(task)
        return
    with _new_progress() as bar:
        task = bar.add_task(desc, total=total)
        for item in iterable:
            yield item
            bar.advance(task)

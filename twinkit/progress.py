"""Progress bars on a terminal, plain quiet output elsewhere."""
from __future__ import annotations

import sys
from typing import Iterable, Iterator, TypeVar

T = TypeVar("T")


def is_interactive() -> bool:
    return sys.stderr.isatty()


def track(iterable: Iterable[T], total: int | None = None, desc: str = "") -> Iterator[T]:
    """Yield from ``iterable``; draw a rich progress bar only when stderr is a terminal."""
    if not is_interactive():
        yield from iterable
        return
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    if total is None:
        try:
            total = len(iterable)  # type: ignore[arg-type]
        except TypeError:
            total = None
    with Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        transient=True,
    ) as bar:
        task = bar.add_task(desc, total=total)
        for item in iterable:
            yield item
            bar.advance(task)

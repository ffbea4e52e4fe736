"""Executors run the items of a fanned-out step. The engine only calls ``map(fn, items)``.

``LocalExecutor`` uses worker processes on this machine (started with 'spawn', so
libraries that start threads, such as open3d, are safe). Other executors (Dask,
Ray) are plugins of kind ``executor`` that provide the same ``map``.
"""
from __future__ import annotations

import multiprocessing as mp
from concurrent.futures import ProcessPoolExecutor
from typing import Any, Callable, Iterator


class LocalExecutor:
    """Run items in up to ``workers`` local processes (in this process when ``workers <= 1``)."""

    def __init__(self, workers: int = 2):
        self.workers = max(1, int(workers))

    def map(self, fn: Callable[[Any], Any], items: list[Any]) -> Iterator[Any]:
        if self.workers <= 1 or len(items) <= 1:
            for it in items:
                yield fn(it)
            return
        with ProcessPoolExecutor(max_workers=min(self.workers, len(items)), mp_context=mp.get_context("spawn")) as pool:
            yield from pool.map(fn, items)

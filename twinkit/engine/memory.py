"""Memory of a step: its peak resident memory while it runs, and handing freed memory back between items."""
from __future__ import annotations

import os
import threading


class _PeakRSS:
    """Samples this process's resident memory while a step runs (Linux /proc)."""

    def __init__(self, interval: float = 0.05):
        self.interval = interval
        self.peak = self.start = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def _rss(self) -> int:
        try:
            with open("/proc/self/statm") as f:
                return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
        except OSError:
            return 0

    def _loop(self):
        while not self._stop.is_set():
            self.peak = max(self.peak, self._rss())
            self._stop.wait(self.interval)

    def __enter__(self):
        self.peak = self.start = self._rss()
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, self._rss())


def release_memory() -> None:
    """Hand freed heap memory back to the system after an item, so that a pooled worker does not
    carry one item's peak into the next (glibc keeps freed arenas otherwise; measured on the large
    demo site: workers started later tiles at 2.9-3.3 GB). A no-op where there is no glibc."""
    import ctypes
    import gc

    gc.collect()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass

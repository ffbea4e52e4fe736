"""Time and peak resident memory of a block of code (sampled from a background thread)."""
from __future__ import annotations

import threading
import time


def _rss_bytes() -> int:
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * 4096
    except OSError:  # not Linux
        import psutil

        return int(psutil.Process().memory_info().rss)


class Measure:
    """``with Measure() as m: ...`` then ``m.seconds``, ``m.peak_rss_mb`` (absolute peak during the block)
    and ``m.delta_peak_mb`` (peak minus the resident size at entry)."""

    def __init__(self, interval_s: float = 0.02):
        self.interval_s = interval_s
        self.seconds = 0.0
        self.peak = 0
        self.start_rss = 0
        self._stop = threading.Event()

    def _run(self) -> None:
        while not self._stop.is_set():
            r = _rss_bytes()
            if r > self.peak:
                self.peak = r
            self._stop.wait(self.interval_s)

    def __enter__(self) -> "Measure":
        self.start_rss = _rss_bytes()
        self.peak = self.start_rss
        self._t0 = time.perf_counter()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, _rss_bytes())
        self.seconds = time.perf_counter() - self._t0

    @property
    def peak_rss_mb(self) -> float:
        return self.peak / 2**20

    @property
    def delta_peak_mb(self) -> float:
        return (self.peak - self.start_rss) / 2**20

    def as_dict(self) -> dict:
        return {"seconds": round(self.seconds, 3), "peak_rss_mb": round(self.peak_rss_mb, 1),
                "delta_peak_mb": round(self.delta_peak_mb, 1)}

"""Hydra callback: when a multirun ends, gather its jobs into one summary (table + plot)."""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback

log = logging.getLogger("twinkit")


class SweepSummary(Callback):
    """Writes ``<sweep dir>/summary.md`` (and what the report module adds) after ``twinkit -m ...``."""

    def on_multirun_end(self, config: Any, **kwargs: Any) -> None:
        sweep_dir = Path(str(config.hydra.sweep.dir))
        try:
            from twinkit.report import write_sweep_summary
        except ImportError:
            return
        try:
            path = write_sweep_summary(sweep_dir)
        except Exception as exc:  # a summary must never turn a finished sweep into a failure
            log.warning("twinkit: could not write the sweep summary for %s: %s", sweep_dir, exc)
            return
        if path is not None:
            print(f"twinkit: sweep summary file://{Path(path).resolve()}")

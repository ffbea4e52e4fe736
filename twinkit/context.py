"""The object every step receives as ``ctx``."""
from __future__ import annotations

import logging
import os
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping, TypeVar

T = TypeVar("T")


@dataclass
class StepContext:
    """What a running step may know and use.

    Attributes:
        step_id: the recipe step's id (``"reconstruct"``).
        workdir: temporary folder of this run of the step; the engine moves it into
            place only when the step returns and every declared output exists.
        site: the site's configuration as a plain dict (``name``, ``crs``, ``base_point``, ...).
        config: the whole composed configuration as a plain dict.
        threads: how many CPU threads the step may use.
        log: a logger named after the step.
    """

    step_id: str
    workdir: Path
    site: Mapping[str, Any] = field(default_factory=dict)
    config: Mapping[str, Any] = field(default_factory=dict)
    threads: int = field(default_factory=lambda: os.cpu_count() or 1)
    log: logging.Logger = field(default_factory=lambda: logging.getLogger("twinkit.step"))
    _component_factory: Callable[[str, str | None], Any] | None = None
    _executor_factory: Callable[[], Any] | None = None
    _degraded: list = field(default_factory=list)
    _gates: list = field(default_factory=list)
    _notes: list = field(default_factory=list)
    _substeps: dict = field(default_factory=dict)
    _substep_stack: list = field(default_factory=list)
    _t0: float = field(default_factory=time.perf_counter)

    def gate(self, name: str, value: float | None, threshold: float, op: str = ">=", unit: str = "",
             why: str = "", hint: str | None = None, reason: str | None = None) -> bool:
        """Declare one quality gate of this step's result: the figure ``value`` must be ``op`` (``>=``, ``>``,
        ``<=``, ``<``) ``threshold``; True when it passes (a figure of None, nothing to measure, passes).

        ``name`` names the figure ("continuity driving"), ``unit`` its unit ("%", "m"), ``why`` what the
        threshold protects ("a wheel drops into a hole"). Every gate is stored in the step's metrics under
        ``gates`` and logged, passed or not; one that fails calls :meth:`degraded` with ``reason`` (default: the
        figure against its threshold and ``why``) and ``hint`` (the setting to try).
        """
        from twinkit.quality import gate_entry, gate_text

        entry = gate_entry(name, value, threshold, op, unit, why)
        self._gates.append(entry)
        if entry["ok"]:
            self.log.debug("gate %s", gate_text(entry))  # the step's progress line prints every gate
        else:
            self.degraded(f"{reason} (gate {gate_text(entry)})" if reason else
                          gate_text(entry) + (f": {why}" if why else ""), hint)
        return bool(entry["ok"])

    def note(self, text: str) -> None:
        """A fact about the twin the run's status names beside "ok" or "degraded" ("no road network")."""
        if text not in self._notes:
            self._notes.append(str(text))
        self.log.debug("note: %s", text)

    def degraded(self, reason: str, hint: str | None = None) -> None:
        """Say that this step's result is degenerate (far less than it should be): the run ends "degraded".

        ``reason`` says what was achieved against what was expected ("the mesh covers 5 m² of a 900 m² walk");
        ``hint`` says what to look at or which setting to try ("try reconstructor.max_dist_m=0.6"). The step still returns its outputs; later steps still run. The
        run's manifest, report and ``twinkit status`` show the reasons in red, and the command exits with 4
        (``engine.degraded_exit_code``). The reasons are stored with the result, so a cached step stays degraded.
        """
        entry = {"step": self.step_id, "reason": str(reason)}
        if hint:
            entry["hint"] = str(hint)
        self._degraded.append(entry)
        self.log.warning("DEGRADED: %s%s", reason, f" ({hint})" if hint else "")

    @contextmanager
    def substep(self, name: str) -> Iterator[None]:
        """Time one part of the step: ``with ctx.substep("poisson"): ...``. The engine stores each part's wall
        seconds and peak resident memory (MB, and above the memory at its start) in the step's metrics under
        ``substeps`` (step.json, the manifest); the report's timeline and ``twinkit profile`` show them.

        A name used twice adds up (seconds summed, peaks the highest, ``calls`` counted); a substep inside another
        is named ``outer/inner``. Time outside every substep is shown as the step's ``(other)``.
        """
        from twinkit.surface.measure import Measure

        full = "/".join([*self._substep_stack, str(name)])
        self._substep_stack.append(str(name))
        m = Measure()
        start = time.perf_counter() - self._t0
        try:
            with m:
                yield
        finally:
            self._substep_stack.pop()
            self._substeps[full] = add_substep(self._substeps.get(full), {**m.as_dict(), "start_s": round(start, 3)})

    @property
    def substeps(self) -> dict[str, dict]:
        """The substeps measured so far: name -> ``{"seconds", "peak_rss_mb", "delta_peak_mb", "start_s"[, "calls"]}``
        (``start_s``: when its first call began, seconds after the step's context was made)."""
        return {k: dict(v) for k, v in self._substeps.items()}

    @property
    def degraded_reasons(self) -> list[dict]:
        """What ``degraded`` was told so far (tests read it)."""
        return list(self._degraded)

    def progress(self, iterable: Iterable[T], total: int | None = None, desc: str | None = None) -> Iterator[T]:
        """Iterate with a progress bar on a terminal; plain and quiet otherwise."""
        from twinkit.progress import track

        return track(iterable, total=total, desc=desc or self.step_id)

    def component(self, kind: str, name: str | None = None) -> Any:
        """Build the component plugin of ``kind`` selected in the config (or ``name``) with its params."""
        if self._component_factory is None:
            from twinkit.plugins import build_component

            return build_component(kind, name, dict(self.config))
        return self._component_factory(kind, name)

    def map(self, fn: Callable[..., T], items: list[Any]) -> list[T]:
        """Run ``fn(item)`` for every item on the configured executor; results in order."""
        if self._executor_factory is None:
            from twinkit.executors import LocalExecutor

            ex = LocalExecutor(workers=self.threads)
        else:
            ex = self._executor_factory()
        return list(ex.map(fn, items))


def add_substep(old: dict | None, new: dict) -> dict:
    """Two records of one substep name added up (a second call, or a fan-out step's items): seconds summed, peaks
    the highest, calls counted."""
    if not old:
        return dict(new)
    return {"seconds": round(old.get("seconds", 0.0) + new.get("seconds", 0.0), 3),
            "peak_rss_mb": max(old.get("peak_rss_mb", 0.0), new.get("peak_rss_mb", 0.0)),
            "delta_peak_mb": max(old.get("delta_peak_mb", 0.0), new.get("delta_peak_mb", 0.0)),
            "start_s": min(old.get("start_s", 0.0), new.get("start_s", 0.0)),
            "calls": int(old.get("calls", 1)) + int(new.get("calls", 1))}


def with_substeps(metrics: dict, substeps: Mapping[str, dict]) -> dict:
    """``metrics`` with the substeps a step measured through :meth:`StepContext.substep` under ``substeps``
    (beside any the step returned there itself)."""
    if not substeps:
        return metrics
    return {**metrics, "substeps": {**(metrics.get("substeps") or {}), **substeps}}

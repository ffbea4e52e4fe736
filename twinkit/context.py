"""The object every step receives as ``ctx``."""
from __future__ import annotations

import logging
import os
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

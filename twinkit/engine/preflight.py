"""Preflight: the checks that fail cheaply, run for every planned step before the first step runs.

The engine checks that every site input file a step reads exists and is readable; each plugin may add
its own checks (``register(..., preflight=fn)``, see twinkit/hookspecs.py): ``fn(site, params, inputs)``
returns its problems, one line each. Every problem of every step is collected and reported together,
one line each (a single problem: that line alone), as an :class:`twinkit.InputError` (exit 2), before a
long step has run. A preflight
that crashes is a bug of its plugin: it is logged and the run goes on (the step's own checks remain).
"""
from __future__ import annotations

import logging
import os
import time
from pathlib import Path

from twinkit.engine.keys import missing_input
from twinkit.errors import InputError, TwinkitError

log = logging.getLogger("twinkit.preflight")


def site_input_problems(plan) -> list[str]:
    """Site input files of the planned steps that are missing or unreadable, one line each (the same
    words as when the step itself meets them: twinkit/engine/keys.py, twinkit/os_errors.py)."""
    out: list[str] = []
    seen: set[Path] = set()
    for ps in plan:
        for src in ps.inputs.values():
            if src is None or src.path is None or src.path in seen:
                continue
            seen.add(src.path)
            if not src.path.exists():
                out.append(missing_input(src.path, ps.id))
            elif not os.access(src.path, os.R_OK) or (src.path.is_dir() and not os.access(src.path, os.X_OK)):
                out.append(f"{src.path}: permission denied; make it readable by this user (site input of step "
                           f"'{ps.id}')")
    return out


def run_preflight(plan, cfg: dict) -> list[str]:
    """Run the preflight of every planned step; raise InputError listing every problem (exit 2)."""
    t0 = time.perf_counter()
    site = cfg.get("site") or {}
    problems = site_input_problems(plan)
    bad_inputs = {p for p in problems}
    for ps in plan:
        fn = getattr(ps.plugin, "preflight", None) if ps.plugin is not None else None
        if fn is None:
            continue
        # every wired input: the site file's path, or None when an earlier step writes it (not there yet)
        inputs = {param: src.path for param, src in ps.inputs.items() if src is not None}
        try:
            found = fn(site, ps.params, inputs) or []
        except TwinkitError as exc:
            found = [str(exc)]
        except Exception as exc:  # noqa: BLE001 -- a plugin's bug must not stop a run its step may handle
            log.warning("preflight of step '%s' (%s) failed: %s: %s; going on", ps.id, ps.label,
                        type(exc).__name__, exc)
            continue
        problems += [f"step '{ps.id}' ({ps.label}): {p}" for p in found if p not in bad_inputs]
    log.debug("preflight: %d steps checked in %.2f s", len(plan), time.perf_counter() - t0)
    if len(problems) == 1:
        raise InputError(problems[0])  # one line, as when the step itself meets it
    if problems:
        raise InputError(f"preflight found {len(problems)} problems before the first step ran:\n  "
                         + "\n  ".join(problems))
    return problems

"""Helpers for plugin authors' tests (also a pytest plugin: fixtures ``twinkit_context``).

    from twinkit.testing import make_context, run_step, run_plugin, check_plugin

``run_step`` runs one step-like plugin through the same code path as the engine
(temporary folder, declared outputs checked, atomic move) without a recipe.
``run_plugin`` does the same for an installed plugin named by kind and name (the registry),
so a package never imports another plugin's modules to use it. ``shared_plugin_run`` runs one
expensive fixture (the small demo site) once for every test session of a ``make test`` run;
``bench_check`` marks a slow end-to-end test that ``make bench`` runs instead of ``make test``.
"""
from __future__ import annotations

import contextlib
import dataclasses
import fcntl
import hashlib
import inspect
import json
import logging
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from twinkit.context import StepContext


def make_context(workdir: Path, site: dict | None = None, config: dict | None = None, step_id: str = "test") -> StepContext:
    """A real StepContext writing into ``workdir``."""
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    return StepContext(
        step_id=step_id,
        workdir=workdir,
        site=dict(site or {"name": "test"}),
        config=dict(config or {}),
        log=logging.getLogger(f"twinkit.step.{step_id}"),
    )


def plugin_from_module(module, kind: str, name: str):
    """Register just ``module`` (no installed entry points) and return its plugin ``kind/name``."""
    from twinkit.plugins import load_registry

    return load_registry(extra=[(getattr(module, "__name__", "module"), module)], entry_points=False).get(kind, name)


def check_plugin(plugin) -> None:
    """Contract checks every plugin must pass (raises AssertionError with the reason)."""
    from twinkit.signature import parse_signature
    from twinkit.plugins import STEP_KINDS

    assert plugin.name and plugin.version, f"{plugin.qualname}: needs a name and a version"
    if plugin.params is not None:
        assert isinstance(plugin.params, type) and dataclasses.is_dataclass(plugin.params), \
            f"{plugin.qualname}: params must be a dataclass"
        obj = plugin.params()  # every parameter must have a default
        for f in dataclasses.fields(obj):
            assert f.type is not None, f"{plugin.qualname}: parameter {f.name} needs a type"
    if plugin.kind in STEP_KINDS:
        sig = parse_signature(plugin.run)
        assert sig.outputs, f"{plugin.qualname}: a step must declare at least one out_<name> parameter"
    else:
        params = list(inspect.signature(plugin.run).parameters)
        assert len(params) >= 1, f"{plugin.qualname}: a component's run(params) takes its params"


def run_step(plugin, workdir: Path, inputs: dict[str, Path] | None = None, params: Any = None,
             site: dict | None = None, config: dict | None = None) -> dict[str, Path]:
    """Run a step-like plugin once; returns {artefact file name: path} of its outputs."""
    from twinkit.engine import execute_plugin

    return execute_plugin(plugin, Path(workdir), inputs or {}, params, site=site, config=config)


def installed_plugin(kind: str, name: str):
    """The installed plugin ``kind/name``, looked up in the registry as a recipe would (``uses: kind/name``).

    Raises :class:`twinkit.PluginError` when no installed package provides it; tests that need
    another package's plugin call :func:`need_plugin` instead, which skips.
    """
    from twinkit.plugins import get_registry

    return get_registry().get(kind, name)


def need_plugin(kind: str, name: str):
    """:func:`installed_plugin`, or skip the calling test when no installed package provides it."""
    from twinkit.errors import PluginError

    try:
        return installed_plugin(kind, name)
    except PluginError as exc:
        pytest.skip(f"plugin {kind}/{name} is not installed ({exc})")


def run_plugin(kind: str, name: str, workdir: Path, inputs: dict[str, Path] | None = None, params: Any = None,
               *, site: dict | None = None, config: dict | None = None, **overrides: Any) -> dict[str, Path]:
    """Run the installed plugin ``kind/name`` once, found through the registry, never by importing its package.

    This is how a plugin's tests and benches use another plugin (the demo site generator, a
    reconstructor, ...): ``run_plugin("site_generator", "demo_intersection", tmp, size="small")``.
    ``params`` is the plugin's params object (default: its defaults); keyword ``overrides`` replace
    single fields of it. Runs like :func:`run_step` (the engine's code path); returns
    {artefact file name: path} of its outputs.
    """
    plugin = installed_plugin(kind, name)
    if overrides:
        params = dataclasses.replace(params if params is not None else plugin.default_params(), **overrides)
    return run_step(plugin, workdir, inputs, params, site=site, config=config)


#: the folder, shared by every test session of one ``make test`` run, where :func:`shared_plugin_run` keeps
#: its results (scripts/run_tests.py makes a fresh one for each run and removes it at the end)
CACHE_ENV = "TWINKIT_TEST_CACHE"


def shared_plugin_run(kind: str, name: str, workdir: Path, *, site: dict | None = None,
                      **overrides: Any) -> dict[str, Path]:
    """:func:`run_plugin` of a plugin without inputs (a site generator), computed once per test run.

    With ``$TWINKIT_TEST_CACHE`` set (``make test`` sets it), the result lives in
    ``$TWINKIT_TEST_CACHE/<kind>-<name>-<key>/result``, the key covering the plugin's version and code, its
    parameters and ``site``: the first caller (of any session) computes it under a file lock, the others
    wait for it and get the same files, made read-only (a test must not write into them). Without the
    variable it is :func:`run_plugin` into ``workdir``. Returns {artefact file name: path}.
    """
    root = os.environ.get(CACHE_ENV)
    if not root:
        return run_plugin(kind, name, workdir, site=site, **overrides)
    from twinkit.signature import parse_signature

    plugin = installed_plugin(kind, name)
    params = dataclasses.replace(plugin.default_params(), **overrides) if overrides else plugin.default_params()
    text = json.dumps([plugin.qualname, plugin.version, plugin.code_hash(), dataclasses.asdict(params) if params
                       else None, site], sort_keys=True, default=str)
    folder = Path(root) / f"{kind}-{name}-{hashlib.sha256(text.encode()).hexdigest()[:16]}"
    done = folder / "done.json"
    Path(root).mkdir(parents=True, exist_ok=True)
    with open(f"{folder}.lock", "w") as lock, contextlib.ExitStack() as stack:
        fcntl.flock(lock, fcntl.LOCK_EX)
        stack.callback(fcntl.flock, lock, fcntl.LOCK_UN)
        if not done.exists():
            run_plugin(kind, name, folder, site=site, params=params)
            for f in (folder / "result").rglob("*"):
                if f.is_file():
                    f.chmod(f.stat().st_mode & ~0o222)
            done.write_text(text)
    return {p.filename: folder / "result" / p.filename for p in parse_signature(plugin.run).outputs}


#: set by ``make bench`` (bench/bench_slow_tests.py) for the slow end-to-end tests it runs
BENCH_ENV = "TWINKIT_BENCH_CHECKS"


def bench_check() -> pytest.MarkDecorator:
    """Marks a slow end-to-end test that ``make bench`` runs (bench/bench_slow_tests.py lists it) and
    ``make test`` skips, saying where it runs; a fast test of the same behaviour stays in the suite."""
    return pytest.mark.skipif(not os.environ.get(BENCH_ENV),
                              reason="slow end-to-end check: make bench runs it (bench/bench_slow_tests.py)")


@pytest.fixture
def twinkit_context(tmp_path) -> StepContext:
    """A StepContext writing into a temporary folder."""
    return make_context(tmp_path / "step")


# --------------------------------------------------------------------------- a single spinning sweep, ray-cast

SWEEP_SENSOR = np.array([3.0, -2.0, 1.8])
SWEEP_TOP_DEG = 2.0
#: the sweep's scene: flat ground, a building front at x = 18 m taller than the top beam reaches, and a low wall
#: along y = -8 m between x = 4 and 12 m, 1.2 m high (its top seen)
SWEEP_FACADE_X, SWEEP_FACADE_TOP = 18.0, 12.0
SWEEP_WALL_Y, SWEEP_WALL_TOP, SWEEP_WALL_X = -8.0, 1.2, (4.0, 12.0)


def spinning_sweep(sensor=SWEEP_SENSOR, top_deg: float = SWEEP_TOP_DEG, beams: int = 64, az_step_deg: float = 0.12,
                   seed: int = 0, platform: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(points (n, 3), part (n,)) of one sweep of a spinning multi-beam sensor (beams from -24.8 degrees up to
    ``top_deg``, 1 cm range noise) over the scene above; part: 0 ground, 1 facade, 2 wall. With ``platform``
    also the returns of the car carrying the sensor (part 3): its bonnet's front edge 2.3 m ahead and its
    mirrors 1.1 m to either side, 1 m above the road, 32 points (a real sweep has 30-45 such)."""
    sensor = np.asarray(sensor, float)
    rng = np.random.default_rng(seed)
    el = np.radians(np.linspace(-24.8, top_deg, beams))
    az = np.radians(np.arange(0.0, 360.0, az_step_deg))
    e, a = np.meshgrid(el, az, indexing="ij")
    d = np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], axis=-1).reshape(-1, 3)
    t = np.full(len(d), np.inf)
    part = np.full(len(d), -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        hits = [(-sensor[2] / d[:, 2], 0, lambda p: np.ones(len(p), bool)),
                ((SWEEP_FACADE_X - sensor[0]) / d[:, 0], 1,
                 lambda p: (p[:, 2] <= SWEEP_FACADE_TOP) & (np.abs(p[:, 1]) < 40)),
                ((SWEEP_WALL_Y - sensor[1]) / d[:, 1], 2,
                 lambda p: (p[:, 2] <= SWEEP_WALL_TOP) & (p[:, 0] > SWEEP_WALL_X[0]) & (p[:, 0] < SWEEP_WALL_X[1]))]
        for tt, k, inside in hits:
            p = sensor + tt[:, None] * d
            ok = np.isfinite(tt) & (tt > 0.5) & (tt < 80.0) & (tt < t) & inside(p) & (p[:, 2] >= -1e-6)
            t[ok], part[ok] = tt[ok], k
    keep = np.isfinite(t)
    pts = sensor + (t[keep] + rng.normal(0, 0.01, keep.sum()))[:, None] * d[keep]
    if not platform:
        return pts, part[keep]
    car = np.vstack([sensor + [2.3, 0.0, -0.8] + rng.normal(0, [0.05, 0.4, 0.03], (12, 3)),
                     sensor + [0.4, 1.1, -0.7] + rng.normal(0, 0.04, (10, 3)),
                     sensor + [0.4, -1.1, -0.7] + rng.normal(0, 0.04, (10, 3))])
    return np.vstack([pts, car]), np.r_[part[keep], np.full(len(car), 3)]

"""Helpers for plugin authors' tests (also a pytest plugin: fixtures ``twinkit_context``).

    from twinkit.testing import make_context, run_step, run_plugin, check_plugin

``run_step`` runs one step-like plugin through the same code path as the engine
(temporary folder, declared outputs checked, atomic move) without a recipe.
``run_plugin`` does the same for an installed plugin named by kind and name (the registry),
so a package never imports another plugin's modules to use it.
"""
from __future__ import annotations

import dataclasses
import inspect
import logging
from pathlib import Path
from typing import Any

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


@pytest.fixture
def twinkit_context(tmp_path) -> StepContext:
    """A StepContext writing into a temporary folder."""
    return make_context(tmp_path / "step")

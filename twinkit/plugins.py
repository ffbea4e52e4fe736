"""Plugin manager: loads entry points of group ``twinkit`` and keeps the registry.

Environment variable ``TWINKIT_PLUGINS`` selects which entry points load:
unset = all; empty = none; ``a,b`` = only those entry-point names.
``TWINKIT_PLUGIN_MODULES=pkg.mod,other.mod`` also loads plain modules as plugins
(handy while developing a plugin before packaging it).
"""
from __future__ import annotations

import dataclasses
import functools
import hashlib
import importlib.metadata as md
import inspect
import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import pluggy

from twinkit import hookspecs
from twinkit.errors import ConfigError, PluginError

ENTRY_POINT_GROUP = "twinkit"

#: kind -> hook name. Step-like kinds can be bound to recipe steps.
KINDS: dict[str, str] = {
    "site_generator": "twinkit_register_site_generators",
    "reconstructor": "twinkit_register_reconstructors",
    "segmenter": "twinkit_register_segmenters",
    "view_sampler": "twinkit_register_view_samplers",
    "image_model": "twinkit_register_image_models",
    "road_source": "twinkit_register_road_sources",
    "exporter": "twinkit_register_exporters",
    "step": "twinkit_register_steps",
    "executor": "twinkit_register_executors",
}
#: report sections are not a plugin kind (no recipe can bind one): plugins add them to the run report
#: through this hook, into ``Registry.report_sections`` (see twinkit.report and docs/report.md).
REPORT_SECTIONS_HOOK = "twinkit_register_report_sections"
STEP_KINDS = ("site_generator", "reconstructor", "segmenter", "road_source", "exporter", "step")
COMPONENT_KINDS = ("view_sampler", "image_model", "executor")


@functools.lru_cache(maxsize=256)
def _file_digest(path: str, mtime_ns: int) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


#: Core modules whose code shapes what steps write: the shared library that plugins build on (site frame,
#: mesh I/O and operations, surface algorithms, the CityScapes classes). A plugin's code hash covers those
#: it imports; the framework's own modules (engine, CLI, report) do not change results and are left out.
SHARED_LIBRARY: tuple[str, ...] = ("cityscapes", "geo", "mesh", "street", "surface")
_CORE = Path(__file__).resolve().parent
_TWINKIT_IMPORT = re.compile(r"^[ \t]*(?:from[ \t]+twinkit((?:\.\w+)*)[ \t]+import[ \t]+\(?([\w \t,]+)"
                             r"|import[ \t]+twinkit\.(\w+))", re.M)


def _report_only(f: Path, root: Path) -> bool:
    """Whether ``f`` is a plugin's report code (``<pkg>/report.py`` or ``<pkg>/report/...``) or its preflight
    checks (``<pkg>/preflight.py``), which show or check and never change results, so it is left out of the
    code hash."""
    rel = f.relative_to(root).parts
    return rel[0] in ("report.py", "report", "preflight.py")


def _shared_root(name: str) -> list[Path]:
    """The files of one shared-library module (a package's every ``.py`` file, or the one module file)."""
    pkg = _CORE / name
    if pkg.is_dir():
        return sorted(pkg.rglob("*.py"))
    f = _CORE / f"{name}.py"
    return [f] if f.is_file() else []


def _shared_names(text: str) -> set[str]:
    """Names of :data:`SHARED_LIBRARY` modules that source ``text`` imports (``from twinkit.mesh import x``,
    ``from twinkit import geo``, ``import twinkit.surface.cleanup``; also inside functions)."""
    found = set()
    for dotted, names, plain in _TWINKIT_IMPORT.findall(text):
        if plain:
            found.add(plain)
        elif dotted:
            found.add(dotted.split(".")[1])
        else:
            found.update(n.strip() for n in names.replace("\t", " ").split(","))
    return found & set(SHARED_LIBRARY)


#: suffixes of the data files inside a plugin's package that its code hash covers (models, weights, tables)
DATA_SUFFIXES = frozenset({".json", ".npz", ".npy", ".onnx", ".pt", ".pth", ".tflite", ".yaml", ".yml", ".csv"})


def shared_sources(files: list[Path]) -> list[Path]:
    """The shared-library files that ``files`` use, followed through the library's own imports; sorted."""
    seen: set[str] = set()
    todo = [f for f in files]
    out: set[Path] = set()
    while todo:
        f = todo.pop()
        try:
            text = f.read_text(encoding="utf-8", errors="replace")
        except OSError:
            continue
        for name in _shared_names(text) - seen:
            seen.add(name)
            for g in _shared_root(name):
                out.add(g)
                todo.append(g)
    return sorted(out)


@dataclass
class Plugin:
    """One registered plugin."""

    kind: str
    name: str
    run: Callable[..., Any]
    params: type | None
    version: str
    description: str = ""
    uses: tuple[str, ...] = ()
    distribution: str = "?"
    module: str = ""
    #: ``preflight(site, params, inputs) -> list[str]``: the plugin's cheap checks (``inputs``: every wired
    #: input, a site file's path or None for an earlier step's file), run for every planned step
    #: before the first step runs (twinkit/engine/preflight.py); each string is one problem, one line
    preflight: Callable[..., Any] | None = None
    #: another plugin of the same kind to use instead when this one, chosen by the recipe's default (not
    #: on the command line), cannot serve the site: its inputs cannot be wired or its preflight finds a
    #: problem (``road_source=file`` without an OSM file that covers the site -> ``road_source=scan``)
    fallback: str | None = None

    @property
    def qualname(self) -> str:
        return f"{self.kind}/{self.name}"

    def default_params(self) -> Any:
        return self.params() if self.params is not None else None

    def code_hash(self) -> str:
        """sha256 of the plugin's source: every ``.py`` file of the top-level package that defines
        ``run`` (a change in a helper module of the plugin re-runs its steps too), or the one
        source file when ``run`` lives in a plain module; plus the modules of the core's shared library
        (:data:`SHARED_LIBRARY`) that this code imports, directly or through each other, so a change in
        the shared clean-up, mesh I/O or site frame re-runs the steps that use it, and only those.
        The data files the package ships beside its code (:data:`DATA_SUFFIXES`: a trained model, calibrated
        weights) count as code: a retrained model re-runs the steps that use it.
        A plugin's report sections (its ``report.py`` module or ``report/`` package) only show results,
        so editing them re-runs nothing."""
        try:
            src = Path(inspect.getsourcefile(self.run) or "")
            top = sys.modules.get(getattr(self.run, "__module__", "").split(".")[0])
            roots = list(getattr(top, "__path__", []) or [])
            files = sorted(f for f in Path(roots[0]).rglob("*") if "__pycache__" not in f.parts) if roots else []
            own = [f for f in files if f.suffix == ".py" and not _report_only(f, Path(roots[0]))] if roots else [src]
            data = [f for f in files if f.suffix in DATA_SUFFIXES and f.is_file()]
            base = Path(roots[0]) if roots else src.parent
            h = hashlib.sha256()
            for f in sorted(own + data):
                h.update(f.relative_to(base).as_posix().encode() + b"\0")
                h.update(_file_digest(str(f), f.stat().st_mtime_ns).encode())
            for f in shared_sources(own):
                h.update(b"twinkit/" + f.relative_to(_CORE).as_posix().encode() + b"\0")
                h.update(_file_digest(str(f), f.stat().st_mtime_ns).encode())
            return h.hexdigest()[:16]
        except (OSError, TypeError, ValueError):
            return "unknown"


@dataclass
class ReportSection:
    """One section (or one part of a section) of the run report: ``render(ctx) -> str | None``."""

    name: str
    render: Callable[..., Any]
    title: str = ""
    order: float = 500.0
    distribution: str = "?"
    module: str = ""


@dataclass
class Registry:
    plugins: dict[str, dict[str, Plugin]] = field(default_factory=lambda: {k: {} for k in KINDS})
    report_sections: list[ReportSection] = field(default_factory=list)
    sources: list[tuple[str, str, str]] = field(default_factory=list)  # (entry point, distribution, version)

    def get(self, kind: str, name: str) -> Plugin:
        if kind not in self.plugins:
            raise PluginError(f"unknown plugin kind '{kind}'; kinds are: {', '.join(KINDS)}")
        try:
            return self.plugins[kind][name]
        except KeyError:
            have = ", ".join(sorted(self.plugins[kind])) or "none loaded"
            raise PluginError(
                f"no {kind} plugin named '{name}' (available: {have}); "
                f"install the package that provides it or check TWINKIT_PLUGINS"
            ) from None

    def all(self) -> list[Plugin]:
        return [p for kind in KINDS for p in sorted(self.plugins[kind].values(), key=lambda p: p.name)]


def _make_register(registry: Registry, kind: str, dist: str, dist_version: str, module: str):
    def register(
        name: str,
        run: Callable[..., Any],
        params: type | None = None,
        version: str | None = None,
        description: str = "",
        uses: tuple[str, ...] | list[str] = (),
        preflight: Callable[..., Any] | None = None,
        fallback: str | None = None,
    ) -> None:
        if fallback is not None and (not isinstance(fallback, str) or fallback == name):
            raise PluginError(f"{dist}: {kind} plugin '{name}': fallback must name another {kind} plugin")
        if preflight is not None and not callable(preflight):
            raise PluginError(f"{dist}: {kind} plugin '{name}' registered a non-callable preflight")
        if not isinstance(name, str) or not name.replace("_", "").replace("-", "").isalnum():
            raise PluginError(f"{dist}: plugin name {name!r} must be letters, digits, '_' or '-'")
        if not callable(run):
            raise PluginError(f"{dist}: {kind} plugin '{name}' registered a non-callable run")
        if params is not None and not dataclasses.is_dataclass(params):
            raise PluginError(f"{dist}: {kind} plugin '{name}': params must be a dataclass, got {params!r}")
        for u in uses:
            if u not in COMPONENT_KINDS:
                raise PluginError(f"{dist}: {kind} plugin '{name}': uses={u!r} is not a component kind {COMPONENT_KINDS}")
        existing = registry.plugins[kind].get(name)
        if existing is not None:
            raise PluginError(
                f"{kind} plugin '{name}' is registered twice: by {existing.distribution} "
                f"({existing.module}) and by {dist} ({module}); uninstall one or rename it"
            )
        registry.plugins[kind][name] = Plugin(
            kind=kind,
            name=name,
            run=run,
            params=params,
            version=version or dist_version,
            description=description or (inspect.getdoc(run) or "").split("\n")[0],
            uses=tuple(uses),
            distribution=dist,
            module=getattr(run, "__module__", module),
            preflight=preflight,
            fallback=fallback,
        )

    return register


def _make_section_register(registry: Registry, dist: str, module: str):
    def register(name: str, render: Callable[..., Any], title: str = "", order: float = 500.0) -> None:
        if not isinstance(name, str) or not name.replace("_", "").replace("-", "").isalnum():
            raise PluginError(f"{dist}: report section name {name!r} must be letters, digits, '_' or '-'")
        if not callable(render):
            raise PluginError(f"{dist}: report section '{name}' registered a non-callable render")
        if any(s.name == name and s.distribution == dist for s in registry.report_sections):
            raise PluginError(f"report section '{name}' is registered twice by {dist} ({module})")
        registry.report_sections.append(ReportSection(
            name=name, render=render, title=title, order=float(order), distribution=dist,
            module=getattr(render, "__module__", module)))

    return register


def make_plugin_manager() -> pluggy.PluginManager:
    pm = pluggy.PluginManager("twinkit")
    pm.add_hookspecs(hookspecs)
    return pm


def _selected(ep_name: str) -> bool:
    sel = os.environ.get("TWINKIT_PLUGINS")
    if sel is None:
        return True
    return ep_name in {s.strip() for s in sel.split(",") if s.strip()}


def load_registry(extra: list[tuple[str, object]] | None = None, entry_points: bool = True) -> Registry:
    """Load every selected entry point of group ``twinkit`` (plus ``extra`` (name, module) pairs).

    ``entry_points=False`` loads only ``extra`` (a plugin's own tests use this).
    """
    pm = make_plugin_manager()
    registry = Registry()
    modules: list[tuple[str, str, str, object]] = []
    for ep in sorted(md.entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        if not entry_points or not _selected(ep.name):
            continue
        try:
            mod = ep.load()
        except Exception as exc:  # a broken third-party plugin must say who it is
            dist = ep.dist.name if ep.dist else "?"
            raise PluginError(f"could not load twinkit plugin '{ep.name}' from {dist}: {exc!r}") from exc
        dist_name = ep.dist.name if ep.dist else "?"
        dist_version = ep.dist.version if ep.dist else "0"
        modules.append((ep.name, dist_name, dist_version, mod))
    import importlib

    env_modules = os.environ.get("TWINKIT_PLUGIN_MODULES", "") if entry_points else ""
    for modname in [m.strip() for m in env_modules.split(",") if m.strip()]:
        try:
            modules.append((modname, modname, "0", importlib.import_module(modname)))
        except ImportError as exc:
            raise PluginError(f"TWINKIT_PLUGIN_MODULES names '{modname}', which does not import: {exc}") from exc
    for name, mod in extra or []:
        modules.append((name, name, "0", mod))
    for ep_name, dist_name, dist_version, mod in modules:
        try:
            pm.register(mod, name=ep_name)
        except ValueError as exc:
            raise PluginError(f"plugin '{ep_name}' ({dist_name}) is registered twice: {exc}") from exc
        registry.sources.append((ep_name, dist_name, dist_version))
    try:
        pm.check_pending()
    except pluggy.PluginValidationError as exc:
        raise PluginError(f"a plugin implements a hook that does not exist (misspelled?): {exc}") from exc
    for kind, hook_name in [*KINDS.items(), ("report_section", REPORT_SECTIONS_HOOK)]:
        hook = getattr(pm.hook, hook_name)
        for impl in hook.get_hookimpls():
            plugin_obj = impl.plugin
            ep_name = pm.get_name(plugin_obj) or "?"
            dist_name, dist_version = next(
                ((d, v) for (e, d, v) in registry.sources if e == ep_name), (ep_name, "0")
            )
            module = getattr(plugin_obj, "__name__", ep_name)
            if hook_name == REPORT_SECTIONS_HOOK:
                register = _make_section_register(registry, dist_name, module)
            else:
                register = _make_register(registry, kind, dist_name, dist_version, module)
            impl.function(register=register)
    return registry


_REGISTRY: Registry | None = None


def get_registry(reload: bool = False) -> Registry:
    global _REGISTRY
    if _REGISTRY is None or reload:
        _REGISTRY = load_registry()
    return _REGISTRY


def build_component(kind: str, name: str | None, config: dict) -> Any:
    """Instantiate a component plugin with its params from ``config[kind]`` (or defaults)."""
    from omegaconf import OmegaConf

    reg = get_registry()
    node = dict(config.get(kind) or {})
    chosen = name or node.get("plugin")
    if not chosen:
        raise ConfigError(f"no {kind} selected: add '{kind}=<name>' (available: {', '.join(sorted(reg.plugins[kind]))})")
    plugin = reg.get(kind, chosen)
    params = None
    if plugin.params is not None:
        values = {k: v for k, v in node.items() if k != "plugin"} if node.get("plugin") == chosen else {}
        params = OmegaConf.to_object(OmegaConf.merge(OmegaConf.structured(plugin.params), values))
    return plugin.run(params)

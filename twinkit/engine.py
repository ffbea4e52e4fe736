"""The step engine: plan a recipe, decide per step whether to run, reuse or keep an edit, and run it.

Layout of a site's outputs (``outputs/<site>/``)::

    01_site/ 02_read_cloud/ ...     one numbered folder per step: the files people open and edit,
                                    plus step.json (what made them, with hashes)
    runs/<run id>/manifest.json     provenance of each run (and run.log)
    .cache/steps/<key>/             results stored by cache key, shared by all runs and multirun jobs
    .cache/hashes.sqlite            stat -> sha256 cache, so unchanged files are never re-read
    .cache/edits/                   hand edits set aside when their step had to re-run

A step's cache key hashes its plugin (kind, name, version, code), its resolved
parameters, the configuration of the components it uses, and the content hashes
of its inputs. Outputs are written in a temporary folder and moved into the store
only when the step returned and every declared output exists; the numbered
folder is then swapped in atomically.
"""
from __future__ import annotations

import dataclasses
import datetime as _dt
import hashlib
import json
import logging
import os
import shutil
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from twinkit.context import StepContext
from twinkit.errors import ConfigError, InputError, LockedError, ManualActionPending, StepError, TwinkitError
from twinkit.hashing import HashCache, artefact_hash, list_files
from twinkit.jsonio import write_json as write_json_atomic
from twinkit.plugins import STEP_KINDS, Plugin, Registry
from twinkit.signature import Port, Signature, parse_signature

log = logging.getLogger("twinkit")

RECORD = "step.json"
RECORD_SCHEMA = 1
_STEP_SPEC_KEYS = {"id", "uses", "params", "inputs", "foreach", "manual", "description", "optional"}


# --------------------------------------------------------------------------- planning


@dataclass
class StepSpec:
    """One entry of a recipe's ``steps`` list."""

    id: str
    uses: str | None = None
    params: dict = field(default_factory=dict)
    inputs: dict = field(default_factory=dict)
    foreach: str | None = None
    manual: dict | None = None
    description: str = ""
    optional: bool = False  # skip the step (with a logged reason) when a required input is unavailable


@dataclass
class Source:
    """Where an input comes from: an earlier step's output, or a site input file."""

    filename: str
    step_index: int | None = None  # producer's index in the plan
    path: Path | None = None  # site input


@dataclass
class PlannedStep:
    index: int
    spec: StepSpec
    plugin: Plugin | None
    params: Any
    params_dict: dict
    signature: Signature
    inputs: dict[str, Source | None]
    outputs: tuple[Port, ...]
    components: dict[str, Any]
    foreach: Source | None = None

    @property
    def id(self) -> str:
        return self.spec.id

    @property
    def folder(self) -> str:
        return f"{self.index:02d}_{self.spec.id}"

    @property
    def label(self) -> str:
        return self.plugin.qualname if self.plugin else "manual"


def _params_to_dict(obj: Any) -> dict:
    if obj is None:
        return {}
    return json.loads(json.dumps(dataclasses.asdict(obj), default=str))


def _plain_ok(value: Any, tp: Any) -> tuple[bool, Any]:
    """Check (and lightly convert) a value against a simple annotation; (False, None) when unsure."""
    import types
    import typing

    if tp is Any:
        return True, value
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None:
            return (type(None) in args), None
        for a in args:
            if a is not type(None):
                ok, v = _plain_ok(value, a)
                if ok:
                    return True, v
        return False, None
    if tp is bool:
        return isinstance(value, bool), value
    if tp is int:
        return isinstance(value, int) and not isinstance(value, bool), value
    if tp is float:
        return (isinstance(value, (int, float)) and not isinstance(value, bool)), float(value) if isinstance(value, (int, float)) else None
    if tp is str:
        return isinstance(value, str), value
    if origin in (list, typing.List) or tp is list:
        args = typing.get_args(tp)
        if not isinstance(value, list):
            return False, None
        if not args:
            return True, list(value)
        out = []
        for x in value:
            ok, v = _plain_ok(x, args[0])
            if not ok:
                return False, None
            out.append(v)
        return True, out
    return False, None


def _fast_params(cls: type, merged: dict) -> Any | None:
    """Build the params dataclass directly when every value has a plain type; None to use OmegaConf."""
    import typing

    try:
        hints = typing.get_type_hints(cls)
    except Exception:
        return None
    values = {}
    for k, v in merged.items():
        ok, conv = _plain_ok(v, hints.get(k, Any))
        if not ok:
            return None
        values[k] = conv
    try:
        return cls(**values)
    except Exception:
        return None


def resolve_params(plugin: Plugin, *layers: dict, where: str) -> tuple[Any, dict]:
    """Merge parameter layers over the plugin's dataclass defaults; unknown keys and wrong types fail clearly."""
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    if plugin.params is None:
        extra = {k for layer in layers for k in (layer or {}) if k != "plugin"}
        if extra:
            raise ConfigError(f"{where}: plugin {plugin.qualname} takes no parameters, got {sorted(extra)}")
        return None, {}
    fields = [f.name for f in dataclasses.fields(plugin.params)]
    merged: dict = {}
    for layer in layers:
        for k, v in dict(layer or {}).items():
            if k == "plugin":
                continue
            if k not in fields:
                raise ConfigError(
                    f"{where}: plugin {plugin.qualname} has no parameter '{k}' (parameters: {', '.join(fields)})"
                )
            merged[k] = v
    fast = _fast_params(plugin.params, merged)
    if fast is not None:
        return fast, _params_to_dict(fast)
    base = OmegaConf.structured(plugin.params)
    for layer in layers:
        if not layer:
            continue
        layer = {k: v for k, v in dict(layer).items() if k != "plugin"}
        for k in layer:
            if k not in fields:
                raise ConfigError(
                    f"{where}: plugin {plugin.qualname} has no parameter '{k}' (parameters: {', '.join(fields)})"
                )
        try:
            base = OmegaConf.merge(base, layer)
        except OmegaConfBaseException as exc:
            raise ConfigError(f"{where}: plugin {plugin.qualname}: {exc.msg if hasattr(exc, 'msg') else exc}") from None
    obj = OmegaConf.to_object(base)
    return obj, _params_to_dict(obj)


def _spec_from(raw: Any, recipe_name: str, i: int) -> StepSpec:
    if isinstance(raw, str):
        raw = {"id": raw.split("/")[-1], "uses": raw}
    if not isinstance(raw, dict) or "id" not in raw:
        raise ConfigError(f"recipe '{recipe_name}': step #{i + 1} must be a mapping with an 'id' (got {raw!r})")
    unknown = set(raw) - _STEP_SPEC_KEYS
    if unknown:
        raise ConfigError(
            f"recipe '{recipe_name}', step '{raw['id']}': unknown key(s) {sorted(unknown)}; "
            f"allowed: {sorted(_STEP_SPEC_KEYS)}"
        )
    spec = StepSpec(**{k: v for k, v in raw.items()})
    spec.params = dict(spec.params or {})
    spec.inputs = dict(spec.inputs or {})
    if not spec.id.replace("_", "").isalnum():
        raise ConfigError(f"recipe '{recipe_name}': step id {spec.id!r} must be letters, digits and '_'")
    if (spec.uses is None) == (spec.manual is None):
        raise ConfigError(f"recipe '{recipe_name}', step '{spec.id}': give exactly one of 'uses' or 'manual'")
    return spec


def _site_inputs(site: dict) -> dict[str, Any]:
    return dict(site.get("inputs") or {})


#: key of the composed config holding the step parameters given on the command line (see ``given_params``)
GIVEN_KEY = "command_line_params"


def given_params(cfg: dict, overrides: list[str]) -> dict:
    """The step parameters among the command-line ``overrides`` (``steps.<name>.<param>=...`` and
    ``<kind>.<param>=...``), with their composed values: ``{"steps": {name: {param: v}}, kind: {param: v}}``.

    Every parameter is already in the composed config (the plugins' defaults fill it), so a value there
    cannot tell a default from a choice; this keeps the choices, which then override a recipe's fixed
    ``params:``, as a user who types ``reconstructor.depth=11`` expects."""
    out: dict = {}
    for ov in overrides:
        if "=" not in ov or ov.startswith("~"):
            continue
        parts = ov.split("=", 1)[0].lstrip("+").split(".")
        if parts[0] == "steps" and len(parts) == 3:
            node = (cfg.get("steps") or {}).get(parts[1]) or {}
            if parts[2] in node:
                out.setdefault("steps", {}).setdefault(parts[1], {})[parts[2]] = node[parts[2]]
        elif parts[0] in STEP_KINDS and parts[0] not in ("step", "site_generator") and len(parts) == 2:
            node = cfg.get(parts[0]) or {}
            if parts[1] != "plugin" and parts[1] in node:
                out.setdefault(parts[0], {})[parts[1]] = node[parts[1]]
    return out


def build_plan(cfg: dict, registry: Registry, config_root: Path | None = None,
               skipped: list[tuple[str, str]] | None = None) -> list[PlannedStep]:
    """Turn the composed config into an ordered list of steps with wired inputs.

    Steps marked ``optional: true`` whose required inputs are unavailable are left out and
    appended to ``skipped`` as (step id, reason). Raises ConfigError naming the recipe, step,
    plugin, key or file at fault.
    """
    site = cfg.get("site") or {}
    recipe = cfg.get("recipe") or {}
    rname = recipe.get("name", "?")
    raw_steps = list(recipe.get("steps") or [])
    if not raw_steps:
        raise ConfigError(f"recipe '{rname}' has no steps")
    specs: list[StepSpec] = []
    gen = site.get("generator")
    if gen:
        specs.append(StepSpec(id="site", uses=f"site_generator/{gen}", description="generate the site's inputs"))
    specs += [_spec_from(r, rname, i) for i, r in enumerate(raw_steps)]
    ids = [s.id for s in specs]
    dup = {i for i in ids if ids.count(i) > 1}
    if dup:
        raise ConfigError(f"recipe '{rname}': step ids used twice: {sorted(dup)}")

    plan: list[PlannedStep] = []
    produced: list[tuple[str, bool, int]] = []  # (filename, is_dir, producer index)
    site_inputs = _site_inputs(site)
    given = cfg.get(GIVEN_KEY) or {}
    site_name = site.get("name", "?")
    base_dir = config_root or Path.cwd()

    idx = 0
    for spec in specs:
        idx += 1
        where = f"recipe '{rname}', step '{spec.id}'"
        plugin: Plugin | None = None
        params_obj, params_dict = None, {}
        components: dict[str, Any] = {}
        if spec.manual is not None:
            outs = spec.manual.get("outputs") or []
            if not outs or not spec.manual.get("instructions"):
                raise ConfigError(f"{where}: a manual step needs 'instructions' and 'outputs'")
            ports = []
            for o in outs:
                stem, _, ext = str(o).partition(".")
                ports.append(Port(f"out_{stem}_{ext}", stem, ext or "dir"))
            signature = Signature((), tuple(ports), False)
            in_names = spec.manual.get("inputs") or []
            for n in in_names:
                stem, _, ext = str(n).partition(".")
                ext = ext or None
                signature = Signature(signature.inputs + (Port(f"in_{stem}" + (f"_{ext}" if ext else ""), stem, ext),), signature.outputs, False)
        else:
            uses = str(spec.uses)
            if "/" in uses:
                kind, name = uses.split("/", 1)
            else:
                kind, name = uses, None
            if kind not in STEP_KINDS:
                raise ConfigError(f"{where}: 'uses: {uses}' — kind must be one of {', '.join(STEP_KINDS)}")
            node = dict(cfg.get(kind) or {}) if kind != "step" else {}
            if name is None:
                name = node.get("plugin")
                if not name:
                    raise ConfigError(f"{where}: no {kind} selected; add '{kind}=<name>' or 'uses: {kind}/<name>'")
            try:
                plugin = registry.get(kind, name)
            except TwinkitError as exc:
                raise ConfigError(f"{where}: {exc}") from None
            layers: list[dict] = []
            if kind == "site_generator":
                fields = [f.name for f in dataclasses.fields(plugin.params)] if plugin.params else []
                layers.append({k: site[k] for k in fields if k in site})
            elif kind == "step":
                layers.append(dict((cfg.get("steps") or {}).get(name) or {}))
            elif node.get("plugin") == name:
                layers.append(node)
            layers.append(spec.params)
            # what the user typed on the command line beats the recipe's fixed params
            if kind == "step":
                layers.append(dict((given.get("steps") or {}).get(name) or {}))
            elif kind != "site_generator" and node.get("plugin") == name:
                layers.append(dict(given.get(kind) or {}))
            params_obj, params_dict = resolve_params(plugin, *layers, where=where)
            try:
                signature = parse_signature(plugin.run)
            except ValueError as exc:
                raise ConfigError(f"{where}: {exc}") from None
            for ckind in plugin.uses:
                components[ckind] = cfg.get(ckind)
        # wire inputs
        inputs: dict[str, Source | None] = {}
        try:
            for port in signature.inputs:
                want = spec.inputs.get(port.param)
                inputs[port.param] = _resolve_input(
                    port, want, produced, site_inputs, site_name, where, base_dir, optional=port.optional
                )
        except ConfigError as exc:
            if not spec.optional or "needs input" in str(exc):
                raise
            if skipped is not None:
                skipped.append((spec.id, f"no {port.name} ({port.param}) on this site"))
            idx -= 1
            continue
        unknown_wiring = set(spec.inputs) - {p.param for p in signature.inputs}
        if unknown_wiring:
            raise ConfigError(
                f"{where}: 'inputs' names {sorted(unknown_wiring)}, but {plugin.qualname if plugin else 'the step'} "
                f"reads only {[p.param for p in signature.inputs]}"
            )
        foreach_src = None
        if spec.foreach:
            fport = Port("foreach", str(spec.foreach).partition(".")[0], str(spec.foreach).partition(".")[2] or None)
            foreach_src = _resolve_input(fport, spec.foreach, produced, site_inputs, site_name, where, base_dir, False)
            if not signature.wants_item:
                raise ConfigError(f"{where}: 'foreach' needs a plugin whose run() takes an 'item' parameter")
        ps = PlannedStep(idx, spec, plugin, params_obj, params_dict, signature, inputs, signature.outputs,
                         components, foreach_src)
        plan.append(ps)
        for o in ps.outputs:
            produced.append((o.filename, o.is_dir, idx))
    return plan


def _resolve_input(port: Port, want: str | None, produced, site_inputs: dict, site_name: str, where: str,
                   base_dir: Path, optional: bool) -> Source | None:
    # 1. latest earlier step that writes it
    for filename, is_dir, idx in reversed(produced):
        if want is not None:
            ok = filename == want
        else:
            ok = port.accepts(filename, is_dir)
        if ok:
            # ambiguity within the same producer (cloud.e57 / cloud.las / cloud.ply for in_cloud)
            same = [f for f, d, i in produced if i == idx and (f == want if want else port.accepts(f, d))]
            if len(same) > 1:
                raise ConfigError(
                    f"{where}: input '{port.param}' matches {same} of one step; choose one with "
                    f"'inputs: {{{port.param}: <file>}}' in the recipe"
                )
            return Source(filename=filename, step_index=idx)
    # 2. a site input
    key = (want or port.name).partition(".")[0]
    if key in site_inputs:
        value = site_inputs[key]
        if value is None or value == "???" or value == "":
            raise ConfigError(
                f"site '{site_name}' needs input '{key}' (for {where}): give it on the command line "
                f"(site.inputs.{key}=/path/to/file) or in conf/local/{site_name}.yaml"
            )
        path = Path(str(value)).expanduser()
        if not path.is_absolute():
            path = (base_dir / path).resolve()
        if port.ext not in (None, "dir") and path.suffix.lower() != f".{port.ext}":
            raise ConfigError(f"{where}: site input '{key}' is {path.name}, but '{port.param}' reads .{port.ext} files")
        return Source(filename=path.name, path=path)
    if optional:
        return None
    have = sorted({f for f, _, _ in produced}) + [f"site input '{k}'" for k in site_inputs]
    raise ConfigError(
        f"{where}: nothing provides input '{port.param}' ({want or port.name}); no earlier step writes it and site "
        f"'{site_name}' has no input '{key}'. Available: {', '.join(have) or 'nothing'}"
    )


# --------------------------------------------------------------------------- running


@dataclass
class StepOutcome:
    step: str
    folder: str
    plugin: str
    status: str  # ran | reused | cached | edited | manual | failed | pending
    why: str
    key: str
    duration_s: float
    outputs: dict[str, Any]  # filename -> Path or list[Path]
    hashes: dict[str, Any]  # filename -> artefact hash (or list)
    metrics: dict = field(default_factory=dict)
    peak_rss_mb: float | None = None


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


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def read_record(folder: Path) -> dict | None:
    p = folder / RECORD
    if not p.is_file():
        return None
    try:
        return json.loads(p.read_text())
    except (OSError, json.JSONDecodeError):
        return None


def _link_or_copy(src: Path, dst: Path) -> None:
    dst.parent.mkdir(parents=True, exist_ok=True)
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def unwritable(folder: Path) -> str | None:
    """Why ``folder`` cannot be created or written to, or None when it can (a probe file is written and removed)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / f".write-test-{os.getpid()}"
        probe.write_text("ok")
        probe.unlink()
    except OSError as exc:
        return exc.strerror or str(exc)
    return None


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def compute_into_store(run: Callable, params: Any, inputs: dict[str, Any], outputs: tuple[Port, ...], key: str,
                       store: Path, ctx_kwargs: dict, item: Any = None, wants_item: bool = False,
                       force: bool = False, hash_db: Path | None = None) -> dict:
    """Run one step (or one fan-out item) into ``store/<key>`` atomically; returns the stored record.

    Module-level so executors can ship it to other processes or machines.
    """
    from filelock import FileLock

    store.mkdir(parents=True, exist_ok=True)
    final = store / key
    with FileLock(str(store / f"{key}.lock")):
        if final.is_dir() and (final / RECORD).is_file() and not force:
            rec = json.loads((final / RECORD).read_text())
            rec["_computed_here"] = False
            return rec
        tmp = store / ".tmp" / f"{key}-{os.getpid()}-{threading.get_ident()}"
        if tmp.exists():
            shutil.rmtree(tmp)
        tmp.mkdir(parents=True)
        out_paths = {p.param: tmp / p.filename for p in outputs}
        ctx = StepContext(workdir=tmp, **ctx_kwargs)
        kwargs = dict(inputs)
        kwargs.update(out_paths)
        if wants_item:
            kwargs["item"] = item
        t0 = time.perf_counter()
        try:
            with _PeakRSS() as mem:
                metrics = run(params, ctx, **kwargs)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        duration = time.perf_counter() - t0
        missing = [p.filename for p in outputs if not (tmp / p.filename).exists()]
        wrong = [p.filename for p in outputs if (tmp / p.filename).exists() and p.is_dir != (tmp / p.filename).is_dir()]
        if missing or wrong:
            shutil.rmtree(tmp, ignore_errors=True)
            what = f"did not write {missing}" if missing else f"wrote files where folders were declared (or the reverse): {wrong}"
            raise StepError(f"step '{ctx.step_id}' {what}; nothing from this attempt was kept")
        cache = HashCache(hash_db)
        files = {rel.as_posix(): {"sha256": cache.hash(tmp / rel), "size": (tmp / rel).stat().st_size}
                 for rel in list_files(tmp)}
        record = {
            "schema": RECORD_SCHEMA,
            "key": key,
            "duration_s": round(duration, 3),
            "peak_rss_mb": round(mem.peak / 2**20, 1) if mem.peak else None,
            # what the process held before the step began (a pooled worker keeps memory from earlier items)
            "start_rss_mb": round(mem.start / 2**20, 1) if mem.start else None,
            "metrics": metrics if isinstance(metrics, dict) else {},
            "files": files,
            "artefacts": {p.filename: artefact_hash(tmp / p.filename, cache) for p in outputs},
            "computed_at": _now(),
            "item": item,
        }
        cache.close()
        write_json_atomic(tmp / RECORD, record)
        if final.exists():
            shutil.rmtree(final)
        os.replace(tmp, final)
        record["_computed_here"] = True
        return record


def _item_cost(item: Any) -> float:
    c = item.get("cost") if isinstance(item, dict) else None
    return float(c) if isinstance(c, (int, float)) and not isinstance(c, bool) else 0.0


def _run_item_task(task: dict) -> dict:
    """Executor entry point for one fan-out item (picklable, top level)."""
    try:
        return compute_into_store(**task)
    finally:
        release_memory()


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


class Engine:
    """Runs a plan in a workspace with a shared store.

    Args:
        cfg: the composed configuration (plain dict, resolved).
        registry: loaded plugins.
        workspace: where numbered step folders live (``outputs/<site>`` or a multirun job folder).
        site_root: ``outputs/<site>``; its ``.cache`` is shared by runs and jobs.
        rerun: step ids (or folder names) to force.
        interactive: manual steps wait for their files when true; exit with code 3 otherwise.
    """

    def __init__(self, cfg: dict, registry: Registry, workspace: Path, site_root: Path,
                 rerun: list[str] | None = None, interactive: bool = False, threads: int | None = None,
                 config_root: Path | None = None, executor_factory: Callable[[], Any] | None = None,
                 manual_timeout_s: float | None = None):
        self.cfg = cfg
        self.registry = registry
        self.workspace = Path(workspace)
        self.site_root = Path(site_root)
        self.rerun = set(rerun or [])
        self.interactive = interactive
        self.threads = threads or os.cpu_count() or 1
        self.config_root = config_root
        self.store = self.site_root / ".cache" / "steps"
        self.edits_dir = self.site_root / ".cache" / "edits"
        self.hashes = HashCache(self.site_root / ".cache" / "hashes.sqlite")
        self.executor_factory = executor_factory
        self.manual_timeout_s = manual_timeout_s
        self.skipped: list[tuple[str, str]] = []
        self.plan = build_plan(cfg, registry, config_root, skipped=self.skipped)
        known = {s.id for s in self.plan} | {s.folder for s in self.plan}
        bad = self.rerun - known
        if bad:
            raise ConfigError(f"rerun names unknown step(s) {sorted(bad)}; steps are: {', '.join(s.id for s in self.plan)}")
        self.outcomes: list[StepOutcome] = []
        self._lock = None

    # ---------------------------------------------------------------- workspace and locking
    def _prepare(self) -> None:
        for d in (self.workspace, self.store):
            problem = unwritable(d)
            if problem:
                raise InputError(f"cannot write to {d} ({problem}); choose a writable folder with engine.outputs_dir=<dir>")
        from filelock import FileLock, Timeout

        lock = FileLock(str(self.workspace / ".twinkit.lock"))
        try:
            lock.acquire(timeout=0)
        except Timeout:
            holder = (self.workspace / ".twinkit.owner").read_text().strip() if (self.workspace / ".twinkit.owner").exists() else "?"
            raise LockedError(
                f"another twinkit run is using {self.workspace} ({holder}); wait for it to finish, "
                f"or use another engine.outputs_dir"
            ) from None
        (self.workspace / ".twinkit.owner").write_text(f"pid {os.getpid()} since {_now()}\n")
        self._lock = lock
        # leftovers of killed runs: never counted as done, removed now
        tmp_root = self.store / ".tmp"
        if tmp_root.is_dir():
            for d in tmp_root.iterdir():
                try:
                    pid = int(d.name.split("-")[1])
                except (IndexError, ValueError):
                    pid = -1
                if not _pid_alive(pid):
                    shutil.rmtree(d, ignore_errors=True)
        for d in [*self.workspace.glob(".*.tmp-*"), *self.workspace.glob(".*.old-*")]:
            try:
                pid = int(d.name.rsplit("-", 1)[1])
            except ValueError:
                pid = -1
            if not _pid_alive(pid):
                shutil.rmtree(d, ignore_errors=True)

    def _release(self) -> None:
        if self._lock is not None:
            self._lock.release()
            self._lock = None
        self.hashes.close()

    # ---------------------------------------------------------------- keys
    def _input_values(self, ps: PlannedStep) -> tuple[dict[str, Any], dict[str, Any]]:
        """Paths and content hashes of a step's inputs."""
        paths: dict[str, Any] = {}
        hashes: dict[str, Any] = {}
        sources = dict(ps.inputs)
        if ps.foreach is not None:
            sources["__foreach__"] = ps.foreach
        for param, src in sources.items():
            if src is None:
                paths[param], hashes[param] = None, None
                continue
            if src.path is not None:
                if not src.path.exists():
                    raise InputError(
                        f"site input {src.path} does not exist (needed by step '{ps.id}'); "
                        f"fix the path in the site config or on the command line"
                    )
                paths[param] = src.path
                hashes[param] = artefact_hash(src.path, self.hashes) if src.path.is_dir() else self.hashes.hash(src.path)
            else:
                prod = self.outcomes[src.step_index - 1]
                paths[param] = prod.outputs[src.filename]
                hashes[param] = prod.hashes[src.filename]
        return paths, hashes

    def _descriptor(self, ps: PlannedStep, input_hashes: dict[str, Any]) -> dict:
        if ps.plugin is None:
            plugin = {"kind": "manual", "instructions": ps.spec.manual.get("instructions")}
        else:
            plugin = {"kind": ps.plugin.kind, "name": ps.plugin.name, "version": ps.plugin.version,
                      "code": ps.plugin.code_hash()}
        return {
            "plugin": plugin,
            "params": ps.params_dict,
            "components": ps.components,
            "inputs": input_hashes,
            "outputs": [o.filename for o in ps.outputs],
        }

    @staticmethod
    def _key(descriptor: dict) -> str:
        return hashlib.sha256(json.dumps(descriptor, sort_keys=True, default=str).encode()).hexdigest()[:32]

    @staticmethod
    def _why(old: dict | None, new: dict) -> str:
        if old is None or "descriptor" not in old:
            return "no earlier result"
        o = old["descriptor"]
        reasons = []
        if o.get("plugin", {}).get("name") != new["plugin"].get("name"):
            reasons.append(f"plugin {o['plugin'].get('name')} -> {new['plugin'].get('name')}")
        elif o.get("plugin", {}).get("version") != new["plugin"].get("version"):
            reasons.append(f"plugin version {o['plugin'].get('version')} -> {new['plugin'].get('version')}")
        elif o.get("plugin", {}).get("code") != new["plugin"].get("code"):
            reasons.append("plugin code changed")
        for k in sorted(set(o.get("params", {})) | set(new["params"])):
            a, b = o.get("params", {}).get(k), new["params"].get(k)
            if a != b:
                reasons.append(f"{k} {a!r} -> {b!r}")
        changed = [k for k in sorted(set(o.get("inputs", {})) | set(new["inputs"]))
                   if o.get("inputs", {}).get(k) != new["inputs"].get(k)]
        if changed:
            reasons.append("input changed: " + ", ".join(changed))
        if o.get("components") != new["components"]:
            reasons.append("component config changed")
        return "; ".join(reasons) or "key changed"

    # ---------------------------------------------------------------- workspace records
    def _check_workspace(self, folder: Path, rec: dict) -> tuple[str, list[str]]:
        """'unchanged', 'edited' (+ files) or 'missing' (+ files) for a recorded step folder."""
        missing, edited = [], []
        for rel, info in rec.get("files", {}).items():
            p = folder / rel
            if not p.is_file():
                missing.append(rel)
            elif p.stat().st_size != info["size"] or self.hashes.hash(p) != info["sha256"]:
                edited.append(rel)
        if missing:
            return "missing", missing
        return ("edited", edited) if edited else ("unchanged", [])

    def _set_aside(self, folder: Path, files: list[str], why: str) -> Path:
        dest = self.edits_dir / f"{folder.name}-{_dt.datetime.now().strftime('%Y%m%d-%H%M%S')}"
        for rel in files:
            _link_or_copy(folder / rel, dest / rel)
        log.warning("  %s: hand-edited %s set aside in %s (%s)", folder.name, ", ".join(files), dest, why)
        return dest

    def _store_valid(self, key: str) -> dict | None:
        entry = self.store / key
        rec = read_record(entry)
        if rec is None:
            return None
        for rel, info in rec.get("files", {}).items():
            p = entry / rel
            if not p.is_file() or p.stat().st_size != info["size"] or self.hashes.hash(p) != info["sha256"]:
                log.warning("  cached result %s was modified (%s); computing it again", key, rel)
                shutil.rmtree(entry, ignore_errors=True)
                return None
        return rec

    def _materialize(self, folder: Path, entries: list[tuple[str, Path]], record: dict) -> None:
        """Atomically replace ``folder`` with hard links (or copies) of the stored files."""
        tmp = self.workspace / f".{folder.name}.tmp-{os.getpid()}"
        if tmp.exists():
            shutil.rmtree(tmp)
        tmp.mkdir(parents=True)
        for prefix, src_dir in entries:
            for rel in list_files(src_dir):
                if rel.name == RECORD and rel.parent == Path("."):
                    continue
                _link_or_copy(src_dir / rel, tmp / prefix / rel)
        write_json_atomic(tmp / RECORD, record)
        old = None
        if folder.exists():
            old = self.workspace / f".{folder.name}.old-{os.getpid()}"
            os.replace(folder, old)
        os.replace(tmp, folder)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)

    def _ctx_kwargs(self, ps: PlannedStep) -> dict:
        return {
            "step_id": ps.id,
            "site": self.cfg.get("site") or {},
            "config": self.cfg,
            "threads": self.threads,
            "log": logging.getLogger(f"twinkit.step.{ps.id}"),
        }

    # ---------------------------------------------------------------- the loop
    def run(self, on_step: Callable[[StepOutcome, int, int], None] | None = None) -> list[StepOutcome]:
        self._prepare()
        for sid, reason in self.skipped:
            log.info("[-] %-28s skipped  optional step: %s", sid, reason)
        try:
            n = len(self.plan)
            for ps in self.plan:
                t0 = time.perf_counter()
                try:
                    outcome = self._run_step(ps)
                except TwinkitError:
                    raise
                except Exception as exc:
                    tb = traceback.format_exc()
                    log.debug(tb)
                    raise StepError(
                        f"step '{ps.id}' ({ps.label} {ps.plugin.version if ps.plugin else ''}) failed: "
                        f"{type(exc).__name__}: {exc}. Earlier results are kept; the traceback is in the run log"
                    ) from exc
                if outcome.status not in ("ran",):
                    outcome.duration_s = time.perf_counter() - t0
                self.outcomes.append(outcome)
                if on_step:
                    on_step(outcome, ps.index, n)
            return self.outcomes
        finally:
            self._release()

    def _outputs_of(self, folder: Path, ps: PlannedStep, rec: dict, current: bool) -> tuple[dict, dict]:
        outputs = {p.filename: folder / p.filename for p in ps.outputs}
        if current:
            hashes = {p.filename: artefact_hash(folder / p.filename, self.hashes) for p in ps.outputs}
        else:
            hashes = dict(rec["artefacts"])
        return outputs, hashes

    def _run_step(self, ps: PlannedStep) -> StepOutcome:
        folder = self.workspace / ps.folder
        in_paths, in_hashes = self._input_values(ps)
        desc = self._descriptor(ps, in_hashes)
        key = self._key(desc)
        rec = read_record(folder)
        forced = ps.id in self.rerun or ps.folder in self.rerun
        if ps.plugin is None:
            return self._run_manual(ps, folder, key, desc, rec)
        if ps.foreach is not None:
            return self._run_fanout(ps, folder, key, desc, rec, in_paths, forced)

        if rec is not None and rec.get("key") == key and not forced:
            state, files = self._check_workspace(folder, rec)
            if state == "unchanged":
                outputs, hashes = self._outputs_of(folder, ps, rec, current=False)
                return StepOutcome(ps.id, ps.folder, ps.label, "reused", "unchanged", key, 0.0, outputs, hashes,
                                   rec.get("metrics", {}), rec.get("peak_rss_mb"))
            if state == "edited":
                outputs, hashes = self._outputs_of(folder, ps, rec, current=True)
                return StepOutcome(ps.id, ps.folder, ps.label, "edited",
                                   f"kept hand-edited {', '.join(files)}; later steps re-run", key, 0.0, outputs,
                                   hashes, rec.get("metrics", {}), rec.get("peak_rss_mb"))
            why = f"output missing: {', '.join(files)}"
        elif forced:
            why = "forced by rerun"
        else:
            why = self._why(rec, desc)
        if rec is not None and folder.is_dir():
            state, files = self._check_workspace(folder, rec)
            if state == "edited":
                self._set_aside(folder, files, "forced re-run" if forced else f"its step re-runs ({why})")

        stored = None if forced else self._store_valid(key)
        status = "cached" if stored else "ran"
        if stored is None:
            log.debug("  %s: running %s ...", ps.folder, ps.label)
            from twinkit.progress import step_status

            with step_status(f"{ps.folder} ({ps.label})"):
                stored = compute_into_store(ps.plugin.run, ps.params, in_paths, ps.outputs, key, self.store,
                                            self._ctx_kwargs(ps), force=forced, hash_db=self.hashes.db_path)
            if not stored.pop("_computed_here", True):
                status, why = "cached", why + " (computed by a concurrent job)"
        record = self._workspace_record(ps, key, desc, stored, status, why, in_paths)
        self._materialize(folder, [("", self.store / key)], record)
        outputs, hashes = self._outputs_of(folder, ps, stored, current=False)
        return StepOutcome(ps.id, ps.folder, ps.label, status, why, key,
                           stored.get("duration_s", 0.0) if status == "ran" else 0.0, outputs, hashes,
                           stored.get("metrics", {}), stored.get("peak_rss_mb"))

    def _workspace_record(self, ps, key, desc, stored, status, why, in_paths) -> dict:
        return {
            "schema": RECORD_SCHEMA,
            "step": ps.id,
            "key": key,
            "descriptor": desc,
            "plugin": ps.label,
            "distribution": ps.plugin.distribution if ps.plugin else None,
            "params": ps.params_dict,
            "inputs": {k: (str(v) if not isinstance(v, list) else [str(x) for x in v]) for k, v in in_paths.items()},
            "files": stored.get("files", {}),
            "artefacts": stored.get("artefacts", {}),
            "metrics": stored.get("metrics", {}),
            "duration_s": stored.get("duration_s"),
            "peak_rss_mb": stored.get("peak_rss_mb"),
            "status": status,
            "why": why,
            "recorded_at": _now(),
        }

    # ---------------------------------------------------------------- fan-out
    def _executor(self):
        if self.executor_factory is not None:
            return self.executor_factory()
        from twinkit.plugins import build_component

        if self.cfg.get("executor"):
            return build_component("executor", None, self.cfg)
        from twinkit.executors import LocalExecutor

        return LocalExecutor(workers=min(2, self.threads))

    def _run_fanout(self, ps, folder, key, desc, rec, in_paths, forced) -> StepOutcome:
        items_path = in_paths.pop("__foreach__")
        try:
            items = json.loads(Path(items_path).read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise InputError(f"{items_path}: the 'foreach' list of step '{ps.id}' is not readable JSON ({exc})") from None
        if isinstance(items, dict) and "items" in items:
            items = items["items"]
        if not isinstance(items, list):
            raise InputError(f"{items_path}: 'foreach' of step '{ps.id}' needs a JSON list (or {{\"items\": [...]}})")
        # each item is keyed by its own content and the step's other inputs, not by the whole list,
        # so adding a tile computes only the new tile
        base = dict(desc, inputs={k: v for k, v in desc["inputs"].items() if k != "__foreach__"})
        keys = [self._key({"step": base, "item": it}) for it in items]
        if rec is not None and rec.get("key") == key and not forced:
            state, files = self._check_workspace(folder, rec)
            if state in ("unchanged", "edited"):
                outputs = {p.filename: [folder / f"{i:03d}" / p.filename for i in range(len(items))] for p in ps.outputs}
                if state == "unchanged":
                    hashes = rec["artefacts"]
                else:
                    hashes = {f: [artefact_hash(x, self.hashes) for x in paths] for f, paths in outputs.items()}
                status = "reused" if state == "unchanged" else "edited"
                return StepOutcome(ps.id, ps.folder, ps.label, status,
                                   "unchanged" if state == "unchanged" else f"kept hand-edited {', '.join(files)}",
                                   key, 0.0, outputs, hashes, rec.get("metrics", {}))
        why = "forced by rerun" if forced else self._why(rec, desc)
        todo = [i for i, k in enumerate(keys) if forced or self._store_valid(k) is None]
        # items that say what they cost ("cost": any number) start costliest first, so that a big
        # item does not start last and leave the other workers idle (results are keyed, not ordered)
        todo.sort(key=lambda i: -_item_cost(items[i]))
        tasks = [dict(run=ps.plugin.run, params=ps.params, inputs=in_paths, outputs=ps.outputs, key=keys[i],
                      store=self.store, ctx_kwargs={**self._ctx_kwargs(ps), "log": None, "config": self.cfg},
                      item=items[i], wants_item=True, force=forced, hash_db=self.hashes.db_path) for i in todo]
        for t in tasks:
            t["ctx_kwargs"].pop("log")
        t0 = time.perf_counter()
        if tasks:
            log.debug("  %s: running %s on %d of %d items ...", ps.folder, ps.label, len(tasks), len(items))
            ex = self._executor()
            results = ex.map(_run_item_task, tasks)
            for _ in _track(results, len(tasks), ps.id):
                pass
        duration = time.perf_counter() - t0
        stored = [read_record(self.store / k) for k in keys]
        files: dict[str, Any] = {}
        for i, r in enumerate(stored):
            for rel, info in r["files"].items():
                if rel != RECORD:
                    files[f"{i:03d}/{rel}"] = info
        artefacts = {p.filename: [r["artefacts"][p.filename] for r in stored] for p in ps.outputs}
        metrics = {"items": len(items), "computed": len(tasks),
                   "per_item": [r.get("metrics", {}) | {"peak_rss_mb": r.get("peak_rss_mb"), "start_rss_mb": r.get("start_rss_mb"),
                                                        "duration_s": r.get("duration_s")} for r in stored]}
        status = "ran" if tasks else "cached"
        record = self._workspace_record(ps, key, desc, {"files": files, "artefacts": artefacts, "metrics": metrics,
                                                        "duration_s": round(duration, 3)}, status, why, in_paths)
        record["item_keys"] = keys
        self._materialize(folder, [(f"{i:03d}", self.store / k) for i, k in enumerate(keys)], record)
        outputs = {p.filename: [folder / f"{i:03d}" / p.filename for i in range(len(items))] for p in ps.outputs}
        return StepOutcome(ps.id, ps.folder, ps.label, status, why + f" ({len(tasks)}/{len(items)} items computed)",
                           key, duration, outputs, artefacts, metrics)

    # ---------------------------------------------------------------- manual actions
    def _run_manual(self, ps, folder, key, desc, rec) -> StepOutcome:
        folder.mkdir(parents=True, exist_ok=True)
        wanted = [folder / p.filename for p in ps.outputs]
        missing = [p for p in wanted if not p.exists()]
        if missing:
            text = str(ps.spec.manual["instructions"]).format(
                folder=folder, path=missing[0], files=", ".join(str(m) for m in missing),
                workspace=self.workspace)
            (folder / "INSTRUCTIONS.txt").write_text(text.strip() + "\n\nWaiting for: " +
                                                     ", ".join(str(m) for m in missing) + "\n")
            log.warning("  %s: manual action needed:\n    %s\n    waiting for %s", ps.folder,
                        text.strip().replace("\n", "\n    "), ", ".join(str(m) for m in missing))
            if not self.interactive:
                raise ManualActionPending(
                    f"step '{ps.id}' waits for {', '.join(str(m) for m in missing)} "
                    f"(instructions in {folder / 'INSTRUCTIONS.txt'}); create it and run the same command again"
                )
            _wait_for_files(missing, self.manual_timeout_s)
        hashes = {p.filename: artefact_hash(folder / p.filename, self.hashes) for p in ps.outputs}
        files = {rel.as_posix(): {"sha256": self.hashes.hash(folder / rel), "size": (folder / rel).stat().st_size}
                 for rel in list_files(folder) if rel.name not in (RECORD, "INSTRUCTIONS.txt")}
        stale = rec is not None and rec.get("key") not in (None, key)
        why = "provided by hand" + ("; NOTE: its inputs changed since — check it is still right" if stale else "")
        status = "manual"
        record = {"schema": RECORD_SCHEMA, "step": ps.id, "key": key, "descriptor": desc, "plugin": "manual",
                  "files": files, "artefacts": hashes, "status": status, "why": why, "recorded_at": _now()}
        write_json_atomic(folder / RECORD, record)
        outputs = {p.filename: folder / p.filename for p in ps.outputs}
        return StepOutcome(ps.id, ps.folder, "manual", status, why, key, 0.0, outputs, hashes)

    # ---------------------------------------------------------------- status (dry run)
    def status(self) -> list[tuple[str, str, str]]:
        """What a run would do, without running or writing anything: (folder, decision, why)."""
        rows = []
        dirty = False
        for ps in self.plan:
            folder = self.workspace / ps.folder
            rec = read_record(folder)
            if dirty:
                rows.append((ps.folder, "would run", "an earlier step re-runs"))
                self.outcomes.append(None)  # type: ignore[arg-type]
                continue
            try:
                in_paths, in_hashes = self._input_values(ps)
            except TwinkitError as exc:
                rows.append((ps.folder, "blocked", str(exc)))
                dirty = True
                continue
            key = self._key(self._descriptor(ps, in_hashes))
            forced = ps.id in self.rerun
            if ps.plugin is None:
                done = all((folder / p.filename).exists() for p in ps.outputs)
                rows.append((ps.folder, "manual done" if done else "waits for you",
                             ", ".join(p.filename for p in ps.outputs)))
                if not done:
                    dirty = True
                    continue
                hashes = {p.filename: artefact_hash(folder / p.filename, self.hashes) for p in ps.outputs}
            elif rec is not None and rec.get("key") == key and not forced:
                state, files = self._check_workspace(folder, rec)
                if state == "missing":
                    rows.append((ps.folder, "would run", f"output missing: {', '.join(files)}"))
                    dirty = True
                    continue
                rows.append((ps.folder, "up to date" if state == "unchanged" else "edited",
                             "" if state == "unchanged" else ", ".join(files)))
                if ps.foreach is not None:
                    hashes = rec["artefacts"] if state == "unchanged" else None
                    if hashes is None:
                        dirty = True
                        continue
                else:
                    _, hashes = self._outputs_of(folder, ps, rec, current=state == "edited")
            else:
                stored = None if forced else read_record(self.store / key)
                if stored is not None:
                    rows.append((ps.folder, "cached", "result stored for this key"))
                    hashes = stored["artefacts"]
                else:
                    rows.append((ps.folder, "would run", "forced by rerun" if forced else self._why(rec, self._descriptor(ps, in_hashes))))
                    dirty = True
                    continue
            outputs = {p.filename: folder / p.filename for p in ps.outputs}
            self.outcomes.append(StepOutcome(ps.id, ps.folder, ps.label, "status", "", key, 0, outputs, hashes))
        self.hashes.close()
        return rows


def _track(iterable, total, desc):
    from twinkit.progress import track

    return track(iterable, total=total, desc=desc)


def _wait_for_files(paths: list[Path], timeout_s: float | None) -> None:
    """Block until every path exists and its size stopped changing (watching the folder)."""
    deadline = None if timeout_s is None else time.monotonic() + timeout_s
    event = threading.Event()
    observer = None
    try:
        from watchdog.events import FileSystemEventHandler
        from watchdog.observers import Observer

        class _Handler(FileSystemEventHandler):
            def on_any_event(self, ev):  # noqa: D401
                event.set()

        observer = Observer()
        for d in {p.parent for p in paths}:
            observer.schedule(_Handler(), str(d), recursive=False)
        observer.start()
    except ImportError:  # polling is a fine fallback
        observer = None
    try:
        sizes: dict[Path, int] = {}
        while True:
            if all(p.exists() for p in paths):
                now = {p: (p.stat().st_size if p.is_file() else -1) for p in paths}
                if now == sizes:
                    return
                sizes = now
            if deadline is not None and time.monotonic() > deadline:
                raise ManualActionPending(f"gave up waiting for {', '.join(str(p) for p in paths)}")
            event.wait(0.5)
            event.clear()
    finally:
        if observer is not None:
            observer.stop()
            observer.join()


# --------------------------------------------------------------------------- single-step helper


def execute_plugin(plugin: Plugin, workdir: Path, inputs: dict[str, Path], params: Any = None,
                   site: dict | None = None, config: dict | None = None) -> dict[str, Path]:
    """Run one step-like plugin through the engine's atomic write path, outside any recipe.

    ``inputs`` maps input parameter names (``in_mesh_ply``) to paths. Returns
    {output file name: path} inside ``workdir/result``.
    """
    sig = parse_signature(plugin.run)
    params = params if params is not None else plugin.default_params()
    kwargs = {p.param: (Path(inputs[p.param]) if p.param in inputs else None) for p in sig.inputs}
    missing = [p.param for p in sig.inputs if kwargs[p.param] is None and not p.optional]
    if missing:
        raise InputError(f"{plugin.qualname} needs inputs {missing}")
    store = Path(workdir) / ".store"
    key = hashlib.sha256(repr((plugin.qualname, time.time_ns())).encode()).hexdigest()[:16]
    compute_into_store(plugin.run, params, kwargs, sig.outputs, key, store,
                       {"step_id": plugin.name, "site": site or {"name": "test"}, "config": config or {},
                        "log": logging.getLogger(f"twinkit.step.{plugin.name}")})
    result = Path(workdir) / "result"
    if result.exists():
        shutil.rmtree(result)
    os.replace(store / key, result)
    return {p.filename: result / p.filename for p in sig.outputs}


# --------------------------------------------------------------------------- garbage collection


def collect_garbage(site_root: Path, dry_run: bool = False) -> tuple[list[Path], int]:
    """Stored results that no numbered folder (of the site or of any sweep job) refers to.

    Returns (removed or removable entries, bytes). Entries in use by a running job are safe:
    they are referenced by that job's folders only after it finishes, so run gc when nothing runs.
    """
    store = Path(site_root) / ".cache" / "steps"
    if not store.is_dir():
        return [], 0
    keep: set[str] = set()
    for rec_path in [*Path(site_root).glob(f"[0-9][0-9]_*/{RECORD}"),
                     *Path(site_root).glob(f"sweeps/*/*/[0-9][0-9]_*/{RECORD}")]:
        rec = read_record(rec_path.parent) or {}
        if rec.get("key"):
            keep.add(rec["key"])
        keep.update(rec.get("item_keys") or [])
    doomed = [d for d in store.iterdir() if d.is_dir() and d.name != ".tmp" and d.name not in keep]
    size = sum(f.stat().st_size for d in doomed for f in d.rglob("*") if f.is_file())
    if not dry_run:
        for d in doomed:
            shutil.rmtree(d, ignore_errors=True)
            (store / f"{d.name}.lock").unlink(missing_ok=True)
    return doomed, size


def prune_hash_cache(site_root: Path) -> int:
    """Forget remembered hashes of files that are gone or changed; returns how many were forgotten.

    Kept: every file under the site's folder (results, the store, runs) and every input file that a
    run manifest names and that still exists, so a large scan outside the workspace is not read again.
    """
    site_root = Path(site_root)
    db = site_root / ".cache" / "hashes.sqlite"
    if not db.is_file():
        return 0

    def sig(p: Path):
        try:
            st = os.stat(p)
        except OSError:
            return None
        return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)

    keep: set = set()
    for root, dirs, files in os.walk(site_root):
        for f in files:
            s = sig(Path(root) / f)
            if s is not None:
                keep.add(s)
    for m in site_root.glob("**/runs/*/manifest.json"):
        try:
            entries = json.loads(m.read_text()).get("inputs", [])
        except (OSError, ValueError):
            continue
        for e in entries:
            s = sig(Path(e.get("path", "")))
            if s is not None:
                keep.add(s)
    cache = HashCache(db)
    try:
        return cache.prune(keep)
    finally:
        cache.close()

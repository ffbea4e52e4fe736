"""Provenance: one manifest per run, and a check of a manifest against the files on disk."""
from __future__ import annotations

import functools
import importlib.metadata as md
import json
import os
import platform
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

from twinkit.hashing import sha256_file

SCHEMA_VERSION = 1

#: optional-dependency groups that are tools around a package, not libraries its code runs with
TOOL_EXTRAS = ("test", "tests", "bench", "dev", "docs", "lint")


@functools.lru_cache(maxsize=None)
def _library_versions(distributions: tuple[str, ...]) -> tuple:
    return tuple(library_versions(distributions).items())


def _canon(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def declared_libraries(distributions: tuple[str, ...] | list[str]) -> list[str]:
    """The libraries the given distributions declare (``importlib.metadata.requires``): each one's
    requirements, with those of its optional groups but the tool groups (:data:`TOOL_EXTRAS`), and
    ``twinkit``'s own requirements with every extra a distribution asks of it (``twinkit[geo,mesh]``).
    Names as the requirements spell them, sorted; distributions that are not installed are skipped."""
    from packaging.requirements import InvalidRequirement, Requirement

    dists = [d for d in dict.fromkeys(["twinkit", *distributions])]
    parsed: dict[str, list] = {}
    extras: dict[str, set[str]] = {}  # extras of each distribution that are used
    for d in dists:
        try:
            dist = md.distribution(d)
        except md.PackageNotFoundError:
            continue
        raw = dist.requires or []
        offered = dist.metadata.get_all("Provides-Extra") or []
        reqs = []
        for line in raw:
            try:
                reqs.append(Requirement(line))
            except InvalidRequirement:
                continue
        parsed[_canon(d)] = reqs
        extras.setdefault(_canon(d), set()).update(e for e in offered if e not in TOOL_EXTRAS and d != "twinkit")
    for reqs in parsed.values():
        for r in reqs:
            if r.extras and (r.marker is None or r.marker.evaluate({"extra": ""})):
                extras.setdefault(_canon(r.name), set()).update(r.extras)
    for d in [d for d in extras if d not in parsed]:  # a library asked for with extras: dask[distributed]
        try:
            parsed[d] = [Requirement(line) for line in md.requires(d) or [] if "extra ==" in line]
        except (md.PackageNotFoundError, InvalidRequirement):
            continue
    names: dict[str, str] = {}
    for d, reqs in parsed.items():
        for r in reqs:
            wanted = r.marker is None or any(r.marker.evaluate({"extra": e}) for e in ("", *extras.get(d, ())))
            if wanted:
                names.setdefault(_canon(r.name), r.name)
    return sorted(names.values(), key=_canon)


def library_versions(distributions: tuple[str, ...] | list[str] = ()) -> dict[str, str]:
    """Installed versions of ``twinkit`` and of every library :func:`declared_libraries` finds for the
    loaded plugins' ``distributions``."""
    out = {}
    for name in ["twinkit", *declared_libraries(tuple(distributions))]:
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            pass
    return out


@functools.lru_cache(maxsize=8)
def _git_state(root: Path) -> tuple:
    return tuple(git_state(root).items())


def git_state(root: Path) -> dict[str, Any]:
    def git(*args: str) -> str | None:
        try:
            r = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=10)
        except (OSError, subprocess.TimeoutExpired):
            return None
        return r.stdout.strip() if r.returncode == 0 else None

    commit = git("rev-parse", "HEAD")
    dirty = git("status", "--porcelain", "--untracked-files=no")
    return {"commit": commit, "dirty": bool(dirty) if dirty is not None else None}


def _file_entry(path: Path, cache) -> dict:
    try:
        return {"path": str(path), "sha256": cache.hash(path), "size": path.stat().st_size}
    except OSError as exc:  # an unreadable input: the manifest is still written, and says so
        return {"path": str(path), "sha256": None, "size": None, "error": f"cannot read: {exc.strerror or exc}"}


def build_manifest(*, argv: list[str], overrides: list[str], config: dict, site: dict, outcomes: list,
                   engine, registry, project_root: Path, status: str, error: str | None,
                   started: str, finished: str, duration_s: float) -> dict:
    cache = engine.hashes
    inputs = []
    for ps in engine.plan:
        for src in ps.inputs.values():
            if src is not None and src.path is not None and src.path.is_file():
                inputs.append(_file_entry(src.path, cache))
    inputs = sorted({e["path"]: e for e in inputs}.values(), key=lambda e: e["path"])
    steps = []
    outputs = []
    for oc in outcomes:
        steps.append({
            "id": oc.step, "folder": oc.folder, "plugin": oc.plugin, "status": oc.status, "why": oc.why,
            "key": oc.key, "duration_s": round(oc.duration_s, 3), "peak_rss_mb": oc.peak_rss_mb,
            "metrics": oc.metrics,
        })
        folder = engine.workspace / oc.folder
        for fname, p in oc.outputs.items():
            for path in (p if isinstance(p, list) else [p]):
                path = Path(path)
                files = [path] if path.is_file() else sorted(x for x in path.rglob("*") if x.is_file()) if path.is_dir() else []
                for f in files:
                    e = _file_entry(f, cache)
                    e["step"] = oc.step
                    outputs.append(e)
        _ = folder
    plugins = [
        {"kind": p.kind, "name": p.name, "version": p.version, "distribution": p.distribution, "module": p.module}
        for p in registry.all()
    ]
    from twinkit.quality import notes_of, run_degraded, run_gates

    degraded = run_degraded(steps)
    if status == "ok" and degraded:
        status = "degraded"
    return {
        "schema_version": SCHEMA_VERSION,
        "status": status,
        "degraded": degraded,
        "gates": run_gates(steps),  # every quality gate's figure, passed or failed
        "notes": notes_of(steps),  # facts on the twin the status names ("no road network")
        "error": error,
        "argv": argv,
        "overrides": overrides,
        "config": config,
        "site": {k: site.get(k) for k in ("name", "crs", "base_point", "bounds_m") if k in site},
        "git": dict(_git_state(Path(project_root))),  # once per process: the manifest is written at start and end
        "python": {"version": sys.version.split()[0], "implementation": platform.python_implementation(),
                   "platform": platform.platform()},
        "libraries": dict(_library_versions(tuple(sorted({p.distribution for p in registry.all()})))),
        "plugins": plugins,
        "steps": steps,
        "inputs": inputs,
        "outputs": outputs,
        "workspace": str(engine.workspace),
        "started": started,
        "finished": finished,
        "duration_s": round(duration_s, 3),
    }


def write_manifest(path: Path, manifest: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(manifest, indent=2, sort_keys=True, default=str) + "\n")
    tmp.replace(path)


def verify_manifest(path: Path) -> list[str]:
    """Differences between a manifest and the files on disk (empty when everything matches)."""
    try:
        m = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as exc:
        return [f"{path}: not a readable manifest ({exc})"]
    if m.get("schema_version") != SCHEMA_VERSION:
        return [f"{path}: schema version {m.get('schema_version')} (this twinkit reads {SCHEMA_VERSION})"]
    problems = []
    recipe = ((m.get("config") or {}).get("recipe") or {}).get("name")
    for section in ("inputs", "outputs"):
        for e in m.get(section, []):
            p = Path(e["path"])
            if recipe:
                p = _parked(p, recipe)
            if not p.is_file():
                problems.append(f"{section[:-1]} missing: {p}")
                continue
            size = p.stat().st_size
            if size != e["size"]:
                problems.append(f"{section[:-1]} changed: {p} (size {e['size']} -> {size})")
            elif sha256_file(p) != e["sha256"]:
                problems.append(f"{section[:-1]} changed: {p} (same size, different content)")
    return problems


def _parked(path: Path, recipe: str) -> Path:
    """Where a numbered folder's file of ``recipe`` is now: in place, or parked in
    ``<site>/recipes/<recipe>/NN_step/...`` while another recipe's folders are at the top of the site, or
    in ``<site>/stale/<recipe>/NN_step/...`` once a later plan did not have the step (twinkit/engine/recipes.py)."""
    import re

    parts = path.parts
    for i in range(len(parts) - 1, 0, -1):
        if re.match(r"^\d{2,}_\w+$", parts[i]):
            try:
                owner = json.loads(Path(*parts[: i + 1], "step.json").read_text()).get("recipe")
            except (OSError, ValueError, AttributeError):
                owner = None
            if owner in (None, recipe) and path.is_file():
                return path
            safe = re.sub(r"[^\w.-]", "_", recipe) or "_"
            stale = Path(*parts[:i], "stale", safe, *parts[i:])
            if stale.is_file():  # a step the plan of a later run did not have
                return stale
            parked = Path(*parts[:i], "recipes", safe, *parts[i:])
            return parked if parked.is_file() or owner not in (None, recipe) else path
    return path


_ENV_REF = re.compile(r"\$\{oc\.env:\s*([A-Za-z_][A-Za-z0-9_]*)")


def env_secrets(raw: Any) -> dict[str, str]:
    """``{value: VAR}`` for every environment variable the config reads through ``${oc.env:VAR}``.

    ``raw`` is the config unresolved (``OmegaConf.to_container(cfg, resolve=False)``). Such values
    (tokens, passwords) are kept out of the manifest and the report: :func:`redact`.
    """
    found: dict[str, str] = {}

    def walk(node: Any) -> None:
        if isinstance(node, dict):
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)
        elif isinstance(node, str):
            for var in _ENV_REF.findall(node):
                value = os.environ.get(var)
                if value:
                    found[value] = var

    walk(raw)
    return found


#: names (never values) of the variables the run's config reads through ``${oc.env:...}``, for its processes
SECRET_VARS_ENV = "TWINKIT_SECRET_VARS"


def remember_secrets(secrets: dict[str, str]) -> None:
    """Make the config's secrets (:func:`env_secrets`) known to :func:`redact` everywhere in this process and in
    the processes it starts (steps, fan-out workers), with those known before: only the variables' names are
    stored, in the environment."""
    names = set(secrets.values()) | {v for v in os.environ.get(SECRET_VARS_ENV, "").split(",") if v}
    os.environ[SECRET_VARS_ENV] = ",".join(sorted(names))


def known_secrets() -> dict[str, str]:
    """``{value: VAR}`` of the secrets :func:`remember_secrets` made known (empty when none)."""
    names = os.environ.get(SECRET_VARS_ENV, "")
    return {os.environ[v]: v for v in names.split(",") if v and os.environ.get(v)}


def redact(obj: Any, secrets: dict[str, str] | None = None) -> Any:
    """A copy of ``obj`` with each secret value replaced by ``<from env VAR>`` (inside strings too).

    ``secrets``: the run's (:func:`env_secrets`); None = those made known (:func:`known_secrets`). The one
    redaction of twinkit: the manifest, the step records and the store's, the log and the terminal (a filter on
    the log handlers, the error line), and a plugin's own files (the roads' HTTP cache)."""
    secrets = known_secrets() if secrets is None else secrets
    if not secrets:
        return obj
    if isinstance(obj, dict):
        return {k: redact(v, secrets) for k, v in obj.items()}
    if isinstance(obj, list):
        return [redact(v, secrets) for v in obj]
    if isinstance(obj, str):
        if obj in secrets:
            return f"<from env {secrets[obj]}>"
        for value, var in sorted(secrets.items(), key=lambda kv: -len(kv[0])):
            if len(value) >= 4 and value in obj:
                obj = obj.replace(value, f"<from env {var}>")
        return obj
    return obj


class RedactingFilter:
    """A ``logging`` filter that writes every record with the secrets redacted (:func:`redact`): run.log and the
    terminal never show a value read through ``${oc.env:...}``."""

    def filter(self, record) -> bool:
        if not known_secrets():
            return True
        text = record.getMessage()
        clean = redact(text)
        if clean != text:
            record.msg, record.args = clean, None
        return True

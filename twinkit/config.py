"""Configuration: where configs live, the engine's settings, early checks of CLI choices and config values.

Everything that talks to Hydra is in :mod:`twinkit.hydra_glue`."""
from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import yaml

from twinkit.errors import ConfigError
from twinkit.plugins import COMPONENT_KINDS, STEP_KINDS, Registry
from twinkit.ranges import param


@dataclass
class EngineConfig:
    """Engine settings (``engine.<key>=...`` on the command line)."""

    outputs_dir: str = param("outputs", help="Folder that holds the runs' outputs.")
    threads: int = param(0, ge=0, help="Threads the run may use; 0 = every core.")
    interactive: str = param("auto",
                             help="Whether a manual step waits for its file (else the run stops and says what to "
                                  "provide): auto = when attached to a terminal, true or false.")
    manual_timeout_s: Optional[float] = param(None, gt=0,
                                              help="How long (s) an interactive run waits at a manual step for its "
                                                   "file; null = no limit.")
    report: bool = param(True, help="Write the run report (report.html) at the end of the run.")
    keep_reports: int = param(3, ge=0,
                              help="Reports of the newest runs kept (runs/<time>/report/); older runs keep their "
                                   "manifest and log, their report is removed at the end of a run and by "
                                   "twinkit gc. 0 = keep every report.")
    sweep_memory_gb: float = param(0.0, ge=0,
                                   help="Memory (GB) a sweep's jobs may use together: fewer jobs run at once when "
                                        "their earlier peaks say they need more; 0 = the memory available when the "
                                        "sweep starts.")
    degraded_exit_code: int = param(4, ge=0, le=125,
                                    help="Exit status of a run that finished with a degraded result (docs/engine.md "
                                         '"Quality gates"); 0 = exit 0 as for a clean run.')


def find_config_dir() -> Path:
    """``$TWINKIT_CONFIG_DIR``, else ``./conf``, else the ``conf/`` of the source checkout."""
    env = os.environ.get("TWINKIT_CONFIG_DIR")
    if env:
        return Path(env).resolve()
    cwd = Path.cwd() / "conf"
    if (cwd / "config.yaml").is_file():
        return cwd.resolve()
    here = Path(__file__).resolve().parents[1] / "conf"
    if (here / "config.yaml").is_file():
        return here
    raise ConfigError("no twinkit configuration found: run from the twinkit folder or set TWINKIT_CONFIG_DIR=<repo>/conf")


def project_root(conf_dir: Path) -> Path:
    return conf_dir.parent


def _available(folder: Path) -> list[str]:
    return sorted(p.stem for p in folder.glob("*.yaml")) if folder.is_dir() else []


def check_yaml(path: Path) -> None:
    """One-line error for YAML that does not parse."""
    try:
        yaml.load(path.read_text(), Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError(f"{path}:{where}: {problem}; fix the YAML (or restore it from git) and run again") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read ({exc.strerror})") from None


def local_outputs_dirs(overrides: list[str], conf_dir: Path) -> list[str]:
    """``engine.outputs_dir`` set by ``conf/local/<site>.yaml`` of the chosen site(s), where one sets it."""
    out = []
    for site in _chosen(overrides, conf_dir)["site"]:
        local = conf_dir / "local" / f"{site}.yaml"
        try:
            data = yaml.load(local.read_text(), Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
        except (OSError, yaml.YAMLError):
            continue
        engine = data.get("engine") if isinstance(data, dict) else None
        value = engine.get("outputs_dir") if isinstance(engine, dict) else None
        if isinstance(value, str) and value and "${" not in value:
            out.append(value)
    return out


def _chosen(overrides: list[str], conf_dir: Path) -> dict[str, list[str]]:
    """The sites and recipes a run (or each job of a sweep) uses: the command line's choice, else config.yaml's."""
    from twinkit.hydra_glue import group_choices

    chosen: dict[str, list[str]] = {"site": [], "recipe": []}
    try:
        defaults = yaml.safe_load((conf_dir / "config.yaml").read_text()).get("defaults", [])
    except (OSError, yaml.YAMLError, AttributeError):
        defaults = []
    for d in defaults:
        if isinstance(d, dict):
            for k in ("site", "recipe"):
                if k in d:
                    chosen[k] = [d[k]]
    for group in ("site", "recipe"):
        given = group_choices(overrides, group, _available(conf_dir / group))
        if given is not None:
            chosen[group] = given
    return chosen


def check_choices(overrides: list[str], conf_dir: Path) -> None:
    """Fail in one line on an unknown or empty site/recipe, and on unparsable YAML of the chosen ones."""
    check_yaml(conf_dir / "config.yaml")
    chosen = _chosen(overrides, conf_dir)
    for group, folder in (("site", conf_dir / "site"), ("recipe", conf_dir / "recipe")):
        have = _available(folder)
        for v in chosen[group]:
            if not v:
                raise ConfigError(f"no {group} given: use {group}=<name>; available: {', '.join(have)}")
            if v not in have:
                raise ConfigError(f"unknown {group} '{v}'; available: {', '.join(have) or 'none'} (in {folder})")
            check_yaml(folder / f"{v}.yaml")
    for v in chosen["site"]:
        local = conf_dir / "local" / f"{v}.yaml"
        if local.is_file():
            check_yaml(local)


def _check_site(site: dict, site_file: str | None = None) -> None:
    """The site's georeference fields are numbers in range and its CRS exists (a typo fails now, not in a
    late step)."""
    name = site.get("name", "?")
    where = site_file or f"the site file of site '{name}' (conf/site/<site>.yaml)"
    if site.get("crs"):
        from twinkit.geo.crs import parse_crs
        from twinkit.geo.frame import crs_example

        try:
            parse_crs(str(site["crs"]))
        except Exception as exc:  # noqa: BLE001 - pyproj's CRSError: an unknown code or unparsable text
            raise ConfigError(f"{where}: site.crs {site['crs']} is not a known CRS ({str(exc).splitlines()[0][:160]}); "
                              f"give an existing EPSG code in metres{crs_example(site)} or a PROJ string") from None
    bp = site.get("base_point")
    if bp is None:
        return
    if not isinstance(bp, dict):
        raise ConfigError(f"site.base_point={bp!r} is not a mapping: give {{lat, lon, alt}} or projected {{x, y, z}}")
    limits = {"lat": (-90.0, 90.0), "lon": (-180.0, 180.0)}
    for k, v in bp.items():
        if k not in ("lat", "lon", "alt", "x", "y", "z"):
            continue
        ok = isinstance(v, (int, float)) and not isinstance(v, bool) and v == v and abs(v) != float("inf")
        if not ok:
            raise ConfigError(f"site.base_point.{k}={v!r} is not a number: give it in "
                              f"{'degrees' if k in limits else 'metres (CRS units)'} in the site's file")
        if k in limits and not (limits[k][0] <= v <= limits[k][1]):
            lo, hi = limits[k]
            raise ConfigError(f"site.base_point.{k}={v} is out of range: site.base_point.{k} must be {lo:g}..{hi:g} "
                              "degrees")
    if site.get("crs"):
        from twinkit.errors import InputError
        from twinkit.geo.crs import check_base_point_area

        try:
            check_base_point_area(site, where)
        except InputError as exc:
            raise ConfigError(str(exc)) from None


_PLAIN_NAME = re.compile(r"^[\w.-]+$")


def check_site_name(name: Any, secrets: dict[str, str] | None = None) -> None:
    """``site.name`` becomes the folder ``<engine.outputs_dir>/<name>``: it must be a plain name (letters,
    digits, ``-``, ``_``, ``.``; not ``.`` or ``..``), and not a value read through ``${oc.env:...}``
    (``secrets``: twinkit.manifest.env_secrets), which a folder name would show."""
    if name is None or name == "":
        raise ConfigError("site.name: the site config has no 'name'; give the site a name in its site file")
    for value, var in (secrets or {}).items():
        if value == str(name) or (len(value) >= 4 and value in str(name)):
            raise ConfigError(f"site.name: its value comes from ${{oc.env:{var}}}, and the site's name becomes a "
                              "folder name that would show it; give the site a plain name in its site file")
    if not isinstance(name, str) or not _PLAIN_NAME.match(name) or name in (".", ".."):
        raise ConfigError(f"site.name={name!r} is not a plain name: it becomes the folder <engine.outputs_dir>/<name>; "
                          "use letters, digits, '-', '_' and '.' only (no '/', not '.' or '..')")


def check_composed_site_name(cfg) -> None:
    """:func:`check_site_name` on a composed config (a DictConfig), before anything is written under the name."""
    from omegaconf import OmegaConf

    from twinkit.hydra_glue import as_config_error, plain
    from twinkit.manifest import env_secrets

    try:
        name = OmegaConf.select(cfg, "site.name")
    except Exception as exc:  # noqa: BLE001 -- an unset ${oc.env:VAR}: the one-line configuration error
        err = as_config_error(exc)
        if err is None:
            raise
        raise err from None
    check_site_name(name, env_secrets(plain(cfg, resolve=False)))


def check_config(cfg: dict, registry: Registry, site_file: str | None = None,
                 secrets: dict[str, str] | None = None) -> None:
    """Every parameter in the composed config inside its declared range (twinkit.ranges); the site's base point
    and name (:func:`check_site_name`, with the config's ``secrets``).

    Runs before any step: ``reconstructor.depth=30`` fails here with exit 2 naming the key and the range.
    """
    from twinkit.ranges import check_values

    check_values(EngineConfig, cfg.get("engine") or {}, "engine")
    for kind in (*STEP_KINDS, *COMPONENT_KINDS):
        if kind in ("step", "site_generator"):
            continue
        node = cfg.get(kind)
        if isinstance(node, dict) and node.get("plugin") in registry.plugins.get(kind, {}):
            plugin = registry.plugins[kind][node["plugin"]]
            check_values(plugin.params, node, kind, plugin.qualname)
    for name, node in (cfg.get("steps") or {}).items():
        step = registry.plugins.get("step", {}).get(name)
        if step is not None:
            check_values(step.params, node, f"steps.{name}", step.qualname)
    site = cfg.get("site") or {}
    if isinstance(site, dict):
        gen = registry.plugins.get("site_generator", {}).get(str(site.get("generator")))
        if gen is not None:
            check_values(gen.params, site, "site", gen.qualname)
        check_site_name(site.get("name"), secrets)
        _check_site(site, site_file)


# --------------------------------------------------------------------------- configs are data

_HEADER = re.compile(r"^#\s*@package\s+(\S+)", re.M)
# what a recipe, site, sweep or local file may set under hydra: the values a sweep runs over
_HYDRA_ALLOWED = ("hydra.sweeper.params",)


def _config_files(conf_dir: Path | None, extra_dirs: list[Path]) -> list[tuple[Path, str]]:
    """Every YAML file Hydra could load besides the root config (``conf_dir/config.yaml``), with its group
    (``site``, ``recipe``, ...)."""
    out = []
    for base in [conf_dir, *extra_dirs]:
        if base is None or not base.is_dir():
            continue
        for folder, _dirs, files in os.walk(base, followlinks=True):
            rel = Path(folder).relative_to(base)
            for f in sorted(files):
                if f.endswith((".yaml", ".yml")) and not (base == conf_dir and rel == Path(".") and f == "config.yaml"):
                    out.append((Path(folder) / f, rel.as_posix() if str(rel) != "." else ""))
    return out


def _targets(node: Any, path: str) -> str | None:
    if isinstance(node, dict):
        for k, v in node.items():
            here = f"{path}.{k}" if path else str(k)
            if k == "_target_":
                return here
            found = _targets(v, here)
            if found:
                return found
    elif isinstance(node, list):
        for i, v in enumerate(node):
            found = _targets(v, f"{path}[{i}]")
            if found:
                return found
    return None


def _hydra_keys(node: Any, path: str) -> str | None:
    """The first key under ``hydra`` that is not a sweep's parameter list."""
    if any(path == a or path.startswith(a + ".") for a in _HYDRA_ALLOWED):
        return None
    if not isinstance(node, dict) or not node:
        return path
    for k, v in node.items():
        found = _hydra_keys(v, f"{path}.{k}")
        if found:
            return found
    return None


def config_file_problem(path: Path, group: str) -> str | None:
    """Why a recipe, site, sweep or local config file may not be used (it could run code), or None."""
    text = path.read_text(errors="replace")
    if group == "hydra" or group.startswith("hydra/"):
        return "it is a Hydra config group (hydra/...): recipes and sites cannot add launchers or callbacks"
    try:
        data = yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    except yaml.YAMLError:
        return None  # check_yaml reports it where the file is used
    if not isinstance(data, dict):
        return None
    target = _targets(data, "")
    if target:
        return f"it sets '{target}': a config file is data and cannot name Python objects to call"
    for entry in data.get("defaults") or []:
        names = [entry] if isinstance(entry, str) else list(entry) if isinstance(entry, dict) else []
        for n in names:
            g = str(n).replace("override", "").strip().lstrip("/")
            if g == "hydra" or g.startswith("hydra/"):
                return f"its defaults choose '{str(n).strip()}': recipes and sites cannot change Hydra's launcher, " \
                       "callbacks or logging"
    m = _HEADER.search(text)
    package = m.group(1) if m else "_group_"
    package = package.replace("_group_", group.replace("/", ".")) if group else package.replace("_group_", "")
    if package.startswith("_global_"):
        package = package[len("_global_"):].lstrip(".")
    root: dict = {}
    node: dict = root
    parts = [p for p in package.split(".") if p]
    for p in parts[:-1]:
        node = node.setdefault(p, {})
    if parts:
        node[parts[-1]] = {k: v for k, v in data.items() if k != "defaults"}
    else:
        root = {k: v for k, v in data.items() if k != "defaults"}
    if "hydra" in root:
        bad = _hydra_keys(root["hydra"], "hydra")
        if bad:
            return f"it sets '{bad}': recipes, sites and sweeps may set only {', '.join(_HYDRA_ALLOWED)} under hydra"
    return None


#: the opt-in (``TWINKIT_ALLOW_CODE=1``) that lets the command line make Hydra run code; a run records it
ALLOW_CODE_ENV = "TWINKIT_ALLOW_CODE"
# what a command-line override may set under hydra: where outputs go, a sweep's values, the launcher's settings
_CLI_HYDRA_ALLOWED = ("hydra.run.", "hydra.sweep.", "hydra.sweeper.params", "hydra.job.chdir", "hydra.job.name",
                      "hydra.launcher.", "hydra.verbose", "hydra.output_subdir", "hydra.mode")
_DIR_OPTIONS = {"--config-dir": "--config-dir", "-cd": "--config-dir", "--config-path": "--config-path",
                "-cp": "--config-path"}


_TARGET_KEY = re.compile(r"(^|[{,\s])['\"]?_target_['\"]?\s*:")  # a '_target_' key inside a dict value


def code_allowed() -> bool:
    """Whether ``TWINKIT_ALLOW_CODE=1`` lets the command line name code for Hydra to run (recorded in the manifest)."""
    return os.environ.get(ALLOW_CODE_ENV, "") == "1"


def check_configs_are_data(conf_dir: Path, argv: list[str] | None = None) -> None:
    """Refuse (exit 2, naming the file or the override) a config file or a command line that could make Hydra run
    code.

    Only the root ``config.yaml`` may set Hydra callbacks and the launcher; any other file that sets
    ``_target_``, ``hydra.callbacks``, ``hydra.launcher`` (anything under ``hydra`` but a sweep's
    ``hydra.sweeper.params``) or picks a ``hydra/...`` group is refused before Hydra reads it. The
    folders of ``--config-dir``/``-cd`` and ``--config-path``/``-cp`` are checked too (``config.yaml`` there
    included: it would replace the root config), and so are the command line's overrides
    (:func:`override_problem`); ``TWINKIT_ALLOW_CODE=1`` lifts the checks of what the command line gives.
    """
    argv = list(argv or [])
    for path, group in _config_files(conf_dir, []):
        why = _safe_problem(path, group)
        if why:
            raise ConfigError(f"{path}: refused, {why}; remove it (only {conf_dir / 'config.yaml'} configures Hydra)")
    if code_allowed():
        return
    rerun = next((a for a in argv if a.split("=", 1)[0] == "--experimental-rerun"), None)
    if rerun:
        raise ConfigError(f"command line: {rerun}: refused, it makes Hydra load a pickled config, and a pickle can "
                          f"run code; run with overrides instead (or set {ALLOW_CODE_ENV}=1)")
    for path, group in _config_files(None, _option_dirs(argv)):
        why = _safe_problem(path, group)
        if why:
            raise ConfigError(f"{path}: refused, {why}; a folder given with --config-dir or --config-path is data "
                              f"(another root config: TWINKIT_CONFIG_DIR=<its folder>; or set {ALLOW_CODE_ENV}=1)")
    for a in argv:
        why = None if a.startswith("-") else override_problem(a)
        if why:
            raise ConfigError(f"command line: {a}: refused, {why}; a command line is data like a config file (set "
                              f"{ALLOW_CODE_ENV}=1 to allow it; the run's manifest records that)")


def _option_dirs(argv: list[str]) -> list[Path]:
    """The folders ``--config-dir`` and ``--config-path`` name (a ``pkg://`` source cannot be read: refused)."""
    out = []
    for i, a in enumerate(argv):
        opt, _, value = a.partition("=")
        if opt not in _DIR_OPTIONS or (not value and i + 1 >= len(argv)):
            continue
        value = value or argv[i + 1]
        if value.startswith("pkg://"):
            raise ConfigError(f"{_DIR_OPTIONS[opt]} {value}: refused, a package's configs cannot be checked for "
                              f"code; give a folder (or set {ALLOW_CODE_ENV}=1)")
        out.append(Path(value.removeprefix("file://")).resolve())
    return out


def override_problem(override: str) -> str | None:
    """Why a command-line override could make Hydra run code, or None: a ``_target_`` anywhere, a ``hydra/...``
    group (launcher, callbacks, logging), or a ``hydra.`` key other than where outputs go, a sweep's values
    and the launcher's settings (``hydra.run.dir``, ``hydra.sweep.dir``, ``hydra.job.chdir``,
    ``hydra.launcher.n_jobs``...)."""
    key, _, value = override.partition("=")
    key = key.lstrip("+~").split("@", 1)[0].strip()
    if "_target_" in key.split(".") or _TARGET_KEY.search(value):
        return "it names '_target_', a Python object for Hydra to call"
    if key == "hydra" or key.startswith("hydra/"):
        return f"it chooses the Hydra config group '{key}' (launcher, callbacks or logging)"
    if key.startswith("hydra.") and not any(key.startswith(a) if a.endswith(".") else key == a or key.startswith(a + ".")
                                            for a in _CLI_HYDRA_ALLOWED):
        return f"it sets '{key}'; the command line may set only {', '.join(a + '*' if a.endswith('.') else a for a in _CLI_HYDRA_ALLOWED)} " \
               "under hydra"
    return None


def _safe_problem(path: Path, group: str) -> str | None:
    try:
        return config_file_problem(path, group)
    except OSError as exc:
        return f"cannot read it ({exc.strerror})"

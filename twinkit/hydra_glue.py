"""Every contact twinkit has with Hydra (and OmegaConf's loader), through Hydra's public API only.

- command-line overrides are read with Hydra's own parser (:func:`parse_overrides`, :func:`group_choices`,
  :func:`override_value`), never with regular expressions;
- a config is composed with ``hydra.initialize_config_dir`` + ``hydra.compose`` (:func:`compose`), and
  Hydra's and OmegaConf's composition errors become one-line :class:`~twinkit.errors.ConfigError`\\ s
  (:func:`composition_error`);
- a sweep's jobs are enumerated from the parsed overrides as Hydra's basic sweeper does (:func:`sweep_jobs`),
  so every job can be checked before the first one starts;
- options (``--cfg``, ``--help``, ``-m``) run Hydra's app from ``hydra.main`` (:func:`run_app`) with
  ``HYDRA_FULL_ERROR=1`` (Hydra's documented switch: it raises instead of printing and exiting 1), so
  twinkit reports the error with its own exit status;
- a job reads its runtime state from ``HydraConfig`` (:func:`job_state`), and a multirun job's error travels
  to the sweep's process with its exit status (:func:`job_error`);
- plugins' parameters are stored in Hydra's ``ConfigStore`` (:func:`register_configs`).

``hydra-core`` is pinned to a range (pyproject.toml), not to one version.
"""
from __future__ import annotations

import dataclasses
import functools
import itertools
import os
import sys
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, List

from twinkit.errors import ConfigError

#: the Hydra behaviour twinkit's configs are written for
VERSION_BASE = "1.3"
CONFIG_NAME = "config"
JOB_NAME = "twinkit"


# --------------------------------------------------------------------------- overrides


def parse_overrides(overrides: list[str]) -> list:
    """``key=value`` strings as Hydra's ``Override`` objects; raises Hydra's OverrideParseException."""
    return _parser().parse_overrides(list(overrides))


@functools.lru_cache(maxsize=1)
def _parser():
    from hydra.core.override_parser.overrides_parser import OverridesParser

    return OverridesParser.create()


@functools.lru_cache(maxsize=16)
def _parsed(overrides: tuple[str, ...]) -> tuple | None:
    from hydra.errors import HydraException

    try:
        return tuple(parse_overrides(list(overrides)))
    except (HydraException, ValueError, TypeError):
        return None


def _parsed_or_none(overrides: list[str]) -> tuple | None:
    """The parsed overrides, or None when they do not parse (composition reports that, in Hydra's words).
    Parsed once per list: a run reads the same command line several times before it composes."""
    return _parsed(tuple(overrides))


def group_choices(overrides: list[str], group: str, options: list[str]) -> list[str] | None:
    """The options of config group ``group`` (``site``, ``recipe``) the overrides choose, or None when they
    choose none. A sweep gives each of its values (``site=a,b``, ``choice(a,b)``, ``glob(a*)`` matched
    against ``options``); ``site=`` gives ``[""]``. The last choice wins, as in Hydra."""
    parsed = _parsed_or_none(overrides)
    chosen = None
    for o in parsed or []:
        if o.key_or_group != group or o.package is not None or o.is_delete():
            continue
        if o.value_type is not None and o.value_type.name == "GLOB_CHOICE_SWEEP":
            chosen = o.value().filter(list(options))
        elif o.is_discrete_sweep():
            chosen = [_text(v).strip() for v in o.sweep_iterator()]
        else:
            chosen = [_text(o.value()).strip()]
    return chosen


def _text(value: Any) -> str:
    """An override's value as the user typed it, unquoted (``'a b'`` -> ``a b``)."""
    value = getattr(value, "text", value)  # a QuotedString inside a sweep
    return "" if value is None else str(value)


def override_value(overrides: list[str], key: str) -> str | None:
    """The value the last plain (not swept, not deleted) override of ``key`` sets, as a string, or None."""
    value = None
    for o in _parsed_or_none(overrides) or []:
        if o.key_or_group == key and not o.is_delete() and not o.is_sweep_override():
            value = _text(o.value())
    return value


def options_first(argv: list[str]) -> list[str]:
    """Hydra's parser wants options before overrides; accept them in any order."""
    opts: list[str] = []
    overrides: list[str] = []
    i = 0
    while i < len(argv):
        a = argv[i]
        if a.startswith("-") and "=" not in a.split(" ")[0][:2]:
            opts.append(a)
            if a in _VALUE_OPTIONS and i + 1 < len(argv) and not argv[i + 1].startswith("-") and "=" not in argv[i + 1]:
                opts.append(argv[i + 1])
                i += 1
        else:
            overrides.append(a)
        i += 1
    return opts + overrides


_VALUE_OPTIONS = {"--cfg", "-c", "--package", "-p", "--info", "-i", "--config-path", "-cp", "--config-name", "-cn",
                  "--config-dir", "-cd", "--experimental-rerun", "--shell-completion", "-sc"}


def open_site_inputs(args: list[str]) -> list[str]:
    """``site.inputs.<name>=value`` adds the input when the site file does not list it.

    Site inputs are open-ended (a recipe may want photos, a GCP file, an OSM extract...), so a
    plain override adds or replaces the key (Hydra's ``++``); every other key stays strict, so a
    misspelled ``site.sede=3`` still fails at composition. A value with letters outside ASCII
    (``site.inputs.cloud=straße.ply``), which Hydra's grammar refuses unquoted, is quoted for it.
    """
    return [_quoted_if_needed(("++" + a) if a.startswith("site.inputs.") and "=" in a else a) for a in args]


def _quoted_if_needed(arg: str) -> str:
    """``key=value`` with ``value`` single-quoted when it holds non-ASCII letters and only parses so (a sweep,
    ``a,b`` or ``choice(...)``, is left to Hydra: quoted it would be one value)."""
    key, sep, value = arg.partition("=")
    if (arg.startswith("-") or not sep or value.isascii() or value[:1] in ("'", '"')
            or any(c in value for c in ",()[]{}") or _parsed((arg,))):
        return arg
    quoted = f"{key}='" + value.replace("'", "\\'") + "'"
    return quoted if _parsed((quoted,)) else arg


# --------------------------------------------------------------------------- composing


def compose(conf_dir: Path, overrides: list[str], hydra_config: bool = False):
    """The root config of ``conf_dir`` composed with ``overrides`` (a DictConfig; with the ``hydra`` node
    when ``hydra_config``). A composition error is a one-line ConfigError."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from twinkit.manifest import env_secrets, remember_secrets

    try:
        with initialize_config_dir(config_dir=str(conf_dir), version_base=VERSION_BASE, job_name=JOB_NAME):
            cfg = hydra_compose(config_name=CONFIG_NAME, overrides=list(overrides), return_hydra_config=hydra_config)
    except (HydraException, OmegaConfBaseException) as exc:
        raise composition_error(exc) from None
    remember_secrets(env_secrets(plain(cfg, resolve=False)))  # no message from here on shows them
    return cfg


def set_run_config(cfg) -> None:
    """Make a config composed with ``hydra_config=True`` the current run's (``${hydra:...}`` resolves)."""
    from hydra.core.hydra_config import HydraConfig

    HydraConfig.instance().set_config(cfg)


def plain(node, resolve: bool = True) -> dict:
    """A mapping config node (DictConfig) as a plain dict (OmegaConf.to_container), typed as one. A value
    that does not resolve (an unset ``${oc.env:VAR}``, a missing ``${key}``) is a one-line ConfigError."""
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    try:
        out = OmegaConf.to_container(node, resolve=resolve)
    except OmegaConfBaseException as exc:
        raise composition_error(exc) from None
    if not isinstance(out, dict):
        raise TypeError(f"not a mapping config node: {type(out).__name__}")
    return out


def without_hydra(cfg):
    """A job's composed config without its ``hydra`` node (a copy when it had one; else ``cfg`` itself)."""
    from omegaconf import open_dict

    if "hydra" in cfg:
        cfg = cfg.copy()
        with open_dict(cfg):
            del cfg["hydra"]
    return cfg


def composition_error(exc: Exception) -> ConfigError:
    """Hydra/OmegaConf composition errors, folded into one line (an unset ``${oc.env:VAR}`` named with its key)."""
    import re

    env = re.search(r"Environment variable '([^']+)' not found", str(exc))
    if env:
        key = getattr(exc, "full_key", None) or "the config"
        return ConfigError(f"{key}: the environment variable {env.group(1)} is not set (the config reads it with "
                           f"${{oc.env:{env.group(1)}}}); set it (export {env.group(1)}=...) or give {key} a value")
    from omegaconf.errors import InterpolationResolutionError

    if isinstance(exc, InterpolationResolutionError) and getattr(exc, "full_key", None):
        return ConfigError(f"{exc.full_key}: {str(exc).splitlines()[0].rstrip('.')}; fix the ${{...}} reference "
                           f"in its config file (twinkit --cfg job shows the composed config)")
    # Hydra's MissingConfigException lists the options in its message: say it as twinkit says an unknown plugin
    m = re.search(r"Could not find '([\w/]+)/([^']+)'\s*\nAvailable options in '[^']+':\s*\n(.*?)\nConfig search path",
                  str(exc), re.S)
    if m:
        options = ", ".join(o.strip() for o in m.group(3).splitlines() if o.strip()) or "none"
        return ConfigError(f"no {m.group(1).split('/')[-1]} plugin named '{m.group(2)}' (available: {options}); "
                           f"install the package that provides it, or check TWINKIT_PLUGINS")
    parts = [str(exc)]
    if exc.__cause__ is not None and str(exc.__cause__) not in parts[0]:
        parts.append(str(exc.__cause__))
    lines = []
    for part in parts:
        for line in part.splitlines():
            t = line.strip()
            if t and not t.startswith(("full_key", "object_type", "reference_type", "To append", "Set the environment")):
                lines.append(t.rstrip("."))
    return ConfigError(". ".join(dict.fromkeys(lines)))


def as_config_error(exc: BaseException) -> ConfigError | None:
    """A Hydra or OmegaConf configuration error (one raised outside :func:`compose`, e.g. reading a value of
    the composed config) as the one-line ConfigError a composition error gives; None for any other error."""
    return composition_error(exc) if isinstance(exc, Exception) and _is_composition_error(exc) else None


def _is_composition_error(exc: BaseException) -> bool:
    from hydra.errors import ConfigCompositionException, MissingConfigException, OverrideParseException
    from omegaconf.errors import OmegaConfBaseException

    return isinstance(exc, (ConfigCompositionException, MissingConfigException, OverrideParseException,
                            OmegaConfBaseException))


# --------------------------------------------------------------------------- sweeps


def sweep_jobs(conf_dir: Path, overrides: list[str]) -> list[list[str]] | None:
    """The override list of every job of a multirun, in Hydra's order: the sweep file's
    ``hydra.sweeper.params`` then the command line, each discrete sweep (``a=1,2``, ``range(..)``,
    ``choice(..)``) multiplied out as Hydra's basic sweeper does. None when the overrides do not parse or
    compose, or a sweep cannot be enumerated here (an interval, a glob): Hydra reports those itself."""
    from hydra.errors import HydraException
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    try:
        parsed = parse_overrides(overrides)
        fixed = [o.input_line for o in parsed if o.input_line is not None and not o.is_sweep_override()
                 and not o.key_or_group.startswith("hydra")]
        base = compose(conf_dir, fixed, hydra_config=True)
        node = base.hydra.sweeper.get("params")
        params = OmegaConf.to_container(node, resolve=False) if node is not None else {}
        if not isinstance(params, dict):
            return None
        combined = parse_overrides(["=".join((str(k), str(v))) for k, v in params.items()] + list(overrides))
    except (ConfigError, HydraException, OmegaConfBaseException, ValueError, TypeError, AttributeError):
        return None
    per_key: dict[str, list[str]] = {}
    for o in combined:
        key = o.get_key_element()
        if not o.is_sweep_override():
            per_key[key] = [f"{key}={o.get_value_element_as_str()}"]
        elif o.is_discrete_sweep() and o.value_type.name != "GLOB_CHOICE_SWEEP":
            per_key[key] = [f"{key}={v}" for v in o.sweep_string_iterator()]
        else:
            return None
    return [list(job) for job in itertools.product(*per_key.values())]


# --------------------------------------------------------------------------- Hydra's app and its jobs


def run_app(conf_dir: Path, argv: list[str], job: Callable[[Any], Any]) -> None:
    """Run ``job`` through Hydra's app (``hydra.main``) with ``argv``: options such as ``--cfg``, ``--help``
    and ``-m`` (a sweep, run by the configured launcher). An error with an ``exit_code`` (a job's
    :func:`job_error`) prints its message and exits with that status; a composition error is a one-line
    ConfigError (exit 2); anything else prints its traceback and exits 1."""
    import hydra

    app = hydra.main(config_path=str(conf_dir), config_name=CONFIG_NAME, version_base=VERSION_BASE)(job)
    saved_argv, saved_full = sys.argv, os.environ.get("HYDRA_FULL_ERROR")
    sys.argv = ["twinkit", *argv]
    os.environ["HYDRA_FULL_ERROR"] = "1"  # Hydra raises the error instead of printing it and exiting 1
    try:
        app()
    except Exception as exc:  # noqa: BLE001 -- sorted below
        code = getattr(exc, "exit_code", None)
        if isinstance(code, int):
            print(str(exc), file=sys.stderr)
            raise SystemExit(code) from None
        if _is_composition_error(exc):
            raise composition_error(exc) from None
        from twinkit.sweeps import broken_pool

        if broken_pool(exc):  # a pool worker itself was killed: one line, not loky's traceback
            print(broken_pool(exc), file=sys.stderr)
            raise SystemExit(1) from None
        traceback.print_exception(exc)
        raise SystemExit(1) from None
    finally:
        sys.argv = saved_argv
        if saved_full is None:
            os.environ.pop("HYDRA_FULL_ERROR", None)
        else:
            os.environ["HYDRA_FULL_ERROR"] = saved_full


@dataclass(frozen=True)
class JobState:
    """What a job run by Hydra's app knows of itself."""

    multirun: bool
    output_dir: Path         # the job's folder (hydra.runtime.output_dir)
    overrides: List[str] = field(default_factory=list)   # the job's own overrides (hydra.overrides.task)
    n_jobs: int = 1          # the launcher's concurrent jobs (joblib's n_jobs; <= 0: as many as cores)
    num: int = 0             # the job's number in the sweep


def is_multirun() -> bool:
    """Whether the job running now is one job of a sweep (``-m``)."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    return HydraConfig.get().mode == RunMode.MULTIRUN


def job_state() -> JobState:
    """The running job's :class:`JobState`, read from ``HydraConfig``."""
    from hydra.core.hydra_config import HydraConfig
    from omegaconf import OmegaConf

    hc = HydraConfig.get()
    multirun = is_multirun()
    n_jobs = int(OmegaConf.select(hc, "launcher.n_jobs", default=1) or 1) if multirun else 1  # type: ignore[arg-type]  # a DictConfig
    return JobState(multirun=multirun, output_dir=Path(hc.runtime.output_dir), overrides=list(hc.overrides.task),
                    n_jobs=n_jobs, num=int(hc.job.num or 0) if multirun else 0)


def job_error(message: str, exit_code: int):
    """A multirun job's error, carried to the sweep's process with its exit status (see :func:`run_app`)."""
    from hydra.errors import CompactHydraException

    class TwinkitJobError(CompactHydraException):
        exit_code: int

        def __reduce__(self):
            return job_error, (self.args[0], self.exit_code)

    err = TwinkitJobError(message)
    err.exit_code = exit_code
    return err


# --------------------------------------------------------------------------- the plugins' parameters


def _with_plugin_field(plugin_name: str, params: type | None) -> type:
    base = (params,) if params is not None else ()
    return dataclasses.make_dataclass(
        f"{(params.__name__ if params else 'NoParams')}_{plugin_name}",
        [("plugin", str, field(default=plugin_name))],
        bases=base,
    )


def register_configs(registry) -> None:
    """Put every plugin's parameters into Hydra's ConfigStore (typos fail at composition)."""
    from hydra.core.config_store import ConfigStore

    from twinkit.config import EngineConfig
    from twinkit.plugins import COMPONENT_KINDS, STEP_KINDS

    cs = ConfigStore.instance()
    for kind in (*STEP_KINDS, *COMPONENT_KINDS):
        if kind in ("step", "site_generator"):
            continue
        for name, plugin in registry.plugins[kind].items():
            cs.store(group=kind, name=name, node=_with_plugin_field(name, plugin.params))
        if kind in STEP_KINDS:
            # '<kind>=none' chooses no plugin: the steps using the kind are left out (twinkit/engine/plan.py NONE)
            cs.store(group=kind, name="none", node=_with_plugin_field("none", None))
    steps_fields = []
    for name, plugin in sorted(registry.plugins["step"].items()):
        if plugin.params is not None:
            steps_fields.append((name, plugin.params, field(default_factory=plugin.params)))
    Steps = dataclasses.make_dataclass("Steps", steps_fields)

    Base = dataclasses.make_dataclass("TwinkitBase", [
        ("engine", EngineConfig, field(default_factory=EngineConfig)),
        ("steps", Steps, field(default_factory=Steps)),
        ("rerun", List[str], field(default_factory=list)),
        ("site", Any, None),
        ("recipe", Any, None),
    ] + [(kind, Any, None) for kind in (*STEP_KINDS, *COMPONENT_KINDS) if kind not in ("step", "site_generator")])
    cs.store(name="twinkit_base", node=Base)


# --------------------------------------------------------------------------- OmegaConf's YAML loader


def use_libyaml() -> bool:
    """Make OmegaConf (and so Hydra) parse YAML with libyaml's C parser, same rules as its own loader.

    OmegaConf's loader is PyYAML's pure-Python SafeLoader plus a duplicate-key check and a
    float resolver; both live on the class, so a subclass with the C parser keeps them. Parsing a
    long recipe gets several times faster. Returns False where PyYAML was built without libyaml.
    (The one place twinkit replaces a function of OmegaConf's: ``omegaconf._utils.get_yaml_loader``;
    ``tests/test_config.py`` checks the loader still gives OmegaConf's results.)
    """
    import yaml
    import yaml.cyaml
    from omegaconf import _utils, basecontainer

    if getattr(_utils, "_twinkit_libyaml", False):
        return True
    if not getattr(yaml, "__with_libyaml__", False):
        return False
    base = _utils.get_yaml_loader()

    class CLoader(yaml.cyaml.CParser, base):  # type: ignore[misc, valid-type]
        def __init__(self, stream):
            yaml.cyaml.CParser.__init__(self, stream)
            yaml.constructor.SafeConstructor.__init__(self)
            yaml.resolver.Resolver.__init__(self)

    _utils.get_yaml_loader = lambda: CLoader
    basecontainer.get_yaml_loader = _utils.get_yaml_loader
    setattr(_utils, "_twinkit_libyaml", True)  # noqa: B010 -- a mark on omegaconf's module (read above)
    return True

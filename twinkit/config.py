"""Configuration: where configs live, structured configs from plugins, early checks of CLI choices."""
from __future__ import annotations

import dataclasses
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, List, Optional

import yaml

from twinkit.errors import ConfigError
from twinkit.plugins import COMPONENT_KINDS, STEP_KINDS, Registry


@dataclass
class EngineConfig:
    """Engine settings (``engine.<key>=...`` on the command line)."""

    outputs_dir: str = "outputs"
    threads: int = 0  # 0 = every core
    interactive: str = "auto"  # auto (a terminal) | true | false
    manual_timeout_s: Optional[float] = None
    report: bool = True


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


def use_libyaml() -> bool:
    """Make OmegaConf (and so Hydra) parse YAML with libyaml's C parser, same rules as its own loader.

    OmegaConf's loader is PyYAML's pure-Python SafeLoader plus a duplicate-key check and a
    float resolver; both live on the class, so a subclass with the C parser keeps them. Parsing a
    long recipe gets several times faster. Returns False where PyYAML was built without libyaml.
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
    _utils._twinkit_libyaml = True
    return True


def _with_plugin_field(plugin_name: str, params: type | None) -> type:
    base = (params,) if params is not None else ()
    return dataclasses.make_dataclass(
        f"{(params.__name__ if params else 'NoParams')}_{plugin_name}",
        [("plugin", str, field(default=plugin_name))],
        bases=base,
    )


def register_configs(registry: Registry) -> None:
    """Put every plugin's parameters into Hydra's ConfigStore (typos fail at composition)."""
    from hydra.core.config_store import ConfigStore

    cs = ConfigStore.instance()
    for kind in (*STEP_KINDS, *COMPONENT_KINDS):
        if kind in ("step", "site_generator"):
            continue
        for name, plugin in registry.plugins[kind].items():
            cs.store(group=kind, name=name, node=_with_plugin_field(name, plugin.params))
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


_CHOICE = re.compile(r"^(\+{0,2})(site|recipe)=(.*)$")


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


def check_choices(overrides: list[str], conf_dir: Path) -> None:
    """Fail in one line on an unknown or empty site/recipe, and on unparsable YAML of the chosen ones."""
    check_yaml(conf_dir / "config.yaml")
    chosen: dict[str, list[str]] = {"site": [], "recipe": []}
    defaults = yaml.safe_load((conf_dir / "config.yaml").read_text()).get("defaults", [])
    for d in defaults:
        if isinstance(d, dict):
            for k in ("site", "recipe"):
                if k in d:
                    chosen[k] = [d[k]]
    for ov in overrides:
        m = _CHOICE.match(ov)
        if not m:
            continue
        group, value = m.group(2), m.group(3)
        value = re.sub(r"^(choice|glob)\((.*)\)$", r"\2", value)
        chosen[group] = [v.strip() for v in value.split(",")]
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

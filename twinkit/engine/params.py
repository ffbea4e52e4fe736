"""A plugin's parameters: its dataclass defaults with the config's and the recipe's layers merged over them.

Plain values (bool, int, float, str, lists of them, optional) build the dataclass directly; anything else
goes through OmegaConf, which checks the types. Unknown keys and wrong types fail naming the plugin."""
from __future__ import annotations

import dataclasses
import json
from typing import Any

from twinkit.errors import ConfigError
from twinkit.plugins import Plugin


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
        _check_ranges(plugin, fast, where)
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
    _check_ranges(plugin, obj, where)
    return obj, _params_to_dict(obj)


def _check_ranges(plugin: Plugin, obj: Any, where: str) -> None:
    """Every value inside its declared range (twinkit.ranges), else one line naming the step and key."""
    from twinkit.ranges import check_values

    try:
        check_values(plugin.params, obj, "", plugin.qualname)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None

"""Every parameter a user can set carries its help (``param(..., help=...)``), which ``twinkit plugins`` prints.

The help says what a value does, its unit and its special values; measurements and their history live in
the stage's docs page ("Parameter decisions"), not in the code.
"""
from __future__ import annotations

import dataclasses
import typing

import pytest

from twinkit.config import EngineConfig
from twinkit.ranges import _nested, check_of, check_values, help_of, param



def _without_help(cls: type, prefix: str = "") -> list[str]:
    """Names of the fields of ``cls`` (nested option groups walked) that have no help."""
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        sub = _nested(hints.get(f.name, typing.Any))
        if sub is not None:
            out += _without_help(sub, f"{prefix}{f.name}.")
        elif not help_of(f).strip():
            out.append(prefix + f.name)
    return out


def _plugins():
    from twinkit.plugins import get_registry

    plugins = [p for p in get_registry().all() if p.params is not None]
    assert len(plugins) > 40, "the plugins were not loaded"
    return plugins


def test_every_parameter_of_every_converted_plugin_has_help():
    """A new parameter without ``help=`` fails here, naming the plugin and the field."""
    missing = [f"{p.qualname}: {name}" for p in _plugins() for name in _without_help(p.params)]
    missing += [f"engine: {name}" for name in _without_help(EngineConfig)]
    assert not missing, ("parameters without help (twinkit.ranges.param(..., help=...); one or two sentences: "
                         "what it does, unit, special values):\n" + "\n".join(missing))



def test_a_free_field_carries_help_and_no_check():
    @dataclasses.dataclass
    class P:
        names: list[str] = param(default_factory=lambda: ["a"], free=True, help="names")
        where: typing.Optional[str] = param(None, free=True, help="an address")
        flag: bool = param(True, help="a flag")

    fields = {f.name: f for f in dataclasses.fields(P)}
    assert [help_of(fields[k]) for k in ("names", "where", "flag")] == ["names", "an address", "a flag"]
    assert all(check_of(f) is None for f in fields.values())
    check_values(P, {"names": ["x", "y z"], "where": "tcp://host:8786", "flag": False}, "p")
    assert P().names == ["a"] and P().names is not P().names
    with pytest.raises(TypeError):
        param(1.0, ge=0, free=True)

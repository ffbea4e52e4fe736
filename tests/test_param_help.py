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

#: plugins whose parameters still keep their documentation in ``#`` comments (issue 43 item 5, converted by
#: the helpers that own those files); remove a plugin from here once it is converted: the test below fails
#: when one of these already has help on every field
TO_CONVERT = frozenset({
    # twinkit-roads: scan.py, plugin.py (align, evidence, signals, overview)
    "road_source/scan", "step/align_roads", "step/apply_alignment", "step/roads_overview",
    "step/road_evidence", "step/place_signals",
    # twinkit-photo
    "step/sfm", "step/georeference", "step/roi", "step/dense", "step/photo_texture",
    # twinkit-export: lift_step.py
    "step/lift_movables",
})


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
    missing = [f"{p.qualname}: {name}" for p in _plugins() if p.qualname not in TO_CONVERT
               for name in _without_help(p.params)]
    missing += [f"engine: {name}" for name in _without_help(EngineConfig)]
    assert not missing, ("parameters without help (twinkit.ranges.param(..., help=...); one or two sentences: "
                         "what it does, unit, special values):\n" + "\n".join(missing))


def test_plugins_still_to_convert():
    """Skipped while some plugins keep their help in comments; fails once one of them is done but still listed."""
    qualnames = {p.qualname for p in _plugins()}
    done = sorted(q for q in TO_CONVERT & qualnames
                  if not _without_help(next(p for p in _plugins() if p.qualname == q).params))
    assert not done, f"these plugins have help on every parameter now; remove them from TO_CONVERT: {done}"
    unknown = sorted(TO_CONVERT - qualnames)
    assert not unknown, f"TO_CONVERT names plugins that are not registered: {unknown}"
    pytest.skip(f"parameter help not checked yet for {len(TO_CONVERT)} plugins: {', '.join(sorted(TO_CONVERT))}")


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

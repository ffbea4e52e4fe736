"""Every plugin parameter declares its valid values (twinkit.ranges), and the config is checked before any step."""
from __future__ import annotations

import dataclasses

import pytest

from twinkit.errors import ConfigError
from twinkit.ranges import Choices, Range, check_values, param, undeclared


def test_every_number_of_every_registered_plugin_declares_its_range():
    """A new int/float parameter without param(..., ge=/gt=/le=/lt=) fails here, naming it."""
    from twinkit.plugins import get_registry

    reg = get_registry()
    missing = []
    n = 0
    for plugin in reg.all():
        if plugin.params is None:
            continue
        n += 1
        missing += [f"{plugin.qualname}: {name}" for name in undeclared(plugin.params)]
    assert n > 40, "the plugins were not loaded"
    assert not missing, "parameters without a declared range (twinkit.ranges.param):\n" + "\n".join(missing)


def test_every_default_lies_inside_its_own_range():
    from twinkit.plugins import get_registry

    with_params = [p for p in get_registry().all() if p.params is not None]
    assert len(with_params) > 40, "the plugins were not loaded"
    for plugin in with_params:
        check_values(plugin.params, plugin.params(), plugin.kind, plugin.qualname)


@dataclasses.dataclass
class _P:
    depth: int = param(11, ge=2, le=14)
    radius_m: float = param(-1.0, gt=0, also=(-1,))
    heights_m: list[float] = param(default_factory=lambda: [1.5], gt=0)
    mode: str = param("a", choices=("a", "b"))
    free: float = param(0.0)
    name: str = param("", pattern=r"\w*", words="one word")


@pytest.mark.parametrize("key,value,says", [
    ("depth", 30, "x.depth=30 is out of range: x.depth must be 2..14"),
    ("depth", 0, "2..14"),
    ("radius_m", -2.0, "must be -1 or > 0"),
    ("radius_m", 0.0, "-1 or > 0"),
    ("heights_m", [1.0, -3.0], "x.heights_m=-3.0 is out of range: x.heights_m (each element) must be > 0"),
    ("mode", "c", "x.mode='c' is not allowed: x.mode must be one of 'a', 'b'"),
    ("name", "a b\n#x", "x.name='a b\\n#x' is not allowed: x.name must be one word"),
    ("depth", float("nan"), "2..14"),
])
def test_a_value_outside_names_the_key_and_the_range(key, value, says):
    with pytest.raises(ConfigError) as e:
        check_values(_P, {key: value}, "x")
    assert says in str(e.value)


def test_values_inside_pass_and_undeclared_numbers_are_listed():
    check_values(_P, {"depth": 2, "radius_m": -1, "heights_m": [0.1], "mode": "b", "free": -1e9}, "x")
    assert Range(lo=0, lo_open=True).describe() == "> 0" and Choices(("a",)).describe() == "one of 'a'"

    @dataclasses.dataclass
    class Bare:
        n: int = 1
        s: str = ""

    assert list(undeclared(Bare)) == ["n"]

"""What values a parameter accepts: a range for numbers, a list for strings.

A plugin declares it on the dataclass field that holds the parameter::

    from twinkit.ranges import param

    @dataclass
    class PoissonParams:
        depth: int = param(11, ge=1, le=14)                    # octree depth
        voxel_m: float = param(0.0, ge=0)                      # 0 = off
        check_radius_m: float = param(-1.0, gt=0, also=(-1,))  # -1 = the site's radius
        backend: str = param("open3d", choices=("open3d", "pypoisson"))
        heights_m: list[float] = param(default_factory=lambda: [1.5, 3.0], gt=0)   # each element

``param`` is ``dataclasses.field`` with the check in the field's metadata, so Hydra and OmegaConf see
an ordinary field. The values are checked when the config is composed, before any step runs
(:func:`check_values`), and again on a step's merged parameters; a value outside its range is a
:class:`~twinkit.errors.ConfigError` (exit 2) naming the key and the range. NaN is never in a range.
``tests/test_ranges.py`` walks every registered plugin and fails for a number without a declaration.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import typing
from dataclasses import dataclass
from typing import Any, Iterator

from twinkit.errors import ConfigError

META = "twinkit_check"
HELP = "twinkit_help"
PATH = "twinkit_path"


def _num(x: float) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


@dataclass(frozen=True)
class Range:
    """Numbers between ``lo`` and ``hi`` (either may be open or absent), or one of ``also``."""

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    also: tuple = ()

    def ok(self, v: Any) -> bool:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            return False
        if v in self.also:
            return True
        if isinstance(v, float) and math.isnan(v):
            return False
        if self.lo is not None and (v <= self.lo if self.lo_open else v < self.lo):
            return False
        if self.hi is not None and (v >= self.hi if self.hi_open else v > self.hi):
            return False
        return True

    def describe(self) -> str:
        lo, hi = self.lo, self.hi
        if lo is not None and hi is not None and not self.lo_open and not self.hi_open:
            text = f"{_num(lo)}..{_num(hi)}"
        else:
            parts = []
            if lo is not None:
                parts.append(f"{'>' if self.lo_open else '>='} {_num(lo)}")
            if hi is not None:
                parts.append(f"{'<' if self.hi_open else '<='} {_num(hi)}")
            text = " and ".join(parts) or "any number"
        if self.also:
            text = " or ".join([_num(a) for a in self.also] + [text])
        return text


@dataclass(frozen=True)
class Choices:
    """One of the listed values (strings, usually)."""

    values: tuple

    def ok(self, v: Any) -> bool:
        return v in self.values

    def describe(self) -> str:
        return "one of " + ", ".join(repr(v) if isinstance(v, str) else str(v) for v in self.values)


@dataclass(frozen=True)
class Pattern:
    """A string matching a regular expression as a whole (``describe`` says it in words)."""

    regex: str
    words: str = ""

    def ok(self, v: Any) -> bool:
        import re

        return isinstance(v, str) and re.fullmatch(self.regex, v) is not None

    def describe(self) -> str:
        return self.words or f"a string matching {self.regex}"


def param(default: Any = dataclasses.MISSING, *, ge: float | None = None, gt: float | None = None,
          le: float | None = None, lt: float | None = None, also: tuple = (), choices: tuple | None = None,
          pattern: str | None = None, words: str = "", default_factory: Any = dataclasses.MISSING,
          help: str = "", free: bool = False, path: bool | tuple[str, ...] = False) -> Any:
    """A dataclass field with its valid values: ``ge``/``gt``/``le``/``lt`` for numbers, ``choices`` for the rest.

    ``pattern`` (a regular expression the whole string must match, ``words`` saying it for the error)
    is for strings that reach a command line or a script. ``also`` lists special values outside the
    range (``-1`` = automatic). With no bound at all a number
    still counts as declared ("any number"): say so on purpose, for signed offsets and angles; a flag or a
    free string without choices carries only its ``help``, and so does a field marked ``free=True``
    (a list of strings, a mapping, an optional string, a nested group of options: any value of its type).
    For a list the check applies to each element. ``path=True`` declares a string that names an input file or
    folder (a map, a model's weights): the step's cache key covers that file's content, not only its name
    (docs/engine.md, "When a step runs"); ``path=(".npz", ".json")``: the value with each of these suffixes in
    place of its own names a file (a model's stem).
    ``help`` is the one-paragraph description
    ``twinkit plugins <kind>/<name>`` prints (what the value does, its unit, when to change it);
    measurements and their history belong in the docs, not here.
    """
    unbounded = all(b is None for b in (ge, gt, le, lt, choices, pattern)) and not also
    if free and not unbounded:
        raise TypeError("free=True takes no range, choices or pattern")
    meta: dict[str, Any] = {HELP: help}
    if path is True:
        meta[PATH] = ()
    elif path:
        meta[PATH] = tuple(path)
    if free or unbounded and isinstance(default, (bool, str)):
        # a flag, a free string or a free value: nothing to range-check, only the help to carry
        if default_factory is not dataclasses.MISSING:
            return dataclasses.field(default_factory=default_factory, metadata=meta)
        return dataclasses.field(default=default, metadata=meta)
    if pattern is not None:
        check: Range | Choices | Pattern = Pattern(pattern, words)
    elif choices is not None:
        check = Choices(tuple(choices))
    else:
        if ge is not None and gt is not None or le is not None and lt is not None:
            raise TypeError("give one lower bound (ge or gt) and one upper bound (le or lt)")
        check = Range(lo=gt if gt is not None else ge, hi=lt if lt is not None else le,
                      lo_open=gt is not None, hi_open=lt is not None, also=tuple(also))
    meta[META] = check
    if default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def path_fields(cls: type | None) -> dict[str, tuple[str, ...]]:
    """The fields of ``cls`` (nested dataclasses walked, names dotted) declared with ``param(path=...)``: name ->
    the suffixes of a stem's files (empty for a plain file or folder)."""
    if cls is None or not dataclasses.is_dataclass(cls):
        return {}
    return dict(_path_fields(cls, ""))


@functools.lru_cache(maxsize=None)
def _path_fields(cls: type, prefix: str) -> tuple[tuple[str, tuple[str, ...]], ...]:
    """path_fields, remembered per class (looked up for every step of every run)."""
    hints = typing.get_type_hints(cls)
    out: list[tuple[str, tuple[str, ...]]] = []
    for f in dataclasses.fields(cls):
        sub = _nested(hints.get(f.name, Any))
        if sub is not None:
            out += _path_fields(sub, f"{prefix}{f.name}.")
        elif f.metadata and PATH in f.metadata:
            out.append((prefix + f.name, f.metadata[PATH]))
    return tuple(out)


def help_of(f: dataclasses.Field) -> str:
    """The ``help`` text a field was declared with (empty when it has none)."""
    return (f.metadata.get(HELP) if f.metadata else "") or ""


def check_of(f: dataclasses.Field) -> Range | Choices | Pattern | None:
    return f.metadata.get(META) if f.metadata else None


def _numeric(tp: Any) -> bool:
    """int or float, possibly Optional or a list of them."""
    if tp in (int, float):
        return True
    args = [a for a in typing.get_args(tp) if a is not type(None)]
    return bool(args) and all(_numeric(a) for a in args)


def _nested(tp: Any) -> type | None:
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return tp
    args = [a for a in typing.get_args(tp) if a is not type(None)]
    return args[0] if len(args) == 1 and isinstance(args[0], type) and dataclasses.is_dataclass(args[0]) else None


def undeclared(cls: type, prefix: str = "") -> Iterator[str]:
    """Names of numeric fields of ``cls`` (and of its nested dataclasses) without a range."""
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        tp = hints.get(f.name, Any)
        sub = _nested(tp)
        if sub is not None:
            yield from undeclared(sub, f"{prefix}{f.name}.")
        elif _numeric(tp) and check_of(f) is None:
            yield prefix + f.name


def problem(check: Range | Choices | Pattern, value: Any) -> str | None:
    """None when ``value`` (or each element of a list) passes; else the offending value as text."""
    if value is None:
        return None  # Optional: None means "not set", the type check decides whether it may be
    for v in (value if isinstance(value, (list, tuple)) else [value]):
        if not check.ok(v):
            return repr(v) if isinstance(v, str) else str(v)
    return None


def check_values(cls: type | None, values: Any, prefix: str, plugin: str = "") -> None:
    """Raise ConfigError naming ``<prefix>.<field>`` for the first value outside its declared range.

    ``values`` is a mapping (a config node) or an instance of ``cls``; nested dataclasses are walked.
    """
    if cls is None or values is None:
        return
    if dataclasses.is_dataclass(values) and not isinstance(values, type):
        values = {f.name: getattr(values, f.name) for f in dataclasses.fields(values)}
    if not isinstance(values, dict):
        return
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        if f.name not in values:
            continue
        key = f"{prefix}.{f.name}" if prefix else f.name
        sub = _nested(hints.get(f.name, Any))
        if sub is not None:
            check_values(sub, values[f.name], key, plugin)
            continue
        check = check_of(f)
        if check is None:
            continue
        bad = problem(check, values[f.name])
        if bad is not None:
            whose = f" (plugin {plugin})" if plugin else ""
            each = " (each element)" if isinstance(values[f.name], (list, tuple)) else ""
            what = "is out of range" if isinstance(check, Range) else "is not allowed"
            raise ConfigError(f"{key}={bad} {what}{whose}: {key}{each} must be {check.describe()}")


@dataclass(frozen=True)
class ParamInfo:
    """One parameter as ``twinkit plugins <kind>/<name>`` shows it (all fields are display text)."""

    name: str      # dotted for a nested dataclass's fields: ``filter.radius_m``
    type: str      # ``int``, ``list[float]``, ``str | None``
    range: str     # the declared check in words, ``-`` when there is none
    default: str   # repr of the default (a default_factory is called), ``required`` when there is none
    help: str      # the param(help=...) text, ``""`` when there is none


def _type_text(tp: Any) -> str:
    if isinstance(tp, type) and not typing.get_args(tp):
        return tp.__name__
    return str(tp).replace("typing.", "").replace("NoneType", "None")


def describe_params(cls: type | None, prefix: str = "") -> list[ParamInfo]:
    """Every field of the params dataclass ``cls`` (nested dataclasses walked, names dotted), in order."""
    if cls is None:
        return []
    hints = typing.get_type_hints(cls)
    out: list[ParamInfo] = []
    for f in dataclasses.fields(cls):
        tp = hints.get(f.name, Any)
        sub = _nested(tp)
        if sub is not None:
            out.extend(describe_params(sub, f"{prefix}{f.name}."))
            continue
        if f.default is not dataclasses.MISSING:
            default = repr(f.default)
        elif f.default_factory is not dataclasses.MISSING:
            default = repr(f.default_factory())
        else:
            default = "required"
        check = check_of(f)
        shown = check.describe() if check is not None else "-"
        if f.metadata and PATH in f.metadata:
            shown = "a file or folder (its content is in the key)" if shown == "-" else shown
        out.append(ParamInfo(prefix + f.name, _type_text(tp), shown, default, help_of(f)))
    return out

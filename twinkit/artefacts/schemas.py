"""The schemas of the JSON artefacts that cross plugin boundaries: one dataclass each, with a ``VERSION``.

A schema names the fields a reader relies on, with their JSON types; every other field of the file is kept
as it is in ``extra`` (so a write of what was read gives the same file). ``Schema.from_json(data, path)``
validates and raises :class:`ArtefactError` naming the file, the field and the fix; ``to_json()`` gives the
plain dict the writer stores. A document also reads like the dict it came from (``doc["cameras"]``,
``doc.get("frame")``), so a step moved onto the catalogue keeps its logic.

The version is the catalogue's: files carry no stamp (a stamp would change every file a run writes). A
reader recognises an older layout by its shape (``points_meta.json`` without ``density`` is version 1).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar

from twinkit.errors import InputError


class ArtefactError(InputError):
    """A catalogued artefact does not follow its schema; the message names the file, the field and the fix."""


_JSON_TYPES: dict[str, type | tuple[type, ...]] = {"dict": dict, "list": list, "str": str, "number": (int, float), "int": int, "bool": bool}


def _type_ok(value: Any, kind: str) -> bool:
    if kind.endswith("?"):
        if value is None:
            return True
        kind = kind[:-1]
    if kind in ("number", "int") and isinstance(value, bool):
        return False
    return isinstance(value, _JSON_TYPES[kind])


@dataclass
class JsonSchema:
    """Base of a JSON artefact's schema. Subclasses declare dataclass fields (the fields a reader relies
    on) and ``KINDS``: field -> JSON kind (``dict``, ``list``, ``str``, ``number``, ``int``, ``bool``; a
    trailing ``?`` allows null). ``ITEMS``: list field -> the keys each of its objects must hold."""

    VERSION: ClassVar[int] = 1
    FILE: ClassVar[str] = ""
    FIX: ClassVar[str] = "re-run the step that wrote it"
    KINDS: ClassVar[dict[str, str]] = {}
    ITEMS: ClassVar[dict[str, tuple[str, ...]]] = {}
    INDENT: ClassVar[int] = 2  # the writer's indent (the demo site's files keep their 1)

    extra: dict = field(default_factory=dict, repr=False)
    #: the schema's fields the file had (None: built in code); an optional field it lacked stays absent
    _present: set[str] | None = field(default=None, init=False, repr=False, compare=False)

    @classmethod
    def _known(cls) -> list[str]:
        return [f.name for f in dataclasses.fields(cls) if f.name not in ("extra", "_present")]

    @classmethod
    def _fail(cls, path: Any, what: str) -> ArtefactError:
        where = str(path) if path is not None else cls.FILE
        return ArtefactError(f"{where}: {what} ({cls.FILE} schema v{cls.VERSION}); {cls.FIX}")

    @classmethod
    def from_json(cls, data: Any, path: Any = None):
        """Validate ``data`` (the parsed JSON) and build the schema object; ``path`` names the file in errors."""
        if not isinstance(data, dict):
            raise cls._fail(path, f"expected a JSON object, found {type(data).__name__}")
        names = cls._known()
        for name in names:
            kind = cls.KINDS.get(name, "dict")
            if name not in data:
                if kind.endswith("?"):
                    continue
                raise cls._fail(path, f"field '{name}' is missing")
            if not _type_ok(data[name], kind):
                raise cls._fail(path, f"field '{name}' should be {kind.rstrip('?')}, found "
                                      f"{type(data[name]).__name__}")
        for name, keys in cls.ITEMS.items():
            for i, item in enumerate(data.get(name) or []):
                if not isinstance(item, dict):
                    raise cls._fail(path, f"{name}[{i}] should be an object")
                miss = [k for k in keys if k not in item]
                if miss:
                    raise cls._fail(path, f"{name}[{i}] lacks field(s) {miss}")
        obj = cls(**{n: data[n] for n in names if n in data},
                  extra={k: v for k, v in data.items() if k not in names})
        obj._present = {n for n in names if n in data}
        obj._check(path)
        return obj

    def _check(self, path: Any) -> None:
        """Checks beyond the field kinds (nested blocks); raise ``self._fail(path, ...)``."""

    def to_json(self) -> dict:
        """The plain dict the writer stores (the known fields and ``extra``)."""
        out = dict(self.extra)
        for name in self._known():
            v = getattr(self, name)
            if v is None and (name not in self._present if self._present is not None
                              else self.KINDS.get(name, "").endswith("?")):
                continue  # an optional field the file did not have (or the code did not set) stays absent
            out[name] = v
        return out

    # a document reads like the dict it came from
    def __getitem__(self, key: str) -> Any:
        return self.to_json()[key]

    def get(self, key: str, default: Any = None) -> Any:
        return self.to_json().get(key, default)

    def __contains__(self, key: object) -> bool:
        return key in self.to_json()


@dataclass
class PointsMeta(JsonSchema):
    """``points_meta.json``: how a site-frame cloud ``points.ply`` was made (read_cloud, or the photo
    branch's dense step). ``density`` is :func:`twinkit.surface.density.measure`'s block (``spacing_m``
    median nearest-neighbour spacing in metres, ``capture``, ...), required since version 2."""

    VERSION: ClassVar[int] = 2
    FILE: ClassVar[str] = "points_meta.json"
    FIX: ClassVar[str] = "re-run the step that wrote it (read_cloud, or dense on the photo branch)"
    KINDS: ClassVar[dict[str, str]] = {"source": "dict", "counts": "dict", "fields": "dict", "frame": "dict",
                                       "bounds_m": "list", "density": "dict"}
    DENSITY_KEYS: ClassVar[tuple[str, ...]] = ("points", "spacing_m", "capture")

    source: dict = field(default_factory=dict)
    counts: dict = field(default_factory=dict)
    fields: dict = field(default_factory=dict)
    frame: dict = field(default_factory=dict)
    bounds_m: list = field(default_factory=list)
    density: dict = field(default_factory=dict)

    def _check(self, path: Any) -> None:
        miss = [k for k in self.DENSITY_KEYS if k not in self.density]
        if miss:
            raise self._fail(path, f"the density block lacks {miss}")
        if not _type_ok(self.density["spacing_m"], "number"):
            raise self._fail(path, "density.spacing_m should be a number (metres)")

    @property
    def spacing_m(self) -> float:
        """Median nearest-neighbour point spacing, metres."""
        return float(self.density["spacing_m"])

    @property
    def ground_two_way_share(self) -> float | None:
        """Share of the ground's points sampled in patches rather than single scan lines (a spinning sweep's
        rings: about 0.3; :func:`twinkit.surface.density.measure`); None where unknown (no ground, or a file
        written before the key and read without its points)."""
        share = self.density.get("ground_two_way_share")
        return None if share is None else float(share)


@dataclass
class CamerasSite(JsonSchema):
    """``cameras_site.json``: the registered photos' cameras in the site frame (twinkit-photo's georeference).
    Each camera: ``image`` (file in the photos folder), ``K`` (3x3 px), ``R_world_from_camera`` (3x3),
    ``center`` (3, metres, site frame); optional ``width``/``height`` (px), ``model``/``params`` (COLMAP)."""

    FILE: ClassVar[str] = "cameras_site.json"
    FIX: ClassVar[str] = "re-run georeference"
    KINDS: ClassVar[dict[str, str]] = {"cameras": "list", "convention": "str?", "frame": "str?"}
    ITEMS: ClassVar[dict[str, tuple[str, ...]]] = {"cameras": ("image", "K", "R_world_from_camera", "center")}

    cameras: list = field(default_factory=list)
    convention: str | None = None
    frame: str | None = None


@dataclass
class DemoCameras(JsonSchema):
    """``cameras.json``: the demo site's true cameras: per camera ``image`` and ``center`` (3, metres, site
    frame), on the demo site also ``R_world_from_camera`` and ``gps``; optional ``intrinsics`` (``K``,
    ``width``, ``height``)."""

    FILE: ClassVar[str] = "cameras.json"
    FIX: ClassVar[str] = "re-run the site step (twinkit-demo-site)"
    INDENT: ClassVar[int] = 1
    KINDS: ClassVar[dict[str, str]] = {"cameras": "list", "intrinsics": "dict?"}
    ITEMS: ClassVar[dict[str, tuple[str, ...]]] = {"cameras": ("image", "center")}

    cameras: list = field(default_factory=list)
    intrinsics: dict | None = None

    def _check(self, path: Any) -> None:
        miss = [k for k in ("K", "width", "height") if k not in (self.intrinsics or {"K": 0, "width": 0, "height": 0})]
        if miss:
            raise self._fail(path, f"intrinsics lacks {miss}")


@dataclass
class GroundControl(JsonSchema):
    """``gcp.json``: ground-control points, each ``id``, ``site_xyz`` (3, metres, site frame) and
    ``observations`` (the photos and pixels it is seen at)."""

    FILE: ClassVar[str] = "gcp.json"
    FIX: ClassVar[str] = "give each point an id, site_xyz and its observations (docs/photo.md)"
    KINDS: ClassVar[dict[str, str]] = {"points": "list"}
    INDENT: ClassVar[int] = 1

    points: list = field(default_factory=list)


@dataclass
class RoadsTruth(JsonSchema):
    """``roads_truth.json``: the demo site's true road layout in the site frame (``roads`` with
    ``centerline``, ``polygon``, ``width_m``, ``lanes``; ``lanes`` with ``points``, ``direction``)."""

    FILE: ClassVar[str] = "roads_truth.json"
    FIX: ClassVar[str] = "re-run the site step (twinkit-demo-site)"
    INDENT: ClassVar[int] = 1
    KINDS: ClassVar[dict[str, str]] = {"roads": "list", "lanes": "list", "frame": "str"}
    ITEMS: ClassVar[dict[str, tuple[str, ...]]] = {"roads": ("name", "centerline", "polygon", "width_m"),
                                                   "lanes": ("road", "points", "direction")}

    roads: list = field(default_factory=list)
    lanes: list = field(default_factory=list)
    frame: str = ""


@dataclass
class Crosswalks(JsonSchema):
    """``crosswalks.json`` (roads' place_crosswalks): ``metrics`` (``crosswalks``: how many crossings the scan
    and OSM show, ``carla_crosswalks``: how many carla.Map reports), ``crosswalks`` (each with ``source``
    and its site-frame ``polygon``), ``enabled``."""

    FILE: ClassVar[str] = "crosswalks.json"
    FIX: ClassVar[str] = "re-run the place_crosswalks step (twinkit-roads)"
    INDENT: ClassVar[int] = 1
    KINDS: ClassVar[dict[str, str]] = {"enabled": "bool", "metrics": "dict", "crosswalks": "list"}
    ITEMS: ClassVar[dict[str, tuple[str, ...]]] = {"crosswalks": ("source", "polygon")}

    enabled: bool = True
    metrics: dict = field(default_factory=dict)
    crosswalks: list = field(default_factory=list)

    def _check(self, path: Any) -> None:
        if not isinstance(self.metrics.get("crosswalks"), int):
            raise self._fail(path, "metrics.crosswalks should be an int")


@dataclass
class SiteInfo(JsonSchema):
    """``site.json``: the site's georeference (``crs``, ``base_point`` lat/lon/alt, optional
    ``base_point_projected`` x/y/z) and what the demo site holds."""

    FILE: ClassVar[str] = "site.json"
    FIX: ClassVar[str] = "re-run the site step, or give crs and base_point (lat, lon, alt)"
    INDENT: ClassVar[int] = 1
    KINDS: ClassVar[dict[str, str]] = {"crs": "str", "base_point": "dict", "base_point_projected": "dict?",
                                       "frame": "str?"}

    crs: str = ""
    base_point: dict = field(default_factory=dict)
    base_point_projected: dict | None = None
    frame: str | None = None

"""The lanes of an OpenDRIVE map in the site frame, read with CARLA's own parser (``carla.Map``, offline).

The one place twinkit walks OpenDRIVE lane geometry, and the one place that knows CARLA's frame: CARLA
(Unreal) is left-handed with y = -north, the site frame is right-handed (x east, y north, z up, metres). A
point at CARLA (x, y, z) is at site (x, -y, z); a heading counter-clockwise from east is minus CARLA's yaw.
:func:`from_carla` / :func:`to_carla` and :func:`yaw_from_carla` / :func:`yaw_to_carla` are those two rules
(the CARLA package's frame, right-handed like the site frame, mirrors into CARLA the same way); everything
else here hands out site-frame numbers.

CARLA evaluates the whole lane model (reference-line geometries, ``laneOffset``, every lane section, width
polynomials, elevation), so a sample's width and borders are what CARLA drives on.

    lm = LaneMap(xodr_text, source="aligned.xodr")  # parses once; OpenDriveError when it cannot
    wp = lm.waypoints(1.0)          # CARLA's waypoints (driving lanes), raw
    every = lm.lanes(0.5)           # + every lane reached sideways from them (sidewalks, borders, ...)
    for lane in every.per_lane():   # one LaneSamples per (road, section, lane), ordered by s
        left, right = lane.borders()

``carla`` is imported inside the functions, never at import time.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from twinkit.errors import InputError

#: (road id, lane-section id, lane id): one lane of one lane section
LaneKey = tuple[int, int, int]


class OpenDriveError(InputError):
    """``carla.Map`` cannot read the OpenDRIVE text; the message names the file (``source``) and what to do
    (``why``), so a caller that knows the file better can say ``f"{path}: {exc.why}"``."""

    def __init__(self, source: str, why: str):
        super().__init__(f"{source}: {why}")
        self.source, self.why = source, why


def from_carla(xyz) -> np.ndarray:
    """(..., 2|3) CARLA's frame (Unreal, left-handed: y = -north) -> the right-handed frame of the OpenDRIVE file
    (the site frame, or the CARLA package's frame: y north): y negated. float64, a copy. Its own inverse."""
    a = np.array(xyz, dtype=float)
    a[..., 1] = -a[..., 1]
    return a


def to_carla(xyz) -> np.ndarray:
    """(..., 2|3) the OpenDRIVE file's right-handed frame (y north) -> CARLA's frame (y = -north): y negated."""
    return from_carla(xyz)


def yaw_from_carla(yaw_deg):
    """CARLA's yaw (degrees; clockwise from east seen from above, y being -north) -> heading in the right-handed
    frame (degrees, counter-clockwise from east): negated. Its own inverse."""
    return -np.asarray(yaw_deg, float) if np.ndim(yaw_deg) else -float(yaw_deg)


def yaw_to_carla(heading_deg):
    """Heading (degrees, counter-clockwise from east, right-handed frame) -> CARLA's yaw (degrees): negated."""
    return yaw_from_carla(heading_deg)


@dataclass(frozen=True)
class LaneSamples:
    """Lane-centre samples, one row per sample, in the site frame; arrays of equal length n.

    ``xyz`` (n, 3) float64 m: the lane's centre (height from the OpenDRIVE elevation);
    ``right`` (n, 2) float64: CARLA's right vector of the lane (to the right of its driving direction, unit
    up to CARLA's float32; :attr:`normal` is it normalised); ``heading_deg`` (n,) float64: the direction of
    the lane's centre line (its driving direction), counter-clockwise from east; ``carla_pitch_deg`` /
    ``carla_roll_deg`` (n,) float64: the pitch and roll CARLA reports (its frame); ``width`` (n,) float64 m:
    the lane's width there (the width polynomial of its lane section); ``s`` (n,) float64 m along the road;
    ``road`` / ``section`` / ``lane`` (n,) int64 ids; ``type`` (n,) str: CARLA's lane-type name
    (``Driving``, ``Sidewalk``, ``OnRamp``, ...; compare with :meth:`is_type`); ``junction`` (n,) int64: the
    junction id, -1 outside junctions.
    """

    xyz: np.ndarray
    right: np.ndarray
    heading_deg: np.ndarray
    carla_pitch_deg: np.ndarray
    carla_roll_deg: np.ndarray
    width: np.ndarray
    s: np.ndarray
    road: np.ndarray
    section: np.ndarray
    lane: np.ndarray
    type: np.ndarray
    junction: np.ndarray

    def __len__(self) -> int:
        return len(self.s)

    @classmethod
    def _from_rows(cls, rows: list[tuple]) -> "LaneSamples":
        """Rows as :func:`_row` makes them -> columns."""
        a = np.array([r[:14] for r in rows], float).reshape(-1, 14)
        ids = a[:, 10:14].astype(np.int64)
        return cls(xyz=a[:, 0:3], right=a[:, 3:5], heading_deg=yaw_from_carla(a[:, 5]), carla_pitch_deg=a[:, 6],
                   carla_roll_deg=a[:, 7], width=a[:, 8], s=a[:, 9], road=ids[:, 0], section=ids[:, 1],
                   lane=ids[:, 2], junction=ids[:, 3], type=np.array([r[14] for r in rows], dtype=object))

    def take(self, idx) -> "LaneSamples":
        """The samples at ``idx`` (indices or a boolean mask), in that order."""
        return LaneSamples(**{f.name: getattr(self, f.name)[idx] for f in fields(self)})

    @property
    def in_junction(self) -> np.ndarray:
        """(n,) bool: the sample lies on a junction's lane."""
        return self.junction >= 0

    def is_type(self, *names: str) -> np.ndarray:
        """(n,) bool: the lane type is one of ``names`` (case-insensitive: ``driving`` matches ``Driving``)."""
        want = {n.lower() for n in names}
        return np.array([t.lower() in want for t in self.type], bool).reshape(len(self))

    @property
    def normal(self) -> np.ndarray:
        """(n, 2) float64: the unit vector to the lane's right (site frame); (0, 0) stays (0, 0)."""
        r = self.right
        norm = np.sqrt(r[:, 0] * r[:, 0] + r[:, 1] * r[:, 1])
        return r / np.where(norm > 0, norm, 1.0)[:, None]

    def borders(self) -> tuple[np.ndarray, np.ndarray]:
        """(left, right): (n, 2) float64 site-frame points of the lane's two borders, half a width each side
        of the centre, across the driving direction (left = the side the right vector points away from)."""
        c, h = self.xyz[:, :2], (self.width / 2)[:, None]
        nrm = self.normal
        return c - nrm * h, c + nrm * h

    def unique(self, decimals: int = 3) -> "LaneSamples":
        """The first sample of each (road, section, lane, s rounded to ``decimals``), in the given order."""
        seen: set = set()
        keep = []
        for i, k in enumerate(zip(self.road.tolist(), self.section.tolist(), self.lane.tolist(),
                                  (round(v, decimals) for v in self.s.tolist()))):
            if k not in seen:
                seen.add(k)
                keep.append(i)
        return self.take(np.asarray(keep, np.int64))

    def per_lane(self) -> list["LaneSamples"]:
        """One :class:`LaneSamples` per (road, section, lane), in the order each lane first appears, its
        samples ordered by s (stable)."""
        groups: dict[LaneKey, list[int]] = {}
        for i, k in enumerate(zip(self.road.tolist(), self.section.tolist(), self.lane.tolist())):
            groups.setdefault(k, []).append(i)
        out = []
        for members in groups.values():
            idx = np.asarray(members, np.int64)
            out.append(self.take(idx[np.argsort(self.s[idx], kind="stable")]))
        return out

    @property
    def key(self) -> LaneKey:
        """(road, section, lane) of the first sample (one lane's samples: :meth:`per_lane`)."""
        return int(self.road[0]), int(self.section[0]), int(self.lane[0])


@dataclass(frozen=True)
class Landmark:
    """An OpenDRIVE signal as CARLA places it: ``id`` and ``type`` (OpenDRIVE strings, e.g. ``1000001`` a
    traffic light), ``road`` and ``s`` it is defined on, ``xyz`` (3,) float64 site frame, m."""

    id: str
    type: str
    road: int
    s: float
    xyz: np.ndarray


def _row(w) -> tuple:
    """One CARLA waypoint -> (x, y, z, right x, right y, yaw, pitch, roll, width, s, road, section, lane,
    junction, type): position and right vector already in the site frame, angles as CARLA has them."""
    t = w.transform
    loc, rot, rv = t.location, t.rotation, t.get_right_vector()
    return (loc.x, -loc.y, loc.z, rv.x, -rv.y, rot.yaw, rot.pitch, rot.roll, w.lane_width, w.s, w.road_id,
            w.section_id, w.lane_id, w.junction_id if w.is_junction else -1, str(w.lane_type))


class LaneMap:
    """An OpenDRIVE map parsed once by ``carla.Map`` (offline); every answer in the site frame.

    ``source`` names the file in error messages (default: ``name``)."""

    def __init__(self, xodr_text: str, name: str = "site", source: str | Path | None = None):
        import carla

        self.source = str(source if source is not None else name)
        if "<OpenDRIVE" not in xodr_text:
            raise OpenDriveError(self.source, "not an OpenDRIVE file (no <OpenDRIVE> element); give the .xodr a road "
                                 "source wrote (e.g. osm_to_opendrive's)")
        try:
            self._map = carla.Map(name, xodr_text)
        except Exception as exc:  # noqa: BLE001 - CARLA raises RuntimeError("failed to generate map")
            raise OpenDriveError(self.source, f"carla.Map cannot read it ({type(exc).__name__}: {exc}); check that "
                                 "it is well-formed XML (xmllint --noout) and valid OpenDRIVE 1.4-1.6 (open it in "
                                 "an OpenDRIVE viewer), or write it again with its road source") from None

    @classmethod
    def from_file(cls, path: str | Path, name: str | None = None) -> "LaneMap":
        """Read and parse ``path`` (UTF-8)."""
        p = Path(path)
        return cls(p.read_text(encoding="utf-8"), name or p.stem or "site", source=p)

    def _generate(self, step_m: float) -> list:
        """carla.Map.generate_waypoints; CARLA's errors on lanes it cannot walk as an OpenDriveError."""
        try:
            return self._map.generate_waypoints(float(step_m))
        except Exception as exc:  # noqa: BLE001 - e.g. IndexError("map::at") for a road without a centre lane
            raise OpenDriveError(self.source, f"carla.Map cannot walk its lanes ({type(exc).__name__}: {exc}); "
                                 "check that every lane section has its <center> lane and every link names a road, "
                                 "lane and junction that exist (open it in an OpenDRIVE viewer)") from None

    def waypoints(self, step_m: float) -> LaneSamples:
        """CARLA's waypoints every ``step_m`` along every driving lane (``generate_waypoints``), as CARLA
        orders them, duplicates kept."""
        return LaneSamples._from_rows([_row(w) for w in self._generate(step_m)])

    def lanes(self, step_m: float, max_hops: int = 8) -> LaneSamples:
        """Every lane of every type every ``step_m``: the driving waypoints and, from each, the lanes reached
        sideways (right, then left) up to the next driving lane or ``max_hops`` lanes away. A lane not next
        to a driving lane is not seen. One sample per (road, section, lane, s to the mm), in visit order."""
        import carla

        driving = carla.LaneType.Driving
        rows = []
        for w in self._generate(step_m):
            rows.append(_row(w))
            for side in ("get_right_lane", "get_left_lane"):
                o = getattr(w, side)()
                hops = 0
                while o is not None and hops < max_hops and o.lane_type != driving:
                    rows.append(_row(o))
                    o = getattr(o, side)()
                    hops += 1
        return LaneSamples._from_rows(rows).unique(3)

    def topology(self) -> list[tuple[LaneKey, LaneKey]]:
        """CARLA's topology: one (from lane, to lane) pair per segment of its road graph."""
        return [((a.road_id, a.section_id, a.lane_id), (b.road_id, b.section_id, b.lane_id))
                for a, b in self._map.get_topology()]

    def landmarks(self) -> list[Landmark]:
        """Every signal CARLA reads from the map, where CARLA puts it (site frame)."""
        out = []
        for lm in self._map.get_all_landmarks():
            loc = lm.transform.location
            out.append(Landmark(str(lm.id), str(lm.type), int(lm.road_id), float(lm.s),
                                np.array([loc.x, -loc.y, loc.z], float)))
        return out

    def lane_at(self, xyz, lane_type: str = "Any") -> list[tuple[LaneKey, str] | None]:
        """For each site-frame point of ``xyz`` (k, 3) (or (k, 2): z = 0), the lane CARLA finds there:
        ``Map::GetWaypoint`` (``carla.Map.get_waypoint(loc, project_to_road=False, lane_type=...)``), which
        answers only within half the lane's width of its centre. ``lane_type``: a ``carla.LaneType`` name
        (``Sidewalk``, ``Driving``, ``Parking``, ``Any``). Each answer is ((road, section, lane), CARLA's
        lane-type name) or None."""
        import carla

        want = getattr(carla.LaneType, lane_type)
        pts = np.asarray(xyz, float).reshape(len(xyz), -1)
        if pts.shape[1] == 2:
            pts = np.column_stack([pts, np.zeros(len(pts))])
        out: list[tuple[LaneKey, str] | None] = []
        for x, y, z in to_carla(pts).tolist():
            w = self._map.get_waypoint(carla.Location(x, y, z), project_to_road=False, lane_type=want)
            out.append(None if w is None else ((w.road_id, w.section_id, w.lane_id), str(w.lane_type)))
        return out

    def geolocation(self, locations) -> np.ndarray:
        """(n, 2) lon, lat: ``transform_to_geolocation`` at (n, 2|3) CARLA locations taken as given (x, y[, z]:
        CARLA's own y, not mirrored here; pass north-positive y to get CARLA's formula on north-positive y)."""
        import carla

        p = np.asarray(locations, float)
        p = np.c_[p.reshape(len(p), -1)[:, :2], p.reshape(len(p), -1)[:, 2] if p.ndim > 1 and p.shape[-1] > 2
                  else np.zeros(len(p))]
        out = [self._map.transform_to_geolocation(carla.Location(float(x), float(y), float(z))) for x, y, z in p]
        return np.array([(g.longitude, g.latitude) for g in out], float).reshape(-1, 2)

    def crosswalk_points(self) -> np.ndarray:
        """(n, 3) float64: ``get_crosswalks()``'s points as CARLA gives them (its frame: y = -north), one
        outline after another, each closed by its first point where the OpenDRIVE closes it
        (Map::GetAllCrosswalkZones in LibCarla/source/carla/road/Map.cpp; ``get_xodr_crosswalks.py``
        reads this list). A crosswalk CARLA cannot place raises :class:`OpenDriveError`."""
        try:
            zones = self._map.get_crosswalks()
        except Exception as exc:  # noqa: BLE001 - CARLA asserts, e.g. RuntimeError("s <= road->GetLength()")
            raise OpenDriveError(self.source, f"carla.Map cannot place its crosswalks ({type(exc).__name__}: {exc}); "
                                 "check each crosswalk object's s lies on its road") from None
        return np.array([[p.x, p.y, p.z] for p in zones], float).reshape(-1, 3)

    def crosswalks(self) -> list[np.ndarray]:
        """The crosswalks CARLA reports (:meth:`crosswalk_points` split at each outline's closing point): a
        list of (k, 3) float64 site-frame outlines, each without its closing point."""
        pts = self.crosswalk_points() * np.array([1.0, -1.0, 1.0])
        out: list[np.ndarray] = []
        cur: list[np.ndarray] = []
        for p in pts:
            if len(cur) > 1 and np.allclose(p, cur[0], atol=1e-4):
                out.append(np.array(cur))
                cur = []
            else:
                cur.append(p)
        if cur:
            out.append(np.array(cur))
        return out

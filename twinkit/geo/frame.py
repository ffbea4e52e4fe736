"""The site frame: one local metric frame per site, shared by every step and export.

Definition (the one frame of every step and export, the demo site generator's included)::

    local x = (E - E0) * f      E, N: coordinates in the site's projected CRS
    local y = (N - N0) * f      E0, N0: the base point in that CRS
    local z = h - alt0          f: the CRS's linear unit in metres (1 for metres)

x points to grid east, y to grid north, z up; the origin is the base point.
A site whose CRS is geographic (EPSG:4326, ...) gets a transverse Mercator
(scale 1) centred on its base point as its projected CRS.

Heights: ``alt0`` and every z are heights in the site CRS's vertical datum
when the CRS is compound (e.g. ``EPSG:3067+3900``, TM35FIN + N2000); with a
2D CRS the heights are whatever the survey gave, and twinkit never converts
them. See docs/georeferencing.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from twinkit.errors import InputError
from twinkit.geo.crs import (base_height, base_point_lonlat, check_base_point_area, horizontal, parse_crs, site_dict, unit_factors,
                             z_unit)

#: largest acceptable error of the netconvert projection string against the site frame (metres)
PROJ_TOLERANCE_M = 1e-3


@dataclass(frozen=True)
class SiteFrame:
    """The site frame of one site: build it with :meth:`from_site`; converts site-frame metres to and from
    projected coordinates, WGS84 lon/lat and heights, and gives the PROJ string for netconvert."""

    crs: str  # the site's CRS as the user gave it (EPSG code or PROJ string)
    lat: float  # base point, WGS84 degrees
    lon: float
    alt: float  # base point height (site vertical datum; see module doc)
    easting: float  # base point in the projected CRS (CRS units)
    northing: float
    unit_m: float = 1.0  # metres per CRS unit
    projected: str = ""  # the projected CRS actually used (== crs unless crs is geographic)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_site(cls, site: Mapping[str, Any] | None) -> "SiteFrame":
        """Build the frame from a site config (``crs``, ``base_point: {lat, lon, alt}`` or ``{x, y, z}``)."""
        from pyproj import CRS, Transformer
        from pyproj.exceptions import CRSError

        s = site_dict(site)
        name = s.get("name", "?")
        crs_in = s.get("crs")
        bp = s.get("base_point")
        if not crs_in or not bp:
            missing = [k for k, v in (("crs", crs_in), ("base_point", bp)) if not v]
            raise InputError(
                f"site '{name}' has no georeference (missing {', '.join(missing)}): set site.crs{crs_example(s)} and "
                f"site.base_point ({{lat, lon, alt}} or projected {{x, y, z}}) in conf/site/{name}.yaml"
            )
        try:
            crs = parse_crs(str(crs_in))
        except CRSError as exc:
            raise InputError(f"site '{name}': unknown CRS '{crs_in}' ({str(exc).splitlines()[0]}); "
                             f"give an EPSG code{crs_example(s)} or a PROJ string") from None
        bp = dict(bp)
        horiz = horizontal(crs)
        ll = base_point_lonlat(bp, horiz)
        if ll is None:
            raise InputError(f"site '{name}': base_point needs lat/lon or x/y, got keys {sorted(bp)}")
        lon, lat = ll
        if "lat" in bp and "lon" in bp and not (-90 < lat < 90 and -180 <= lon <= 180):
            raise InputError(f"site '{name}': base point lat={lat} lon={lon} is outside the globe")
        alt = base_height(bp, z_unit(crs))  # z in the CRS's vertical unit, alt in metres: metres here
        check_base_point_area(s, f"site '{name}' (conf/site/{name}.yaml)")
        if abs(lat) > 89.0:
            raise InputError(f"site '{name}': base point latitude {lat} is at a pole; no projected site frame is "
                             "defined there (choose a polar stereographic CRS and give the base point in it)")
        if horiz.is_geographic:
            projected = (f"+proj=tmerc +lat_0={lat!r} +lon_0={lon!r} +k=1 +x_0=0 +y_0=0 "
                         f"+ellps=WGS84 +units=m +no_defs")
            pcrs = CRS.from_user_input(projected)
        else:
            pcrs, projected = horiz, horiz.to_string()
        unit = unit_factors(pcrs)[0]
        t = Transformer.from_crs("EPSG:4326", pcrs, always_xy=True)
        e, n = t.transform(lon, lat)
        if not (math.isfinite(e) and math.isfinite(n)):
            raise InputError(f"site '{name}': base point lat={lat} lon={lon} is outside the area of CRS {crs_in}")
        return cls(crs=str(crs_in), lat=lat, lon=lon, alt=alt, easting=float(e), northing=float(n),
                   unit_m=unit, projected=projected)

    # ------------------------------------------------------------------ transforms
    def _t(self, src, dst):
        from pyproj import Transformer

        return Transformer.from_crs(src, dst, always_xy=True)

    def local_to_projected(self, xy) -> np.ndarray:
        xy = np.asarray(xy, float).reshape(-1, 2)
        return np.stack([xy[:, 0] / self.unit_m + self.easting, xy[:, 1] / self.unit_m + self.northing], 1)

    def projected_to_local(self, en) -> np.ndarray:
        en = np.asarray(en, float).reshape(-1, 2)
        return np.stack([(en[:, 0] - self.easting) * self.unit_m, (en[:, 1] - self.northing) * self.unit_m], 1)

    def local_to_lonlat(self, xy) -> np.ndarray:
        """(n, 2) site-frame metres -> (n, 2) lon, lat (WGS84 degrees)."""
        en = self.local_to_projected(xy)
        lon, lat = self._t(self.projected, "EPSG:4326").transform(en[:, 0], en[:, 1])
        return np.stack([np.asarray(lon, float), np.asarray(lat, float)], 1)

    def lonlat_to_local(self, lonlat) -> np.ndarray:
        """(n, 2) lon, lat (WGS84 degrees) -> (n, 2) site-frame metres."""
        ll = np.asarray(lonlat, float).reshape(-1, 2)
        e, n = self._t("EPSG:4326", self.projected).transform(ll[:, 0], ll[:, 1])
        return self.projected_to_local(np.stack([np.asarray(e, float), np.asarray(n, float)], 1))

    def local_to_height(self, z) -> np.ndarray:
        """Site-frame z -> height in the site's vertical datum (alt0 + z)."""
        return np.asarray(z, float) + self.alt

    @property
    def vertical_datum(self) -> str:
        """Name of the vertical datum heights refer to, or a statement that none is declared."""
        from pyproj import CRS

        crs = CRS.from_user_input(self.crs)
        if crs.is_compound and len(crs.sub_crs_list) > 1:
            return crs.sub_crs_list[1].name
        if crs.is_geographic and len(crs.axis_info) == 3:
            return f"ellipsoidal height ({crs.ellipsoid.name if crs.ellipsoid else '?'})"
        return "undeclared (2D CRS): heights are used as given, never converted"

    def ellipsoidal_heights(self, xyz) -> np.ndarray:
        """(n, 3) site-frame points -> WGS84 ellipsoidal heights; needs a compound CRS and its geoid grid.

        Raises InputError when the CRS declares no vertical datum, or when PROJ lacks the geoid
        grid (then PROJ either fails or returns inf; we never silently return the orthometric value).
        """
        from pyproj import CRS, Transformer

        crs = CRS.from_user_input(self.crs)
        if not crs.is_compound:
            raise InputError(f"site CRS {self.crs} has no vertical datum; use a compound CRS such as "
                             "EPSG:3067+3900 (TM35FIN + N2000) to convert heights")
        xyz = np.asarray(xyz, float).reshape(-1, 3)
        en = self.local_to_projected(xyz[:, :2])
        t = Transformer.from_crs(crs, "EPSG:4979", always_xy=True, only_best=True)
        try:
            _, _, h = t.transform(en[:, 0], en[:, 1], self.local_to_height(xyz[:, 2]), errcheck=True)
        except Exception as exc:
            raise InputError(f"cannot convert {self.vertical_datum} heights to ellipsoidal: {exc}. The geoid grid is "
                             "missing: run `pyproj sync --source-id <agency>` or set PROJ_NETWORK=ON") from None
        h = np.asarray(h, float)
        if not np.all(np.isfinite(h)):
            raise InputError("PROJ returned no height (geoid grid missing); run `pyproj sync` or set PROJ_NETWORK=ON")
        return h

    # ------------------------------------------------------------------ bounding boxes
    def bbox_lonlat(self, radius_m: float) -> tuple[float, float, float, float]:
        """(south, west, north, east) of the square of half-side ``radius_m`` around the base point."""
        r = float(radius_m)
        if r <= 0:
            raise InputError(f"osm_radius_m must be positive, got {radius_m}")
        s = np.linspace(-r, r, 9)
        edge = np.concatenate([np.stack([s, np.full_like(s, -r)], 1), np.stack([s, np.full_like(s, r)], 1),
                               np.stack([np.full_like(s, -r), s], 1), np.stack([np.full_like(s, r), s], 1)])
        ll = self.local_to_lonlat(edge)
        if not np.all(np.isfinite(ll)):
            raise InputError(f"the box of {r} m around the base point leaves the area of CRS {self.crs}")
        south, north = float(ll[:, 1].min()), float(ll[:, 1].max())
        lon = ll[:, 0]
        if lon.max() - lon.min() > 180:  # corners on both sides of +-180
            raise InputError(f"the box of {r} m around lon {self.lon:.5f} crosses the antimeridian (180 deg); "
                             "split the request into two boxes or use a local OSM file")
        return check_bbox(south, float(lon.min()), north, float(lon.max()))

    # ------------------------------------------------------------------ netconvert / OpenDRIVE
    def proj_string(self) -> str:
        """A PROJ string whose output *is* the site frame (metres), for netconvert and the OpenDRIVE geoReference.

        The site CRS's own PROJ definition with its false easting / northing moved by the base point
        (UTM is rewritten as the equivalent transverse Mercator, because +proj=utm ignores +x_0/+y_0),
        and metres as the unit. Verified against :meth:`lonlat_to_local` over +-1 km; raises
        InputError if the CRS cannot be expressed this way.
        """
        from pyproj import CRS

        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            d = dict(CRS.from_user_input(self.projected).to_dict())
        if not d or "proj" not in d:
            raise InputError(f"CRS {self.crs} has no PROJ-string form; netconvert cannot project into it")
        if d.get("proj") == "utm":
            zone = int(d.pop("zone"))
            south = "south" in d
            d.pop("south", None)
            d = {"proj": "tmerc", "lat_0": 0, "lon_0": zone * 6 - 183, "k": 0.9996,
                 "x_0": 500000.0, "y_0": 10000000.0 if south else 0.0, **{k: v for k, v in d.items() if k != "proj"}}
        for k in ("type", "no_defs", "units", "to_meter", "vunits", "vto_meter", "geoidgrids"):
            d.pop(k, None)
        # false easting/northing are in metres in PROJ strings, whatever the unit
        d["x_0"] = float(d.get("x_0", 0.0)) - self.easting * self.unit_m
        d["y_0"] = float(d.get("y_0", 0.0)) - self.northing * self.unit_m
        parts = []
        for k, v in d.items():
            parts.append(f"+{k}" if v is None or v is True else f"+{k}={v!r}" if isinstance(v, float) else f"+{k}={v}")
        s = " ".join(parts) + " +units=m +no_defs"
        err = self.proj_string_error(s)
        if not err < PROJ_TOLERANCE_M:
            raise InputError(f"cannot express the site frame of CRS {self.crs} as one PROJ string "
                             f"(error {err:.3g} m); use a transverse Mercator or Lambert CRS")
        return s

    def proj_string_error(self, proj: str, radius_m: float = 1000.0) -> float:
        """Largest distance (m) between ``proj``'s output and the site frame over a grid of +-radius_m."""
        g = np.linspace(-radius_m, radius_m, 21)
        xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
        ll = self.local_to_lonlat(xy)
        x, y = self._t("EPSG:4326", proj).transform(ll[:, 0], ll[:, 1])
        d = np.hypot(np.asarray(x) - xy[:, 0], np.asarray(y) - xy[:, 1])
        return float(np.max(d)) if np.all(np.isfinite(d)) else float("inf")

    def tmerc_at_base(self) -> str:
        """Transverse Mercator (scale 1) centred on the base point: what a naive OSM import would use."""
        return (f"+proj=tmerc +lat_0={self.lat!r} +lon_0={self.lon!r} +k=1 +x_0=0 +y_0=0 "
                "+ellps=GRS80 +units=m +no_defs")

    def carla_frame(self, radius_m: float = 150.0, tolerance_m: float = 0.5, scale: str = "auto", points=None):
        """The frame of the CARLA package (:func:`twinkit.geo.carla.carla_frame`): true north at the base point,
        an exact PROJ string whose +lat_0/+lon_0 CARLA reads, CARLA's geolocation within ``tolerance_m`` (at the
        twin's ``points`` when given, else within ``radius_m`` of the base point)."""
        from twinkit.geo.carla import carla_frame

        return carla_frame(self, radius_m=radius_m, tolerance_m=tolerance_m, scale=scale, points=points)

    def _z_projected(self) -> float:
        """The base point's height in the CRS's own vertical unit (what ``base_point.z`` means; metres: ``alt``)."""
        return self.alt / z_unit(parse_crs(self.crs))

    def georef_json(self) -> dict:
        """The georeference keys of a site.json: ``crs``, ``base_point`` and ``base_point_projected``."""
        return {"crs": self.crs, "base_point": {"lat": self.lat, "lon": self.lon, "alt": self.alt},
                "base_point_projected": {"x": self.easting, "y": self.northing, "z": self._z_projected()}}

    def to_json(self) -> dict:
        """Everything about the frame (for reports): :meth:`georef_json`, the projected CRS, the vertical datum."""
        return {"crs": self.crs, "projected_crs": self.projected,
                "base_point": {"lat": self.lat, "lon": self.lon, "alt": self.alt},
                "base_point_projected": {"x": self.easting, "y": self.northing, "z": self._z_projected()},
                "vertical_datum": self.vertical_datum,
                "frame": "local = (projected - base_point_projected) * unit_m, z = height - alt; x east, y north, z up"}


def crs_example(site: Mapping[str, Any] | None) -> str:
    """A CRS that fits the site's place, as ``" (e.g. EPSG:32648, WGS 84 / UTM zone 48N at the base point)"``,
    when the base point gives a latitude and longitude; ``""`` when no place is known (no CRS is suggested
    then: one far from the site would be wrong)."""
    from twinkit.geo.crs import utm_epsg

    bp = site_dict(site).get("base_point")
    try:
        lat, lon = float(bp["lat"]), float(bp["lon"])  # type: ignore[index]
    except (TypeError, KeyError, ValueError):
        return ""
    if not (-80.0 <= lat <= 84.0 and -180.0 <= lon <= 180.0):
        return ""  # outside UTM's range (polar) or the globe: no suggestion
    code, zone = utm_epsg(lat, lon)
    return f" (e.g. EPSG:{code}, WGS 84 / UTM {zone} at the base point)"


def georeference_problem(site: Mapping[str, Any] | None, needs: str, instead: str) -> str | None:
    """One line naming the site keys to set when the site has no georeference (``site.crs``, ``site.base_point``)
    and ``needs`` (e.g. "roads from the scan (road_source=scan)") will need one, with ``instead`` (the way to do
    without, e.g. "or road_source=none for a twin without roads"); None when both keys are set (whether they
    are valid is checked where the config is read)."""
    s = site_dict(site)
    missing = [f"site.{k}" for k in ("crs", "base_point") if not s.get(k)]
    if not missing:
        return None
    name = s.get("name", "?")
    todo = ([f"site.crs{crs_example(s)}"] if "site.crs" in missing else []) + (
        ["site.base_point ({lat, lon, alt} or projected {x, y, z})"] if "site.base_point" in missing else [])
    return (f"{' and '.join(missing)}: not set (site '{name}' has no georeference), and {needs} will need "
            f"{'them' if len(missing) > 1 else 'it'}; set {' and '.join(todo)} in conf/site/{name}.yaml or on the "
            f"command line, {instead}")


def check_bbox(south: float, west: float, north: float, east: float) -> tuple[float, float, float, float]:
    """Validate a lon/lat box; raises InputError for boxes crossing the antimeridian or reaching a pole."""
    vals = (south, west, north, east)
    if not all(math.isfinite(v) for v in vals):
        raise InputError(f"bounding box {vals} has non-finite values")
    if west > east:
        raise InputError(f"bounding box west={west} > east={east}: it crosses the antimeridian (180 deg); "
                         "split it into two boxes")
    if not (-180 <= west <= 180 and -180 <= east <= 180):
        raise InputError(f"bounding box longitudes {west}..{east} leave -180..180 (antimeridian); split the box")
    if south >= north:
        raise InputError(f"bounding box south={south} >= north={north}")
    if south <= -89.0 or north >= 89.0:
        raise InputError(f"bounding box latitudes {south}..{north} reach a pole; OSM downloads by box are not "
                         "supported there")
    return south, west, north, east

"""CARLA's geolocation and the frame twinkit writes the CARLA package in.

CARLA 0.9.16 (``LibCarla/source/carla/opendrive/parser/GeoReferenceParser.cpp``) keeps only
``+lat_0`` and ``+lon_0`` of the OpenDRIVE ``geoReference``; ``carla/geom/GeoLocation.cpp``
(``GeoLocation::Transform`` -> ``InverseTransversemercProjection``) turns a location (metres) into
latitude / longitude with a *spherical* transverse Mercator centred on (lat_0, lon_0), radius
6,378,137 m, scale 0.9996, x = east, y = north. The GNSS sensor (``Sensor/GnssSensor.cpp``) and
``carla.Map.transform_to_geolocation`` both use it. :func:`carla_lonlat` is that formula; a test
checks it against the ``carla`` wheel.

Two consequences for a twin:

1. The site frame (the site CRS shifted to the base point) is rotated against true north by the
   meridian convergence and scaled by the CRS's point scale; the spherical formula assumes true
   north and metres at lat_0. So the package is written in the **CARLA frame**: a transverse
   Mercator centred on the base point (``+lat_0``/``+lon_0`` = base point, ``+k`` = scale,
   ``+x_0=+y_0=0``), an exact PROJ string for pyproj and every tool that honours geoReference, and
   the one CARLA reads correctly. The site frame maps into it by a similarity
   (``package = scale * Rz(rotation) * site``; the residual, second order in the distance, is
   :attr:`CarlaFrame.residual_m`).
2. A sphere is not the ellipsoid: at the base point the formula's metres per degree differ from the
   truth by M/(0.9996 a) north and N/(0.9996 a) east (M, N: the ellipsoid's radii of curvature);
   the difference grows linearly with the distance from the base point (0.44 m at 150 m on the demo
   in true metres, 0.78 m at 150 m in Mexico City). One similarity cannot remove the anisotropy
   N/M, but its scale can balance it: :func:`carla_frame` keeps the site frame's metric (a pure
   rotation) when that meets the tolerance, else takes the scale closest to it that does
   (``scale="auto"``).

CARLA 0.9.16 also feeds Unreal's y (= -north: OpenDRIVE y is mirrored into Unreal's left-handed
frame) into the formula as northing, so its latitudes move *south* as an actor moves north (CARLA
issue #1596 fixed this in 2019 by negating y; the 0.9.16 transverse Mercator lost the sign again,
see carla-simulator/carla PR #9552). No right-handed world can undo a mirror, so the error budget
above is that of the formula on north-positive y (what CARLA <= 0.9.15 and the fix compute);
:meth:`CarlaFrame.gnss_to_lonlat` turns what 0.9.16 reports back into the exact position.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from twinkit.geo.frame import SiteFrame

#: CARLA's sphere (GeoLocation.cpp: EARTH_RADIUS_EQUA) and its transverse Mercator scale (k0)
CARLA_EARTH_RADIUS_M = 6378137.0
CARLA_TM_SCALE = 0.9996

SCALE_MODES = ("auto", "site", "true", "minimax")
#: ``scale="auto"`` aims at this fraction below the tolerance (the disc is sampled, CARLA evaluates in float)
AUTO_MARGIN = 0.02


def carla_lonlat(x, y, lat0: float, lon0: float) -> np.ndarray:
    """CARLA 0.9.16's ``GeoLocation::Transform``: location (x, y) metres -> (n, 2) lon, lat degrees.

    ``y`` is the northing the formula assumes. CARLA 0.9.16 passes its Unreal y (= -north) here.
    """
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    kr = CARLA_TM_SCALE * CARLA_EARTH_RADIUS_M
    d = x / kr
    e = y / kr + math.radians(lat0)
    lat = np.arcsin(np.sin(e) / np.cosh(d))
    dlon = np.arctan2(np.sinh(d), np.cos(e))
    return np.stack([lon0 + np.degrees(dlon), np.degrees(lat)], -1).reshape(-1, 2)


def carla_xy(lon, lat, lat0: float, lon0: float) -> np.ndarray:
    """The inverse of :func:`carla_lonlat` (CARLA's ``GeoLocation::GeoLocationToTransform``): (n, 2) x, y."""
    phi = np.radians(np.asarray(lat, float))
    dl = np.radians(np.asarray(lon, float) - lon0)
    kr = CARLA_TM_SCALE * CARLA_EARTH_RADIUS_M
    b = np.cos(phi) * np.sin(dl)
    x = 0.5 * kr * np.log((1 + b) / (1 - b))
    y = kr * (np.arctan2(np.tan(phi), np.cos(dl)) - math.radians(lat0))
    return np.stack([x, y], -1).reshape(-1, 2)


def _disc(radius_m: float, rings: int = 12, per_ring: int = 48) -> np.ndarray:
    """Points of the disc of ``radius_m``: the centre and ``rings`` circles (the last on the edge)."""
    pts = [np.zeros((1, 2))]
    a = np.linspace(0, 2 * np.pi, per_ring, endpoint=False)
    for r in np.linspace(radius_m / rings, radius_m, rings):
        pts.append(np.stack([r * np.cos(a), r * np.sin(a)], 1))
    return np.concatenate(pts)


def _ellps(site: "SiteFrame") -> str:
    """The PROJ ellipsoid name of the site CRS (WGS84 when PROJ names none)."""
    import warnings

    from pyproj import CRS

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = CRS.from_user_input(site.projected).to_dict()
    return str(d.get("ellps") or d.get("datum") or "WGS84")


def _geod_m(ll_a: np.ndarray, ll_b: np.ndarray) -> np.ndarray:
    """Ellipsoidal distance (m, WGS84) between rows of two (n, 2) lon/lat arrays."""
    from pyproj import Geod

    _, _, d = Geod(ellps="WGS84").inv(ll_a[:, 0], ll_a[:, 1], ll_b[:, 0], ll_b[:, 1])
    return np.abs(np.asarray(d, float))


@dataclass(frozen=True)
class CarlaFrame:
    """The frame of the CARLA package: ``package = scale * Rz(rotation) * site`` (x, y and z).

    rotation_rad: counter-clockwise rotation from the site frame to true-north axes at the base point
    scale: package metres per site-frame metre (1.0: the site geometry keeps its size)
    k: the transverse Mercator's scale (package metres per true metre at the base point)
    lat, lon: the base point (= +lat_0 / +lon_0, = CARLA's geolocation of the origin)
    ellps: the ellipsoid of the site CRS
    residual_m: largest distance between the similarity and the exact projection over ``radius_m``
    carla_error_m: largest / mean error of CARLA's formula over ``radius_m`` (north-positive y)
    """

    rotation_rad: float
    scale: float
    k: float
    lat: float
    lon: float
    ellps: str
    radius_m: float
    mode: str
    residual_m: float = 0.0
    carla_error_max_m: float = 0.0
    carla_error_mean_m: float = 0.0
    where: str = ""

    # ------------------------------------------------------------------ the PROJ string
    def geo_reference(self) -> str:
        """The OpenDRIVE geoReference: exact for pyproj, and the +lat_0 / +lon_0 CARLA reads."""
        return (f"+proj=tmerc +lat_0={self.lat!r} +lon_0={self.lon!r} +k={self.k!r} +x_0=0 +y_0=0 "
                f"+ellps={self.ellps} +units=m +no_defs")

    @property
    def measured(self) -> str:
        """Where :attr:`carla_error_max_m` and :attr:`residual_m` were measured, in words."""
        return self.where or f"within {self.radius_m:g} m of the base point"

    # ------------------------------------------------------------------ the similarity
    @property
    def matrix(self) -> np.ndarray:
        """3x3 matrix of ``package = M @ site`` (rotation about z times scale)."""
        c, s = math.cos(self.rotation_rad), math.sin(self.rotation_rad)
        return self.scale * np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    def site_to_package(self, xyz) -> np.ndarray:
        """(n, 2) or (n, 3) site-frame points -> the package frame (same shape)."""
        p = np.asarray(xyz, float)
        m = self.matrix[: p.shape[-1], : p.shape[-1]]
        return p @ m.T

    def package_to_site(self, xyz) -> np.ndarray:
        p = np.asarray(xyz, float)
        m = np.linalg.inv(self.matrix)[: p.shape[-1], : p.shape[-1]]
        return p @ m.T

    # ------------------------------------------------------------------ geolocation
    def package_to_lonlat(self, xy) -> np.ndarray:
        """(n, 2) package-frame x, y (north-positive) -> (n, 2) lon, lat by the exact geoReference (pyproj)."""
        from pyproj import Transformer

        xy = np.asarray(xy, float).reshape(-1, 2)
        lon, lat = Transformer.from_crs(self.geo_reference(), "EPSG:4326", always_xy=True).transform(xy[:, 0], xy[:, 1])
        return np.stack([np.asarray(lon, float), np.asarray(lat, float)], 1)

    def lonlat_to_package(self, lonlat) -> np.ndarray:
        from pyproj import Transformer

        ll = np.asarray(lonlat, float).reshape(-1, 2)
        x, y = Transformer.from_crs("EPSG:4326", self.geo_reference(), always_xy=True).transform(ll[:, 0], ll[:, 1])
        return np.stack([np.asarray(x, float), np.asarray(y, float)], 1)

    def carla_lonlat(self, xy) -> np.ndarray:
        """CARLA's formula at package points (x, y north-positive)."""
        xy = np.asarray(xy, float).reshape(-1, 2)
        return carla_lonlat(xy[:, 0], xy[:, 1], self.lat, self.lon)

    def gnss_to_lonlat(self, lat, lon) -> np.ndarray:
        """What CARLA 0.9.16 reports (GNSS sensor, ``transform_to_geolocation`` of a world location) -> the
        exact (n, 2) lon, lat: undo CARLA's formula, undo its y mirror, apply the exact geoReference."""
        xy = carla_xy(lon, lat, self.lat, self.lon)
        xy[:, 1] = -xy[:, 1]
        return self.package_to_lonlat(xy)

    def to_json(self) -> dict:
        return {"geo_reference": self.geo_reference(), "rotation_deg": math.degrees(self.rotation_rad),
                "scale": self.scale, "k": self.k, "mode": self.mode, "radius_m": self.radius_m,
                "similarity_residual_m": self.residual_m, "carla_error_max_m": self.carla_error_max_m,
                "carla_error_mean_m": self.carla_error_mean_m, "measured": self.measured,
                "frame": "package = scale * Rz(rotation) * site (x east, y north, z up, origin at the base point); "
                         "CARLA Location = (x, -y, z)"}


class _ErrorField:
    """CARLA's formula against the exact tmerc(lat, lon, k) over the disc of ``radius_m``, for any k.

    The exact position of package point ``k * u`` is that of ``u`` in the k=1 tmerc, so the true lon/lat
    are projected once and each k costs only CARLA's formula and a geodesic distance.
    """

    def __init__(self, lat: float, lon: float, ellps: str, radius_m: float, u: np.ndarray | None = None):
        from pyproj import Transformer

        self.lat, self.lon = lat, lon
        self.u = _disc(radius_m) if u is None else np.asarray(u, float).reshape(-1, 2)
        tm = _tm1(lat, lon, ellps)
        lon_t, lat_t = Transformer.from_crs(tm, "EPSG:4326", always_xy=True).transform(self.u[:, 0], self.u[:, 1])
        self.truth = np.stack([np.asarray(lon_t, float), np.asarray(lat_t, float)], 1)

    def __call__(self, k: float) -> tuple[float, float]:
        p = self.u * k
        d = _geod_m(self.truth, carla_lonlat(p[:, 0], p[:, 1], self.lat, self.lon))
        return float(d.max()), float(d.mean())


def carla_error(lat: float, lon: float, k: float, ellps: str, radius_m: float) -> tuple[float, float]:
    """(max, mean) metres between CARLA's formula and the exact tmerc(lat, lon, k) over the disc of ``radius_m``
    (true metres)."""
    return _ErrorField(lat, lon, ellps, radius_m)(k)


def _tm1(lat: float, lon: float, ellps: str) -> str:
    """The k=1 transverse Mercator centred on (lat, lon)."""
    return f"+proj=tmerc +lat_0={lat!r} +lon_0={lon!r} +k=1 +x_0=0 +y_0=0 +ellps={ellps} +units=m +no_defs"


def _fit(site: "SiteFrame", xy: np.ndarray, ellps: str) -> tuple[complex, np.ndarray]:
    """Least-squares similarity (no translation: both frames have the base point at 0) from the site frame
    to the k=1 transverse Mercator at the base point, over the site-frame points ``xy``; returns (a, w) with
    package = a * site (complex) and w the points' (n, 2) k=1 transverse Mercator coordinates."""
    from pyproj import Transformer

    ll = site.local_to_lonlat(xy)
    x, y = Transformer.from_crs("EPSG:4326", _tm1(site.lat, site.lon, ellps), always_xy=True).transform(ll[:, 0], ll[:, 1])
    z = xy[:, 0] + 1j * xy[:, 1]
    w = np.asarray(x) + 1j * np.asarray(y)
    a = complex(np.sum(np.conj(z) * w) / max(float(np.sum(np.abs(z) ** 2)), 1e-12))
    return a, np.stack([w.real, w.imag], 1)


def where_text(points: np.ndarray) -> str:
    """Where ``points`` (site-frame x, y) lie, in words: how many, how far from the base point, their box."""
    p = np.asarray(points, float).reshape(-1, 2)
    d = np.hypot(p[:, 0], p[:, 1])
    lo, hi = p.min(0), p.max(0)
    return (f"at {len(p)} points of the twin, {d.min():.0f}-{d.max():.0f} m from the base point (site box x "
            f"{lo[0]:.0f}..{hi[0]:.0f}, y {lo[1]:.0f}..{hi[1]:.0f} m)")


def carla_frame(site: "SiteFrame", radius_m: float = 150.0, tolerance_m: float = 0.5,
                scale: str = "auto", points=None) -> CarlaFrame:
    """The CARLA package frame of ``site``.

    points: site-frame x, y where the twin is (its meshes, its map); the similarity is fitted, and CARLA's error
    measured and balanced, at these points (:attr:`CarlaFrame.measured` says so). Without them, over the disc of
    ``radius_m`` about the base point.

    scale: ``site`` keeps the site frame's metric (pure rotation); ``true`` makes package metres true
    metres at the base point; ``minimax`` minimises CARLA's formula error over the disc of ``radius_m``;
    ``auto`` (default) is ``site`` when that meets ``tolerance_m`` (less :data:`AUTO_MARGIN`), else the
    scale closest to it that does (``minimax`` when none does: see :attr:`CarlaFrame.carla_error_max_m`).
    """
    from twinkit.errors import InputError

    if scale not in SCALE_MODES:
        raise InputError(f"carla frame: scale={scale!r}; use one of {', '.join(SCALE_MODES)}")
    if not radius_m > 0:
        raise InputError(f"carla frame: radius_m must be positive, got {radius_m}")
    ellps = _ellps(site)
    xy = _disc(radius_m) if points is None else np.asarray(points, float)[..., :2].reshape(-1, 2)
    if not len(xy):
        raise InputError("carla frame: no points of the twin to measure CARLA's geolocation at")
    a, w = _fit(site, xy, ellps)
    c = abs(a)  # true metres per site metre near the base point (1 / the CRS's point scale)
    rot = math.atan2(a.imag, a.real)

    field = _ErrorField(site.lat, site.lon, ellps, radius_m, u=None if points is None else w)
    target = tolerance_m * (1.0 - AUTO_MARGIN)

    def err(k: float) -> float:
        return field(k)[0]

    # the formula's error is the max of terms linear in k: one minimum, found by golden section
    lo, hi = 0.98, 1.02
    g = (math.sqrt(5) - 1) / 2
    for _ in range(60):
        m1, m2 = hi - g * (hi - lo), lo + g * (hi - lo)
        if err(m1) < err(m2):
            hi = m2
        else:
            lo = m1
    k_opt = 0.5 * (lo + hi)
    k_site = 1.0 / c
    if scale == "site":
        k = k_site
    elif scale == "true":
        k = 1.0
    elif scale == "minimax":
        k = k_opt
    else:
        k = k_site
        if err(k_site) > target:
            if err(k_opt) > target:
                k = k_opt
            else:  # bisect between the site scale and the optimum for the boundary of the tolerance
                a_, b_ = k_site, k_opt
                for _ in range(60):
                    mid = 0.5 * (a_ + b_)
                    if err(mid) > target:
                        a_ = mid
                    else:
                        b_ = mid
                k = b_
    emax, emean = field(k)
    f = CarlaFrame(rotation_rad=rot, scale=1.0 if k == k_site else k * c, k=k, lat=site.lat, lon=site.lon, ellps=ellps,
                   radius_m=float(radius_m), mode=scale, carla_error_max_m=emax, carla_error_mean_m=emean,
                   where="" if points is None else where_text(xy))
    # residual of the similarity against the exact geoReference, at the same points
    if points is None:
        xy = xy / max(f.scale, 1e-12)
    d = _geod_m(site.local_to_lonlat(xy), f.package_to_lonlat(f.site_to_package(xy)))
    return CarlaFrame(**{**f.__dict__, "residual_m": float(d.max())})


def carla_xodr(text: str, frame: CarlaFrame, name: str) -> str:
    """The OpenDRIVE ``text`` (site frame) moved into ``frame``: the one CARLA geolocates (its geoReference the
    frame's exact PROJ string; the site-frame string kept in a header ``userData``). Used by the CARLA package and
    by ``recipe=roads``'s ``roads_carla.xodr``."""
    from twinkit.errors import InputError
    from twinkit.geo.xodr import XodrFrameError, transform_xodr

    try:
        return transform_xodr(text, frame.rotation_rad, frame.scale, frame.geo_reference(), name=name)
    except XodrFrameError as exc:
        raise InputError(str(exc)) from None


def wheel_error(carla_text: str, frame: CarlaFrame, site: "SiteFrame", site_xy) -> dict:
    """CARLA's geolocation of the map ``carla_text`` (in ``frame``) measured with the ``carla`` wheel
    (``transform_to_geolocation`` of :class:`twinkit.street.lanes.LaneMap`) at the site-frame points ``site_xy``, against their exact
    position (the site frame's geoReference): max / mean metres, on north-positive y (see the module's note)."""
    from twinkit.street.lanes import LaneMap

    xy = np.asarray(site_xy, float)[..., :2].reshape(-1, 2)
    got = LaneMap(carla_text, "twinkit_geolocation").geolocation(frame.site_to_package(xy))
    d = _geod_m(site.local_to_lonlat(xy), got)
    return {"carla_error_max_m": float(d.max()), "carla_error_mean_m": float(d.mean()), "points": int(len(xy)),
            "measured": where_text(xy).replace("of the twin", "of the map"), "tool": "carla wheel " + _wheel_version()}


def _wheel_version() -> str:
    try:
        from importlib.metadata import version

        return version("carla")
    except Exception:  # noqa: BLE001 (a version label only)
        return "?"


def landed_text(site: "SiteFrame", xy) -> str:
    """Where site-frame points ``xy`` (a map's roads) lie on the Earth, in words: their middle's latitude and
    longitude and its ellipsoidal distance from the base point (for a message about a map far from the site)."""
    p = np.asarray(xy, float)[..., :2].reshape(-1, 2)
    mid = np.median(p, 0).reshape(1, 2)
    ll = site.local_to_lonlat(mid)
    d = float(_geod_m(ll, np.array([[site.lon, site.lat]]))[0])
    lon, lat = float(ll[0, 0]), float(ll[0, 1])
    far = f"{d / 1000:,.1f} km" if d >= 1000 else f"{d:.0f} m"
    return (f"{abs(lat):.2f} {'N' if lat >= 0 else 'S'}, {abs(lon):.2f} {'E' if lon >= 0 else 'W'}, "
            f"{far} from the base point ({site.lat:.5f}, {site.lon:.5f})")

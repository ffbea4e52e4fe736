"""East-north-up (ENU) tangent frames: what geospatial consumers of a 3D scene assume, and the site frame mapped into one.

Geospatial scene schemas place a stage by one reference point (latitude, longitude, height above the
WGS84 ellipsoid) and read the stage's coordinates as metres in the local tangent plane there: a stage
point p (x east, y north, z up) is ``ECEF(reference) + R_enu^T @ p`` in earth-centred earth-fixed
coordinates, then geodetic latitude / longitude / height (NVIDIA Omniverse's
``OmniWGS84ReferencePositionAPI`` with ``tangentPlane = ENU``; Cesium's georeference origin on a Z-up
stage). :func:`enu_to_lonlat` is that reading rule, :func:`lonlat_to_enu` its inverse, both through
pyproj's geodetic <-> ECEF conversion (EPSG:4979 <-> EPSG:4978).

The site frame (:class:`twinkit.geo.frame.SiteFrame`) is a projected grid: its y axis is *grid* north,
turned from true north by the meridian convergence, and its metres are grid metres (the CRS's point scale
k). Read as ENU without a transform, a point 150 m from the base point lands metres away (TM35FIN at
24.93 E: 1.79 deg, 3.1 m per 100 m). :func:`site_to_enu` fits the one similarity (rotation about z and a
horizontal scale; heights stay metres) that takes the site frame into the ENU frame at its base point,
with the residual over a disc stated.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from twinkit.geo.frame import SiteFrame


def _enu_rotation(lat_deg: float, lon_deg: float) -> np.ndarray:
    """(3, 3) rows east, north, up of the tangent plane at (lat, lon), in ECEF axes."""
    la, lo = math.radians(lat_deg), math.radians(lon_deg)
    return np.array([[-math.sin(lo), math.cos(lo), 0.0],
                     [-math.sin(la) * math.cos(lo), -math.sin(la) * math.sin(lo), math.cos(la)],
                     [math.cos(la) * math.cos(lo), math.cos(la) * math.sin(lo), math.sin(la)]])


def _ecef(lon, lat, h) -> np.ndarray:
    from pyproj import Transformer

    x, y, z = Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True).transform(lon, lat, h)
    return np.stack([np.asarray(x, float), np.asarray(y, float), np.asarray(z, float)], -1).reshape(-1, 3)


def enu_to_lonlat(enu, lat0: float, lon0: float, h0: float) -> np.ndarray:
    """The geospatial schemas' reading rule: (n, 3) ENU metres at the reference (``lat0``, ``lon0`` degrees,
    ``h0`` m above the WGS84 ellipsoid) -> (n, 3) lon, lat (degrees), ellipsoidal height (m)."""
    from pyproj import Transformer

    p = np.asarray(enu, float).reshape(-1, 3)
    ecef = _ecef(lon0, lat0, h0)[0] + p @ _enu_rotation(lat0, lon0)
    lon, lat, h = Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True).transform(
        ecef[:, 0], ecef[:, 1], ecef[:, 2])
    return np.stack([np.asarray(lon, float), np.asarray(lat, float), np.asarray(h, float)], -1).reshape(-1, 3)


def lonlat_to_enu(lonlath, lat0: float, lon0: float, h0: float) -> np.ndarray:
    """(n, 3) lon, lat (degrees), ellipsoidal height (m) -> (n, 3) ENU metres at the reference point."""
    q = np.asarray(lonlath, float).reshape(-1, 3)
    d = _ecef(q[:, 0], q[:, 1], q[:, 2]) - _ecef(lon0, lat0, h0)[0]
    return d @ _enu_rotation(lat0, lon0).T


@dataclass(frozen=True)
class EnuFrame:
    """The ENU frame at a site's base point and the similarity from the site frame into it:
    ``enu = scale * Rz(rotation) * (x, y) , z`` (heights are not scaled).

    rotation_rad: counter-clockwise angle from the site frame's axes to true east / north (= minus the grid
    convergence at the base point)
    scale: ENU metres per site-frame metre, horizontally (1 / the CRS's point scale at the base point)
    lat, lon: the reference point (the base point, WGS84 degrees); height_m: its height as written for
    consumers (see ``height_reference``)
    residual_m: largest horizontal distance, over ``radius_m`` about the base point, between the similarity
    and the exact ENU coordinates of the site point (second order in the distance)
    """

    rotation_rad: float
    scale: float
    lat: float
    lon: float
    height_m: float
    radius_m: float
    residual_m: float

    def matrix(self) -> np.ndarray:
        """(4, 4) site frame -> ENU, column vectors (``enu = M @ [x, y, z, 1]``)."""
        c, s = math.cos(self.rotation_rad) * self.scale, math.sin(self.rotation_rad) * self.scale
        return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], float)

    def apply(self, xyz) -> np.ndarray:
        """(n, 3) site frame -> (n, 3) ENU metres at the base point."""
        p = np.asarray(xyz, float).reshape(-1, 3)
        return p @ self.matrix()[:3, :3].T


def site_to_enu(frame: "SiteFrame", height_m: float, radius_m: float = 150.0) -> EnuFrame:
    """The :class:`EnuFrame` of ``frame``: the least-squares similarity (rotation about z and horizontal scale,
    no shift: the base point is the origin of both) from site-frame points on a disc of ``radius_m`` to their
    exact ENU coordinates (site -> lon/lat by the site CRS -> ECEF -> ENU at the base point). ``height_m``: the
    base point's height to write for consumers (ellipsoidal where known); it moves no point horizontally."""
    from twinkit.geo.carla import _disc

    xy = _disc(radius_m)
    ll = frame.local_to_lonlat(xy)
    enu = lonlat_to_enu(np.c_[ll, np.full(len(ll), height_m)], frame.lat, frame.lon, height_m)[:, :2]
    # planar similarity without translation: complex ratio enu / xy by least squares
    a = xy[:, 0] + 1j * xy[:, 1]
    b = enu[:, 0] + 1j * enu[:, 1]
    z = complex(np.vdot(a, b) / np.vdot(a, a))
    f = EnuFrame(rotation_rad=math.atan2(z.imag, z.real), scale=abs(z), lat=frame.lat, lon=frame.lon,
                 height_m=float(height_m), radius_m=float(radius_m), residual_m=0.0)
    res = np.hypot(*(f.apply(np.c_[xy, np.zeros(len(xy))])[:, :2] - enu).T)
    return EnuFrame(**{**f.__dict__, "residual_m": float(res.max())})

"""CARLA's geolocation (twinkit.geo.carla) against the carla 0.9.16 wheel and pyproj.

Rules encoded (CARLA 0.9.16 source):
- LibCarla/source/carla/opendrive/parser/GeoReferenceParser.cpp: only +lat_0 / +lon_0 of the
  geoReference are kept for the geolocation.
- LibCarla/source/carla/geom/GeoLocation.cpp: GeoLocation::Transform is a spherical transverse
  Mercator (radius 6378137 m, k0 0.9996) centred on (lat_0, lon_0), taking the location's y as northing
  (Unreal's y = -north: the 0.9.16 latitude mirror, carla-simulator/carla PR #9552).
"""
import math

import numpy as np
import pytest

from twinkit import InputError
from twinkit.geo import SiteFrame
from twinkit.geo.carla import carla_lonlat, carla_xy

carla = pytest.importorskip("carla")

SITES = {
    # name: (crs, lat, lon) -- the demo (TM35FIN, 1.8 deg convergence), a UTM site, a large convergence
    "demo": ("EPSG:3067", 60.16945, 24.93365),
    "mex": ("EPSG:32614", 19.4326, -99.1332),
    "haparanda": ("EPSG:3006", 65.8356, 24.1383),  # SWEREF99 TM, 9 deg from its central meridian: -8.3 deg
}
RADIUS = 150.0


def _xodr(geo: str) -> str:
    """A one-road OpenDRIVE with ``geo`` as its geoReference (carla.Map needs a road to parse)."""
    return f"""<?xml version="1.0"?><OpenDRIVE><header revMajor="1" revMinor="4"><geoReference><![CDATA[{geo}]]>
</geoReference></header><road name="r" length="10" id="1" junction="-1"><planView><geometry s="0" x="0" y="0" hdg="0"
length="10"><line/></geometry></planView><lanes><laneSection s="0"><center><lane id="0" type="none" level="false"/>
</center><right><lane id="-1" type="driving" level="false"><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane>
</right></laneSection></lanes></road></OpenDRIVE>"""


def _grid(radius: float, step: float = 10.0) -> np.ndarray:
    g = np.arange(-radius, radius + 1e-9, step)
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    a = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    edge = radius * np.stack([np.cos(a), np.sin(a)], 1)
    return np.concatenate([xy[np.hypot(xy[:, 0], xy[:, 1]) <= radius], edge])


def _wheel(m, xy: np.ndarray) -> np.ndarray:
    out = []
    for x, y in xy:
        g = m.transform_to_geolocation(carla.Location(float(x), float(y), 0.0))
        out.append((g.longitude, g.latitude))
    return np.array(out)


def _dist_m(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    from pyproj import Geod

    return np.abs(np.asarray(Geod(ellps="WGS84").inv(a[:, 0], a[:, 1], b[:, 0], b[:, 1])[2]))


def test_carla_formula_is_the_wheels():
    m = carla.Map("f", _xodr("+proj=tmerc +lat_0=60.16945 +lon_0=24.93365"))
    xy = _grid(2000.0, 250.0)
    np.testing.assert_allclose(_wheel(m, xy), carla_lonlat(xy[:, 0], xy[:, 1], 60.16945, 24.93365), atol=1e-9)
    back = carla_xy(*carla_lonlat(xy[:, 0], xy[:, 1], 60.16945, 24.93365).T, 60.16945, 24.93365)
    np.testing.assert_allclose(back, xy, atol=1e-6)


def test_the_site_frame_string_puts_carla_on_the_equator():
    """Today's geoReference (the exact site frame) gives CARLA (lat_0, lon_0) = (0, 27): 6,675 km off."""
    sf = SiteFrame.from_site({"crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365}})
    g = carla.Map("s", _xodr(sf.proj_string())).transform_to_geolocation(carla.Location(0, 0, 0))
    assert (g.latitude, g.longitude) == (0.0, 27.0)


@pytest.mark.parametrize("site", sorted(SITES))
def test_carla_geolocation_within_half_a_metre_over_150_m(site):
    crs, lat, lon = SITES[site]
    sf = SiteFrame.from_site({"crs": crs, "base_point": {"lat": lat, "lon": lon}})
    f = sf.carla_frame(radius_m=RADIUS, tolerance_m=0.5)
    geo = f.geo_reference()
    m = carla.Map(site, _xodr(geo))
    site_xy = _grid(RADIUS)
    truth = sf.local_to_lonlat(site_xy)  # pyproj, the site CRS
    pkg = f.site_to_package(site_xy)
    # the geoReference is exact for pyproj: package point -> the site point's lon/lat within a millimetre
    assert _dist_m(f.package_to_lonlat(pkg), truth).max() < 1e-3
    # CARLA's formula on north-positive y (CARLA <= 0.9.15's convention, and the fix of PR #9552)
    err = _dist_m(_wheel(m, pkg), truth)
    assert err.max() <= 0.5, (site, err.max())
    assert err.max() == pytest.approx(f.carla_error_max_m, abs=0.02)
    # CARLA 0.9.16 on its own world location (x, -y): latitudes mirrored about the base point
    world = np.stack([pkg[:, 0], -pkg[:, 1]], 1)
    reported = _wheel(m, world)
    mirrored = _dist_m(reported, truth)
    far = np.abs(pkg[:, 1]) > 50
    assert np.all(mirrored[far] > 1.9 * np.abs(pkg[far, 1]) - 1.0)
    # ... which twinkit turns back into the exact position
    fixed = f.gnss_to_lonlat(reported[:, 1], reported[:, 0])
    assert _dist_m(fixed, truth).max() < 0.01


def test_rotation_and_scale_are_the_convergence_and_point_scale():
    """The fitted similarity is the CRS's meridian convergence and point scale (pyproj's factors)."""
    from pyproj import CRS, Proj

    for crs, lat, lon in SITES.values():
        sf = SiteFrame.from_site({"crs": crs, "base_point": {"lat": lat, "lon": lon}})
        f = sf.carla_frame(scale="site")
        fac = Proj(CRS.from_user_input(crs)).get_factors(lon, lat)
        assert math.degrees(f.rotation_rad) == pytest.approx(-fac.meridian_convergence, abs=1e-4)
        assert f.k == pytest.approx(fac.meridional_scale, abs=1e-6)
        assert f.scale == 1.0 and f.residual_m < 1e-3


def test_scale_modes():
    crs, lat, lon = SITES["mex"]
    sf = SiteFrame.from_site({"crs": crs, "base_point": {"lat": lat, "lon": lon}})
    site, true, auto, best = (sf.carla_frame(scale=s) for s in ("site", "true", "auto", "minimax"))
    # in Mexico City the sphere's metres are too short north-south: neither the site nor true metres meet 0.5 m
    assert site.carla_error_max_m > 0.75 and true.carla_error_max_m > 0.75
    assert best.carla_error_max_m < auto.carla_error_max_m <= 0.5
    assert abs(auto.scale - 1) < abs(best.scale - 1)  # auto: the smallest change of size that meets the tolerance
    demo = SiteFrame.from_site({"crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365}})
    assert demo.carla_frame().scale == 1.0  # the demo meets it with a pure rotation
    with pytest.raises(InputError, match="scale"):
        demo.carla_frame(scale="bigger")


def test_similarity_round_trip():
    sf = SiteFrame.from_site({"crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365}})
    f = sf.carla_frame(scale="minimax")
    p = np.array([[10.0, -20.0, 3.0], [-140.0, 5.0, -1.0]])
    np.testing.assert_allclose(f.package_to_site(f.site_to_package(p)), p, atol=1e-9)
    q = f.site_to_package(p)
    assert q[0, 2] == pytest.approx(3.0 * f.scale)  # z scales with x, y: a similarity
    np.testing.assert_allclose(np.linalg.norm(q[:, :2], axis=1), f.scale * np.linalg.norm(p[:, :2], axis=1))

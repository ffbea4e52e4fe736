"""File CRS -> site frame rules (twinkit.geo.crs), and that they agree with the site frame."""
import numpy as np
import pytest
from pyproj import Transformer

from twinkit import InputError
from twinkit.geo import (SiteFrame, apply_frame, base_point_in, parse_crs, short_crs, to_site_frame,
                         unit_factors)

DEMO_SITE = {"name": "demo", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 12.0}}
FT = 0.3048  # international foot
US_FT = 1200 / 3937


def test_unit_factors_and_names():
    assert unit_factors(parse_crs("EPSG:3067")) == (1.0, 1.0)
    fxy, fz = unit_factors(parse_crs("EPSG:2992"))  # Oregon Lambert, international feet
    assert fxy == pytest.approx(FT) and fz == fxy
    fxy, fz = unit_factors(parse_crs("EPSG:2263+6360"))  # NY Long Island (US ft) + NAVD88 height (US ft)
    assert fxy == pytest.approx(US_FT) and fz == pytest.approx(US_FT)
    assert unit_factors(parse_crs("EPSG:3067+3900")) == (1.0, 1.0)
    assert parse_crs(None) is None and parse_crs("") is None
    assert short_crs(parse_crs("EPSG:3067").to_wkt()) == "EPSG:3067"


@pytest.mark.parametrize("site", [
    DEMO_SITE,
    {"crs": "EPSG:3067+3900", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 12.0}},
    {"crs": "EPSG:2992", "base_point": {"lat": 45.5, "lon": -122.6, "alt": 3.0}},  # feet
    {"crs": "EPSG:2263", "base_point": {"x": 988000.0, "y": 215000.0, "z": 30.0}},  # US feet, projected base
    {"crs": "EPSG:2154", "base_point": {"x": 652000.0, "y": 6862000.0, "z": 30.0}},
])
def test_the_base_point_is_the_site_frames_origin(site):
    """One rule: the shift a cloud gets is the site frame's base point, in metres, for every kind of CRS
    and base point (x, y are in the CRS's units, as in SiteFrame)."""
    f = SiteFrame.from_site(site)
    bp = base_point_in(parse_crs(site["crs"]), site)
    assert bp == pytest.approx([f.easting * f.unit_m, f.northing * f.unit_m, f.alt], abs=1e-6)


def test_a_feet_cloud_lands_where_the_site_frame_puts_it():
    site = {"name": "portland", "crs": "EPSG:2992", "base_point": {"lat": 45.5, "lon": -122.6, "alt": 3.0}}
    f = SiteFrame.from_site(site)
    local = np.array([[0.0, 0.0, 0.0], [120.0, -45.0, 2.0], [-300.0, 250.0, 9.0]])
    en = f.local_to_projected(local[:, :2])  # feet
    file_xyz = np.c_[en, (local[:, 2] + f.alt) / FT]
    got, info = to_site_frame(file_xyz, "EPSG:2992", site, "cloud.las")
    assert info.shift_source == "base_point" and info.unit_factor_xy == pytest.approx(FT)
    assert np.abs(got[:, :2] - local[:, :2]).max() < 1e-6
    # the same base point given in projected feet gives the same frame: x, y and z in the CRS's feet
    site_xy = dict(site, base_point={"x": f.easting, "y": f.northing, "z": 3.0 / FT})
    again, _ = to_site_frame(file_xyz, "EPSG:2992", site_xy, "cloud.las")
    assert np.abs(again - got).max() < 1e-6


def test_a_cloud_in_another_crs_is_reprojected_into_the_site_frame():
    f = SiteFrame.from_site(DEMO_SITE)
    local = np.array([[0.0, 0.0], [40.0, -25.0], [-60.0, 55.0]])
    ll = f.local_to_lonlat(local)
    e, n = Transformer.from_crs("EPSG:4326", "EPSG:32635", always_xy=True).transform(ll[:, 0], ll[:, 1])
    file_xyz = np.c_[e, n, [12.0, 13.0, 14.0]]
    got, info = to_site_frame(file_xyz, "EPSG:32635", DEMO_SITE, "scan.e57")
    assert info.reprojected and info.shift_source == "base_point"
    assert np.abs(got[:, :2] - local).max() < 1e-6 and got[:, 2] == pytest.approx([0.0, 1.0, 2.0])
    scanners = apply_frame(np.r_[file_xyz[:1], [[np.nan] * 3]], "EPSG:32635", DEMO_SITE, info)
    assert np.abs(scanners[0] - got[0]).max() < 1e-9 and np.isnan(scanners[1]).all()


def test_local_clouds_rounded_centres_and_wrong_crs():
    small = np.array([[1.0, 2.0, 0.5], [10.0, -4.0, 1.0]])
    got, info = to_site_frame(small, None, {"name": "t"}, "a.ply")
    assert np.array_equal(got, small) and info.shift == [0.0, 0.0, 0.0] and info.shift_source == "none"
    far = small + [652123.0, 6862456.0, 30.4]
    got, info = to_site_frame(far, None, {"name": "t"}, "a.ply")
    assert info.shift_source == "rounded_centre" and info.shift == [652100.0, 6862500.0, 31.0]
    with pytest.raises(InputError, match="wrong CRS"):
        to_site_frame(far, "EPSG:2154", dict(DEMO_SITE, crs="EPSG:2154"), "a.ply")
    with pytest.raises(InputError, match="geographic"):
        to_site_frame(np.array([[24.9, 60.1, 0.0]]), "EPSG:4326", {"name": "t"}, "a.ply")

"""The site frame (twinkit.geo.frame): definition, conversions, the netconvert PROJ string, bad input."""
import numpy as np
import pytest

from twinkit import InputError
from twinkit.geo import SiteFrame, check_bbox

DEMO_SITE = {"name": "demo", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 12.0}}


def test_site_frame_matches_the_demo_definition():
    f = SiteFrame.from_site(DEMO_SITE)
    # the demo generator's own numbers (site.json): local = projected - base_point_projected
    assert f.easting == pytest.approx(385346.25059729954, abs=1e-6)
    assert f.northing == pytest.approx(6672076.517834117, abs=1e-6)
    xy = np.array([[0.0, 0.0], [123.4, -56.7], [-300.0, 300.0]])
    back = f.lonlat_to_local(f.local_to_lonlat(xy))
    assert np.abs(back - xy).max() < 1e-6
    assert np.allclose(f.local_to_lonlat([[0, 0]])[0], [24.93365, 60.16945], atol=1e-10)
    assert f.local_to_height([0.5])[0] == pytest.approx(12.5)


def test_projected_base_point_gives_the_same_frame():
    f = SiteFrame.from_site(DEMO_SITE)
    g = SiteFrame.from_site({"crs": "EPSG:3067", "base_point": {"x": f.easting, "y": f.northing, "z": 12.0}})
    assert g.lat == pytest.approx(f.lat, abs=1e-9) and g.lon == pytest.approx(f.lon, abs=1e-9) and g.alt == 12.0


def test_netconvert_projection_reproduces_the_site_frame_but_tmerc_at_base_does_not():
    f = SiteFrame.from_site(DEMO_SITE)
    assert f.proj_string_error(f.proj_string(), 1000.0) < 1e-3
    # a transverse Mercator at the base point is rotated by the meridian convergence (~1.8 deg here)
    err300 = f.proj_string_error(f.tmerc_at_base(), 300.0)
    assert err300 > 5.0


@pytest.mark.parametrize("crs,bp", [("EPSG:2992", {"lat": 45.5, "lon": -122.6, "alt": 0}),  # Oregon Lambert, feet
                                    ("EPSG:32633", {"lat": 48.19212, "lon": 16.2955, "alt": 200}),  # UTM 33N
                                    ("EPSG:4326", {"lat": 48.19212, "lon": 16.2955, "alt": 200})])  # geographic
def test_other_crs_kinds(crs, bp):
    f = SiteFrame.from_site({"crs": crs, "base_point": bp})
    assert f.proj_string_error(f.proj_string(), 500.0) < 1e-3
    assert np.abs(f.lonlat_to_local([[bp["lon"], bp["lat"]]])).max() < 1e-6


def test_bad_georeference():
    with pytest.raises(InputError, match="unknown CRS"):
        SiteFrame.from_site({"crs": "EPSG:999999", "base_point": {"lat": 0, "lon": 0}})
    with pytest.raises(InputError, match="no georeference"):
        SiteFrame.from_site({"name": "nowhere"})
    with pytest.raises(InputError, match="pole"):
        SiteFrame.from_site({"crs": "EPSG:4326", "base_point": {"lat": 89.95, "lon": 0}})


def test_boxes_across_the_antimeridian_or_a_pole_are_refused():
    f = SiteFrame.from_site({"crs": "EPSG:4326", "base_point": {"lat": -16.5, "lon": 179.9995}})  # Fiji
    with pytest.raises(InputError, match="antimeridian"):
        f.bbox_lonlat(200.0)
    with pytest.raises(InputError, match="antimeridian"):
        check_bbox(-17.0, 179.9, -16.0, -179.9)
    with pytest.raises(InputError, match="pole"):
        check_bbox(89.5, 0.0, 90.0, 1.0)
    s, w, n, e = SiteFrame.from_site(DEMO_SITE).bbox_lonlat(150.0)
    assert s < 60.16945 < n and w < 24.93365 < e


def test_no_heights_without_a_vertical_datum():
    f = SiteFrame.from_site(DEMO_SITE)
    assert "undeclared" in f.vertical_datum
    with pytest.raises(InputError, match="vertical datum"):
        f.ellipsoidal_heights([[0, 0, 0]])
    g = SiteFrame.from_site({"crs": "EPSG:3067+3900", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 12.0}})
    assert "N2000" in g.vertical_datum


def test_a_base_point_outside_the_crs_area_of_use_is_refused():
    """EPSG:3067 (Finland) with a Mexico City base point was accepted and gave a frame thousands of km from
    the place; now refused with the CRS's area, the site file and a CRS that fits (the UTM zone)."""
    from twinkit.geo import check_base_point_area, outside_area_of_use, utm_epsg
    from twinkit.geo.crs import parse_crs

    bad = {"name": "mexfi", "crs": "EPSG:3067", "base_point": {"lat": 19.4326, "lon": -99.1332, "alt": 2240.0}}
    with pytest.raises(InputError, match=r"conf/site/mexfi\.yaml.*EPSG:3067.*area of use.*EPSG:32614"):
        SiteFrame.from_site(bad)
    # a projected base point in another CRS's metres (Mexico City's UTM 14N x/y read as TM35FIN)
    with pytest.raises(InputError, match="t.yaml: site.crs EPSG:3067 does not fit"):
        check_base_point_area({"crs": "EPSG:3067", "base_point": {"x": 486_000.0, "y": 2_148_000.0}}, "t.yaml")
    # inside (and just across a zone border, within the 2 degree margin) is fine
    assert outside_area_of_use(parse_crs("EPSG:3067"), 60.17, 24.93) is None
    assert outside_area_of_use(parse_crs("EPSG:32633"), 48.19, 11.5) is None  # zone 33 starts at 12 E
    assert outside_area_of_use(parse_crs("EPSG:32633"), 48.19, 5.0) is not None
    SiteFrame.from_site({"crs": "EPSG:32614", "base_point": {"lat": 19.4326, "lon": -99.1332, "alt": 2240.0}})
    assert utm_epsg(19.4326, -99.1332) == (32614, "zone 14N")
    assert utm_epsg(-33.9, 18.4) == (32734, "zone 34S")

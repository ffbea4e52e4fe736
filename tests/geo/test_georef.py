"""The export georeference block (twinkit.geo.georef) and the demo generator's frame (formerly its own GeoRef)."""
import json

import numpy as np
import pytest
from pyproj import Transformer

from twinkit.geo import FRAME, SiteFrame, site_georef

DEMO_SITE = {"name": "demo", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 12.0}}


def test_the_frame_is_exactly_what_the_demo_generator_computed():
    """The demo generator had its own GeoRef (plain pyproj calls on the site CRS); SiteFrame gives the
    same numbers bit for bit, so the demo's LAS/E57/OSM/EXIF files do not change."""
    f = SiteFrame.from_site(DEMO_SITE)
    e, n = Transformer.from_crs("EPSG:4326", "EPSG:3067", always_xy=True).transform(24.93365, 60.16945)
    assert (f.easting, f.northing, f.lat, f.lon, f.alt) == (e, n, 60.16945, 24.93365, 12.0)
    xy = np.random.default_rng(0).uniform(-80, 80, (500, 2))
    lon, lat = Transformer.from_crs("EPSG:3067", "EPSG:4326", always_xy=True).transform(xy[:, 0] + e, xy[:, 1] + n)
    assert np.array_equal(f.local_to_lonlat(xy), np.stack([np.asarray(lon), np.asarray(lat)], 1))
    assert f.georef_json() == {"crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 12.0},
                               "base_point_projected": {"x": e, "y": n, "z": 12.0}}


def test_block_from_site_json_and_from_the_site_config(tmp_path):
    f = SiteFrame.from_site(DEMO_SITE)
    sj = tmp_path / "site.json"
    sj.write_text(json.dumps({**f.georef_json(), "seed": 0}))
    from_json = site_georef(None, sj)
    from_config = site_georef(DEMO_SITE)
    assert from_json == from_config
    assert from_config == {"frame": FRAME, "crs": "EPSG:3067", "lat": 60.16945, "lon": 24.93365, "alt": 12.0,
                           "projected_x": f.easting, "projected_y": f.northing, "projected_z": 12.0}
    # a feet CRS: the projected base point is in the CRS's units, as in the site frame
    feet = {"crs": "EPSG:2992", "base_point": {"lat": 45.5, "lon": -122.6, "alt": 3.0}}
    g = SiteFrame.from_site(feet)
    assert site_georef(feet)["projected_x"] == g.easting and g.unit_m == pytest.approx(0.3048)


def test_block_without_a_usable_georeference():
    assert site_georef(None) == {"frame": FRAME}
    assert site_georef({"name": "x"}) == {"frame": FRAME}
    bad = site_georef({"crs": "EPSG:999999", "base_point": {"lat": 1.0, "lon": 2.0}})
    assert bad == {"frame": FRAME, "crs": "EPSG:999999", "lat": 1.0, "lon": 2.0}

"""Issue 46 item 7 (roads side): every OpenDRIVE file the roads recipe writes can be geolocated by CARLA, and a
map that lands far from the site says where it landed. CARLA's geolocation is measured with the carla wheel
(``carla.Map(name, text).transform_to_geolocation``), not with twinkit's copy of its formula."""
import json
import re

import numpy as np
import pytest

from twinkit import InputError
from twinkit.geo import SiteFrame
from twinkit.testing import plugin_from_module, run_step

import twinkit_roads.plugin as roads

from conftest import DEMO_SITE, FIXTURES

carla = pytest.importorskip("carla")


def _geod(a, b):
    from pyproj import Geod

    return np.abs(np.asarray(Geod(ellps="WGS84").inv(a[:, 0], a[:, 1], b[:, 0], b[:, 1])[2]))


def _lane_centres(text: str) -> np.ndarray:
    """Site-frame lane centres (north-positive y) of a site-frame map, from the carla wheel's waypoints."""
    m = carla.Map("site", text)
    return np.array([(w.transform.location.x, -w.transform.location.y) for w in m.generate_waypoints(5.0)])


def _wheel_lonlat(text: str, xy: np.ndarray) -> np.ndarray:
    m = carla.Map("m", text)
    out = [m.transform_to_geolocation(carla.Location(float(x), float(y), 0.0)) for x, y in xy]
    return np.array([(g.longitude, g.latitude) for g in out])


def _roads(tmp_path, site=DEMO_SITE):
    conv = run_step(plugin_from_module(roads, "step", "osm_to_opendrive"), tmp_path / "conv",
                    {"in_osm_osm": FIXTURES / "tiny_roads.osm"}, roads.ConvertParams(), site=site)
    return conv["roads.xodr"]


def test_the_roads_recipe_writes_a_map_carla_geolocates(tmp_path):
    """roads.xodr's geoReference (the site frame's PROJ string) lands CARLA thousands of km off; roads_carla.xodr,
    the CARLA package's frame, is within the package's 0.5 m at every lane centre, measured with the wheel."""
    xodr = _roads(tmp_path)
    sf = SiteFrame.from_site(DEMO_SITE)
    site_text = xodr.read_text()
    xy = _lane_centres(site_text)
    truth = sf.local_to_lonlat(xy)
    assert _geod(truth, _wheel_lonlat(site_text, xy)).min() > 1e6  # the site-frame map: > 1000 km off
    out = run_step(plugin_from_module(roads, "step", "carla_roads"), tmp_path / "carla", {"in_roads_xodr": xodr},
                   roads.CarlaMapParams(), site=DEMO_SITE)
    doc = json.loads(out["carla_geolocation.json"].read_text())
    m = np.array(doc["frame"]["matrix_site_to_package"])
    err = _geod(truth, _wheel_lonlat(out["roads_carla.xodr"].read_text(), xy @ m[:2, :2].T))
    assert err.max() <= 0.5, err.max()
    assert doc["ok"] and abs(doc["wheel"]["carla_error_max_m"] - err.max()) < 0.1
    assert "points of the map" in doc["wheel"]["measured"] and "from the base point" in doc["wheel"]["measured"]


def test_the_roads_recipe_runs_the_carla_frame_step(tmp_path):
    """recipe=roads through the CLI: roads_carla.xodr beside roads.xodr, and the log says where it was measured."""
    from test_roads_recipe import outputs, run

    site = ("name: roadsite\ncrs: EPSG:3067\nbase_point: {lat: 60.16945, lon: 24.93365, alt: 0.0}\n"
            f"inputs:\n  osm: {FIXTURES / 'tiny_roads.osm'}\n")
    p = run(tmp_path, site)
    assert p.returncode == 0, p.stderr[-2000:]
    out = outputs(tmp_path)
    assert {"roads.xodr", "roads_carla.xodr", "carla_geolocation.json"} <= set(out)
    assert json.loads(out["carla_geolocation.json"].read_text())["wheel"]["carla_error_max_m"] <= 0.5
    assert re.search(r"CARLA's geolocation within 0\.\d+ m \(mean [0-9.]+ m\) at \d+ points of the map, \d+-\d+ m "
                     r"from the base point", p.stderr + p.stdout), (p.stderr + p.stdout)[-2000:]


def test_a_map_far_from_the_site_says_where_it_landed(tmp_path):
    """An OpenDRIVE map whose geoReference put it 50 km east of the base point: the refusal names the place."""
    xodr = _roads(tmp_path).read_text()
    far = re.sub(r'(<geometry [^>]*?x=")([-0-9.eE+]+)"', lambda g: f'{g[1]}{float(g[2]) + 50000.0!r}"', xodr)
    src = tmp_path / "opendrive.xodr"
    src.write_text(far)
    with pytest.raises(InputError) as exc:
        run_step(plugin_from_module(roads, "step", "osm_to_opendrive"), tmp_path / "check",
                 {"in_opendrive_xodr": src}, roads.ConvertParams(), site=DEMO_SITE)
    msg = str(exc.value)
    assert "does not cover the site" in msg
    assert re.search(r"landed at 60\.1\d N, 25\.8\d E, 50\.\d km from the base point", msg), msg

"""Preflight refuses what will fail (issue 46): a georeference that roads or the CARLA package will need is
checked before the first step, with one line naming the keys to set; a suggested CRS fits the place of the
base point (its UTM zone), and none is suggested when no place is known."""
from __future__ import annotations

import time

import pytest

from tests.test_bad_input import SETUPS

SINGAPORE = {"name": "sg", "base_point": {"lat": 1.2903, "lon": 103.8519, "alt": 10.0}}


def test_a_site_without_georeference_is_refused_before_the_first_step(project):
    """A cloud in a local frame, no site.crs nor base point, roads by default: was 11 steps of meshing, views
    and inference, then "site has no georeference" and a Finnish CRS for any cloud."""
    argv = SETUPS["site-no-georeference-roads"](project)
    t0 = time.perf_counter()
    r = project.run(*argv, env=project.env(TWINKIT_PLUGINS="builtins,pointcloud,roads"))
    took = time.perf_counter() - t0
    assert r.rc == 2, r.text[-2000:]
    err = [ln for ln in r.err.splitlines() if ln.startswith("twinkit: error:")]
    assert len(err) == 1 and "site.crs and site.base_point" in err[0] and "road_source=none" in err[0], r.err
    assert "EPSG:" not in err[0]  # no place known: no CRS suggested
    assert err[0].count("site.crs and site.base_point: not set") == 1  # file and its fallback scan: said once
    assert not [d for d in project.ws.iterdir() if d.name[:2].isdigit()], "a step ran"
    assert took < 60, took


def test_the_suggested_crs_fits_the_base_point():
    from twinkit.errors import InputError
    from twinkit.geo import SiteFrame
    from twinkit.geo.frame import crs_example

    assert "EPSG:32648" in crs_example(SINGAPORE) and "UTM zone 48N" in crs_example(SINGAPORE)
    assert "EPSG:32734" in crs_example({"base_point": {"lat": -33.9, "lon": 18.4}})  # Cape Town: zone 34S
    assert crs_example({"name": "x"}) == "" and crs_example({"base_point": {"x": 1.0, "y": 2.0}}) == ""
    with pytest.raises(InputError) as exc:
        SiteFrame.from_site(SINGAPORE)
    assert "EPSG:32648" in str(exc.value) and "EPSG:3067" not in str(exc.value)
    with pytest.raises(InputError) as exc:
        SiteFrame.from_site({"name": "x"})
    assert "EPSG:" not in str(exc.value)


def test_every_road_source_needs_a_georeference():
    from twinkit_roads.preflight import (file_preflight, opendrive_preflight, osm_api_preflight, overpass_preflight,
                                         scan_preflight)

    for name, check in (("file", file_preflight), ("scan", scan_preflight), ("opendrive", opendrive_preflight),
                        ("overpass", overpass_preflight), ("osm_api", osm_api_preflight)):
        found = check(SINGAPORE, None, {})
        assert len(found) == 1 and found[0].startswith("site.crs: not set"), (name, found)
        assert "the road network" in found[0] and "road_source=none" in found[0] and "EPSG:32648" in found[0]
    assert scan_preflight({**SINGAPORE, "crs": "EPSG:32648"}, None, {}) == []


def test_the_carla_package_needs_a_georeference():
    from twinkit_export.plugin import CarlaPackageParams
    from twinkit_export.preflight import carla_package_preflight

    found = carla_package_preflight({"name": "t"}, CarlaPackageParams(), {})
    assert len(found) == 1 and "site.crs and site.base_point: not set" in found[0], found
    assert "the CARLA package (frame=carla" in found[0] and "{frame: site}" in found[0]
    assert carla_package_preflight({"name": "t"}, CarlaPackageParams(frame="site"), {}) == []
    assert carla_package_preflight({**SINGAPORE, "crs": "EPSG:32648"}, CarlaPackageParams(), {}) == []


def test_an_empty_osm_input_and_no_georeference_name_both_fixes(project):
    """A site whose OSM is left empty ('???') and without a georeference: the default road_source=file cannot
    serve it, nor its fallback scan; was only "needs input 'osm'", and the georeference came after the work."""
    argv = SETUPS["site-no-georeference-roads"](project)
    project.site("n", "name: t\ninputs:\n  osm: ???\n")
    r = project.run(*argv, env=project.env(TWINKIT_PLUGINS="builtins,pointcloud,roads"))
    assert r.rc == 2, r.text[-2000:]
    err = [ln for ln in r.err.splitlines() if ln.startswith("twinkit: error:")]
    assert len(err) == 1 and "needs input 'osm'" in err[0] and "nor its fallback road_source=scan" in err[0], r.err
    assert "site.crs and site.base_point: not set" in err[0] and "road_source=none" in err[0]

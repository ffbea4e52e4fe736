"""Plugin contracts, OSM readers, bad input (the site frame itself: tests/geo in the core)."""
import pytest

from twinkit import InputError
from twinkit.testing import check_plugin, plugin_from_module, run_step

import twinkit_roads.plugin as roads
from twinkit_roads.osmio import crop, read_osm, write_osm_xml

from conftest import DEMO_SITE, FIXTURES, need_shared


def test_contracts():
    for kind, name in [("road_source", "file"), ("road_source", "osm_api"), ("road_source", "overpass"),
                       ("step", "osm_to_opendrive"), ("step", "align_roads"), ("step", "apply_alignment")]:
        check_plugin(plugin_from_module(roads, kind, name))


@pytest.mark.parametrize("name,min_ways", [("helsinki_center.osm.pbf", 2600), ("west_oakland.osm.bz2", 31),
                                           ("bavarian_village.osm", 19)])
def test_readers_on_real_files(name, min_ways, tmp_path):
    path = need_shared(name)
    data = read_osm(path)
    c = data.count()
    assert c["highway_ways"] >= min_ways and c["nodes"] > 100
    out = tmp_path / "x.osm"
    write_osm_xml(data, out)
    again = read_osm(out).count()
    assert again["highway_ways"] == c["highway_ways"] and again["nodes"] == c["nodes"]


def test_file_source_crops_around_the_base_point(tmp_path):
    path = need_shared("helsinki_center.osm.pbf")
    site = {"name": "hki", "crs": "EPSG:3067", "base_point": {"lat": 60.1716, "lon": 24.9443, "alt": 0}}
    plugin = plugin_from_module(roads, "road_source", "file")
    out = run_step(plugin, tmp_path / "run", {"in_osm": path}, roads.FileSourceParams(crop_radius_m=150.0), site=site)
    small = read_osm(out["osm.osm"]).count()
    assert 0 < small["highway_ways"] < 2650
    full = read_osm(path)
    everything = crop(full, (60.0, 24.0, 60.5, 25.5)).count()["highway_ways"]
    assert everything >= 0.95 * full.count()["highway_ways"]  # ways cut to < 2 nodes by the extract are dropped


def test_no_roads_is_a_clear_error(tmp_path):
    plugin = plugin_from_module(roads, "road_source", "file")
    with pytest.raises(InputError, match="no roads"):
        run_step(plugin, tmp_path / "run", {"in_osm": FIXTURES / "no_roads.osm"}, site=DEMO_SITE)
    with pytest.raises(InputError, match="needs an OSM file"):
        run_step(plugin, tmp_path / "run2", {}, site=DEMO_SITE)
    bad = tmp_path / "broken.osm"
    bad.write_text("<osm><node id='1' lat='x'")
    with pytest.raises(InputError, match="broken.osm"):
        run_step(plugin, tmp_path / "run3", {"in_osm": bad}, site=DEMO_SITE)


def test_file_source_crops_to_the_site_box_by_default_and_keeps_crossing_ways_whole(tmp_path):
    from twinkit.geo import SiteFrame

    path = need_shared("helsinki_center.osm.pbf")
    site = {"name": "hki", "crs": "EPSG:3067", "base_point": {"lat": 60.1710, "lon": 24.9440, "alt": 0},
            "osm_radius_m": 150.0}
    plugin = plugin_from_module(roads, "road_source", "file")
    out = run_step(plugin, tmp_path / "run", {"in_osm": path}, site=site)
    full, small = read_osm(path), read_osm(out["osm.osm"])
    assert 0 < len(small.ways) < len(full.ways) / 2
    s, w, n, e = SiteFrame.from_site(site).bbox_lonlat(150.0 + roads.FileSourceParams().crop_margin_m)
    crossing = 0
    for wid, (refs, tags) in small.ways.items():
        assert refs == [r for r in full.ways[wid][0] if r in full.nodes]  # whole, not cut at the box
        inside = [s <= small.nodes[r][1] <= n and w <= small.nodes[r][0] <= e for r in refs]
        assert any(inside)
        crossing += not all(inside)
    assert crossing > 10
    # every highway way with a node in the box is there
    box = {i for i, (lo, la, _) in full.nodes.items() if s <= la <= n and w <= lo <= e}
    want = {wid for wid, (refs, t) in full.ways.items() if "highway" in t and box & set(refs)
            and sum(r in full.nodes for r in refs) >= 2}
    assert want <= set(small.ways)
    # crop_radius_m=0: the whole file, as before
    whole = run_step(plugin, tmp_path / "all", {"in_osm": path}, roads.FileSourceParams(crop_radius_m=0.0), site=site)
    assert read_osm(whole["osm.osm"]).count()["highway_ways"] == full.count()["highway_ways"]

"""netconvert + carla.Map on real OSM; alignment on the demo site."""
import json
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from twinkit import InputError
from twinkit.geo import SiteFrame
from twinkit.testing import plugin_from_module, run_step

import twinkit_roads.plugin as roads
from twinkit_roads.align import centreline_rmse, transform_xodr
from twinkit_roads.osmio import read_osm, write_osm_xml

from conftest import DEMO_SITE, FIXTURES, need_shared

HKI = {"name": "hki", "crs": "EPSG:3067", "base_point": {"lat": 60.1716, "lon": 24.9443, "alt": 0.0},
       "osm_radius_m": 300.0}


def _convert(tmp_path, osm, site, **kw):
    plugin = plugin_from_module(roads, "step", "osm_to_opendrive")
    return run_step(plugin, tmp_path, {"in_osm_osm": osm}, roads.ConvertParams(**kw), site=site)


def test_helsinki_converts_and_carla_accepts_it(tmp_path):
    pbf = need_shared("helsinki_center.osm.pbf")
    osm = tmp_path / "osm.osm"
    write_osm_xml(read_osm(pbf), osm)
    out = _convert(tmp_path / "run", osm, HKI)
    rep = json.loads(out["roads_check.json"].read_text())
    assert rep["ok"] and rep["carla"]["topology_segments"] > 500
    assert rep["junctions"] > 50 and rep["traffic_lights"] > 50
    assert rep["carla"]["waypoints_inside"] > 1000
    head = ET.parse(out["roads.xodr"]).getroot().find("header")
    assert "+proj=tmerc" in head.find("geoReference").text and "+lon_0=27" in head.find("geoReference").text


def test_netconvert_nodes_sit_where_the_site_frame_puts_them(tmp_path):
    plain = tmp_path / "plain"
    _convert(tmp_path / "run", FIXTURES / "tiny_roads.osm", DEMO_SITE, extra_args=["--plain-output-prefix", str(plain)])
    frame = SiteFrame.from_site(DEMO_SITE)
    osm = read_osm(FIXTURES / "tiny_roads.osm")
    nodes = {n.get("id"): (float(n.get("x")), float(n.get("y")))
             for n in ET.parse(f"{plain}.nod.xml").getroot().iter("node")}
    assert nodes
    for nid, xy in nodes.items():
        lon, lat, _ = osm.nodes[int(nid)]
        assert np.allclose(frame.lonlat_to_local([[lon, lat]])[0], xy, atol=0.006)  # netconvert writes 2 decimals


def test_netconvert_failure_and_empty_networks_name_the_cause(tmp_path):
    bad = tmp_path / "bad.osm"
    bad.write_text("<osm version='0.6'><way id='1'><nd ref='5'/></way")
    with pytest.raises(InputError, match="netconvert failed on bad.osm"):
        _convert(tmp_path / "r1", bad, DEMO_SITE)
    with pytest.raises(InputError, match="no georeference"):
        _convert(tmp_path / "r2", FIXTURES / "tiny_roads.osm", {"name": "x"})
    far = dict(DEMO_SITE, base_point={"lat": 60.30, "lon": 24.93, "alt": 0})  # 15 km away from the data
    with pytest.raises(InputError, match="do not cover the site"):
        _convert(tmp_path / "r3", FIXTURES / "tiny_roads.osm", far)


def test_transform_xodr_moves_lanes_rigidly(tmp_path):
    out = _convert(tmp_path / "run", FIXTURES / "tiny_roads.osm", DEMO_SITE)
    text = out["roads.xodr"].read_text()
    from twinkit_roads.align import lane_lines

    a = np.concatenate([ln["centre"] for ln in lane_lines(text)])
    yaw, t = math.radians(1.5), np.array([2.0, -3.0])
    moved = transform_xodr(text, yaw, *t, dz=0.25)
    b = np.concatenate([ln["centre"] for ln in lane_lines(moved)])
    R = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
    assert np.abs(a @ R.T + t - b).max() < 0.01
    assert 'a="0.250000"' in moved


@pytest.fixture(scope="module")
def demo_net(demo_site, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("demo_net")
    out = _convert(tmp / "conv", demo_site["roads.osm"], DEMO_SITE)
    truth = [np.asarray(ln["points"]) for ln in json.loads(demo_site["roads_truth.json"].read_text())["lanes"]]
    return out["roads.xodr"], truth


@pytest.mark.parametrize("use_labels", [True, False])
def test_alignment_recovers_the_known_shift_on_the_demo(demo_site, demo_net, tmp_path, use_labels):
    xodr, truth = demo_net
    mesh = demo_site["gt_mesh.ply"]
    inputs = {"in_roads_xodr": xodr, "in_textured_mesh_ply": mesh}
    if use_labels:
        from twinkit.mesh import read_ply

        np.save(tmp_path / "labels.npy", np.asarray(read_ply(mesh).attrs["label"]).astype(np.uint8))
        inputs["in_labels_npy"] = tmp_path / "labels.npy"
    al = run_step(plugin_from_module(roads, "step", "align_roads"), tmp_path / "al", inputs, site=DEMO_SITE)
    a = json.loads(al["alignment.json"].read_text())
    assert a["road_surface_from"] == ("labels" if use_labels else "ground")
    assert a["residual_rmse_m"] < a["residual_rmse_before_m"]
    ap = run_step(plugin_from_module(roads, "step", "apply_alignment"), tmp_path / "ap",
                  {"in_roads_xodr": xodr, "in_alignment_json": al["alignment.json"], "in_textured_mesh_ply": mesh,
                   "in_roads_truth_json": demo_site["roads_truth.json"]}, roads.ApplyParams(qa_px_per_m=8),
                  site=DEMO_SITE)
    b = (-28.0, -28.0, 28.0, 28.0)
    before, _ = centreline_rmse(xodr.read_text(), truth, b)
    after, n = centreline_rmse(ap["aligned.xodr"].read_text(), truth, b)
    assert before > 1.0, "the demo OSM is shifted by metres"
    assert after < 0.3 and n > 100
    assert ap["roads_qa.png"].stat().st_size > 10000


def test_an_edited_alignment_file_is_applied(demo_site, demo_net, tmp_path):
    xodr, truth = demo_net
    site = json.loads(demo_site["site.json"].read_text())["osm_transform"]
    # the generator's own inverse transform, written by hand
    th = -math.radians(site["rotation_deg"])
    R = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    t = -R @ np.array([site["dx_m"], site["dy_m"]])
    f = tmp_path / "alignment.json"
    f.write_text(json.dumps({"yaw_deg": math.degrees(th), "tx_m": t[0], "ty_m": t[1]}))
    ap = run_step(plugin_from_module(roads, "step", "apply_alignment"), tmp_path / "ap",
                  {"in_roads_xodr": xodr, "in_alignment_json": f, "in_textured_mesh_ply": demo_site["gt_mesh.ply"]},
                  roads.ApplyParams(qa_px_per_m=4), site=DEMO_SITE)
    # with the generator's exact inverse, netconvert's lanes lie on the true ones (lane width 3.25 m as in the demo)
    assert centreline_rmse(ap["aligned.xodr"].read_text(), truth, (-28, -28, 28, 28))[0] < 0.03
    f.write_text("{not json")
    with pytest.raises(InputError, match="alignment.json"):
        run_step(plugin_from_module(roads, "step", "apply_alignment"), tmp_path / "ap2",
                 {"in_roads_xodr": xodr, "in_alignment_json": f, "in_textured_mesh_ply": demo_site["gt_mesh.ply"]},
                 site=DEMO_SITE)


def test_footway_only_extract_names_its_way_types(tmp_path):
    """Not netconvert's "No edges loaded.": the way types found, and the setting that widens the kept ones."""
    from twinkit.geo import SiteFrame

    frame = SiteFrame.from_site(DEMO_SITE)
    ll = frame.local_to_lonlat([[-40, 0], [0, 0], [40, 0], [0, 40], [0, -40]])
    nodes = "".join(f'<node id="{i + 1}" version="1" lat="{la:.7f}" lon="{lo:.7f}"/>' for i, (lo, la) in enumerate(ll))
    osm = tmp_path / "paths.osm"
    osm.write_text(f'<?xml version="1.0"?><osm version="0.6">{nodes}'
                   '<way id="1" version="1"><nd ref="1"/><nd ref="2"/><nd ref="3"/><tag k="highway" v="footway"/></way>'
                   '<way id="2" version="1"><nd ref="4"/><nd ref="2"/><tag k="highway" v="footway"/></way>'
                   '<way id="3" version="1"><nd ref="2"/><nd ref="5"/><tag k="highway" v="cycleway"/></way></osm>')
    with pytest.raises(InputError) as err:
        _convert(tmp_path / "run", osm, DEMO_SITE)
    msg = str(err.value)
    assert "paths.osm" in msg and "footway (2), cycleway (1)" in msg and "No edges" not in msg
    assert "steps.osm_to_opendrive.way_types=[motorway," in msg and "footway,cycleway]" in msg


def test_an_opendrive_map_in_another_crs_is_aligned_like_a_converted_one(demo_site, demo_net, tmp_path):
    """The demo's network written in UTM 34 (another CRS, its own geoReference), read back with
    road_source=opendrive into the demo site (TM35FIN), then aligned and applied: the same result as the
    network converted from OSM."""
    xodr, truth = demo_net
    utm34 = dict(DEMO_SITE, name="utm34", crs="EPSG:32634")
    src = plugin_from_module(roads, "road_source", "opendrive")
    other = run_step(src, tmp_path / "to34", {"in_xodr": xodr}, roads.OpenDriveSourceParams(heights="keep"),
                     site=utm34)["opendrive.xodr"]
    assert SiteFrame.from_site(utm34).proj_string() in other.read_text()
    back = run_step(src, tmp_path / "back", {"in_xodr": other}, roads.OpenDriveSourceParams(heights="keep"),
                    site=DEMO_SITE)
    rep = json.loads(back["reprojection.json"].read_text())
    assert rep["residual_max_m"] < 0.01 and abs(rep["similarity"]["rotation_deg"]) > 1  # the grids differ (convergence)
    chk = run_step(plugin_from_module(roads, "step", "osm_to_opendrive"), tmp_path / "chk",
                   {"in_opendrive_xodr": back["opendrive.xodr"]}, site=DEMO_SITE)
    moved = chk["roads.xodr"]
    b = (-28.0, -28.0, 28.0, 28.0)
    assert abs(centreline_rmse(moved.read_text(), truth, b)[0] - centreline_rmse(xodr.read_text(), truth, b)[0]) < 0.01
    mesh = demo_site["gt_mesh.ply"]
    al = run_step(plugin_from_module(roads, "step", "align_roads"), tmp_path / "al",
                  {"in_roads_xodr": moved, "in_textured_mesh_ply": mesh}, site=DEMO_SITE)
    ap = run_step(plugin_from_module(roads, "step", "apply_alignment"), tmp_path / "ap",
                  {"in_roads_xodr": moved, "in_alignment_json": al["alignment.json"], "in_textured_mesh_ply": mesh},
                  roads.ApplyParams(qa_px_per_m=8), site=DEMO_SITE)
    after, n = centreline_rmse(ap["aligned.xodr"].read_text(), truth, b)
    assert after < 0.3 and n > 100


def test_an_opendrive_with_its_own_heights_is_not_lifted_again(demo_site, demo_net, tmp_path):
    """A network whose elevations already follow the ground (road_source=scan writes the scanned heights)
    on a site far above its datum: the height fit compares the two heights, it does not add the ground's
    height again (IGN at 179 m came out at 359 m and the drop test found no ground under any lane)."""
    from twinkit.mesh import read_ply, write_ply

    xodr, _ = demo_net
    lifted = tmp_path / "lifted.xodr"
    lifted.write_text(transform_xodr(xodr.read_text(), 0.0, 0.0, 0.0, dz=179.5))
    m = read_ply(demo_site["gt_mesh.ply"])
    m.vertices = m.vertices + np.array([0.0, 0.0, 179.5])
    mesh = tmp_path / "high.ply"
    write_ply(mesh, m)
    al = run_step(plugin_from_module(roads, "step", "align_roads"), tmp_path / "al",
                  {"in_roads_xodr": lifted, "in_textured_mesh_ply": mesh}, site=DEMO_SITE)
    dz_high = json.loads(al["alignment.json"].read_text())["dz_m"]
    al0 = run_step(plugin_from_module(roads, "step", "align_roads"), tmp_path / "al0",
                   {"in_roads_xodr": xodr, "in_textured_mesh_ply": demo_site["gt_mesh.ply"]}, site=DEMO_SITE)
    dz_low = json.loads(al0["alignment.json"].read_text())["dz_m"]
    assert abs(dz_high - dz_low) < 0.05 and abs(dz_high) < 0.5


def test_lane_edges_are_moved_onto_the_kerbs_feet(demo_site, demo_net):
    """A network a rigid fit left 0.2 deg and 6 cm off (lanes a few cm over the kerb at the ends of the side
    streets) is brought onto the kerbs' feet of the ground-truth mesh; what no kerb constrains (along the
    side streets: the main road's kerbs lie behind its parking strips) stays; a mesh without kerbs moves
    nothing."""
    from twinkit.mesh import read_ply
    from twinkit_roads.align import Transform2D, lane_lines
    from twinkit_roads.kerbs import refine_to_kerbs

    xodr, truth = demo_net
    site = json.loads(demo_site["site.json"].read_text())["osm_transform"]
    th = -math.radians(site["rotation_deg"])
    R = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    t = -R @ np.array([site["dx_m"], site["dy_m"]])
    exact = Transform2D(th, float(t[0]), float(t[1]))
    off = Transform2D(th + math.radians(0.2), float(t[0]) + 0.06, float(t[1]))
    text = xodr.read_text()
    lines = lane_lines(text, 1.0)
    m = read_ply(demo_site["gt_mesh.ply"])

    def rmse(tf):  # lane centres against the truth, inside the site
        c = np.concatenate([tf.apply(ln["centre"]) for ln in lines if not ln["junction"]])
        c = c[(np.abs(c) < 28).all(axis=1)]
        from twinkit_roads.align import polyline_distance

        return float(np.sqrt(np.mean(polyline_distance(c, [t_[:, :2] for t_ in truth]) ** 2)))

    k = refine_to_kerbs(lines, off, m.vertices, m.faces)
    assert k.applied and k.edges >= 20, k
    assert k.before_m > 0.03 and k.after_m < 0.015
    assert rmse(off) > 0.05 and rmse(k.tf) < 0.01, (rmse(off), rmse(k.tf), rmse(exact))
    assert abs(k.shift_m[1]) < 0.005
    # the same network over flat ground: no kerb, nothing moves
    flat = m.vertices.copy()
    flat[:, 2] = 0.0
    k0 = refine_to_kerbs(lines, off, flat, m.faces)
    assert not k0.applied and k0.edges == 0 and "kerb" in k0.why
    assert (k0.tf.yaw_rad, k0.tf.tx, k0.tf.ty) == (off.yaw_rad, off.tx, off.ty)


def test_a_road_drawn_off_its_neighbours_is_moved_onto_its_own_kerbs(demo_site, demo_net, tmp_path):
    """One road of the exactly aligned demo network pushed 8 cm sideways (an OSM way drawn off its
    neighbours: no rigid move fits it) gets a lane offset that brings it back within 2 cm; the others
    get none; apply_alignment writes it as the road's <laneOffset> and carla.Map reads it."""
    from twinkit.mesh import read_ply
    from twinkit_roads.align import Transform2D, lane_lines
    from twinkit_roads.kerbs import road_lane_offsets, set_lane_offsets

    xodr, truth = demo_net
    site = json.loads(demo_site["site.json"].read_text())["osm_transform"]
    th = -math.radians(site["rotation_deg"])
    R = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    t = -R @ np.array([site["dx_m"], site["dy_m"]])
    exact = transform_xodr(xodr.read_text(), th, float(t[0]), float(t[1]))
    m = read_ply(demo_site["gt_mesh.ply"])
    lines = lane_lines(exact, 1.0)
    assert road_lane_offsets(lines, Transform2D(), m.vertices, m.faces) == {}  # in place: under 1 cm, nothing to do
    # a side street (north-south: its lanes end at the kerbs; the main road's kerbs lie behind parking strips),
    # pushed 8 cm to its left
    rid = max({ln["id"][0] for ln in lines if not ln["junction"]},
              key=lambda r: np.mean([np.abs(ln["centre"][:, 1]).mean() for ln in lines if ln["id"][0] == r]))
    pushed = set_lane_offsets(exact, {rid: 0.08})
    off = road_lane_offsets(lane_lines(pushed, 1.0), Transform2D(), m.vertices, m.faces)
    assert list(off) == [rid] and abs(off[rid] + 0.08) < 0.02, off
    # through the steps: alignment.json carries it, apply_alignment writes it
    f = tmp_path / "alignment.json"
    f.write_text(json.dumps({"yaw_deg": 0.0, "tx_m": 0.0, "ty_m": 0.0, "lane_offsets_m": {str(rid): off[rid]}}))
    src = tmp_path / "pushed.xodr"
    src.write_text(pushed)
    ap = run_step(plugin_from_module(roads, "step", "apply_alignment"), tmp_path / "ap",
                  {"in_roads_xodr": src, "in_alignment_json": f, "in_textured_mesh_ply": demo_site["gt_mesh.ply"]},
                  roads.ApplyParams(qa_px_per_m=4), site=DEMO_SITE)
    b = (-28, -28, 28, 28)
    assert centreline_rmse(pushed, truth, b)[0] > centreline_rmse(exact, truth, b)[0] + 0.01
    assert centreline_rmse(ap["aligned.xodr"].read_text(), truth, b)[0] < centreline_rmse(exact, truth, b)[0] + 0.01
    f.write_text(json.dumps({"yaw_deg": 0.0, "tx_m": 0.0, "ty_m": 0.0, "lane_offsets_m": ["not", "a", "map"]}))
    with pytest.raises(InputError, match="lane_offsets_m"):
        run_step(plugin_from_module(roads, "step", "apply_alignment"), tmp_path / "ap2",
                 {"in_roads_xodr": src, "in_alignment_json": f, "in_textured_mesh_ply": demo_site["gt_mesh.ply"]},
                 site=DEMO_SITE)

"""road_source=scan: roads derived from a labelled mesh (a synthetic cross of carriageways with raised
sidewalks), written as OpenDRIVE through netconvert and read back with carla.Map offline (issue 28)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from scan_fixtures import ROAD, SIDEWALK, aerial_lane, cambered_street, cross_mesh, write_aerial_meta
from twinkit_roads import scan
from twinkit_roads.align import centreline_rmse, lane_lines

PROJ = "+proj=tmerc +lat_0=60.16945 +lon_0=24.93365 +k=1 +x_0=0 +y_0=0 +ellps=GRS80 +units=m +no_defs"


def derive_xodr(tmp_path, v, f, labels, **kw):
    p = scan.ScanSourceParams(**kw)
    net = scan.derive_network(v, f, labels, p)
    scan.add_sidewalks(net, v, f, labels, p)
    scan.add_heights_and_signals(net, v, f, labels, p)
    nod, edg = scan.write_plain(net, p, PROJ, tmp_path / "plain")
    out = tmp_path / "scan.xodr"
    scan.netconvert_plain(nod, edg, out, p)
    return net, scan.mark_source(out.read_text(encoding="utf-8"))


def on_road(pts, main_half, side_half, arms="ns"):
    x, y = pts[:, 0], pts[:, 1]
    side = np.abs(x) <= side_half
    if arms == "n":
        side &= y >= 0
    return (np.abs(y) <= main_half) | side


@pytest.fixture(scope="module")
def four_way(tmp_path_factory):
    v, f, lab, truth = cross_mesh(step_m=1.0)
    net, text = derive_xodr(tmp_path_factory.mktemp("cross"), v, f, lab)
    return v, f, lab, truth, net, text


def test_four_way_cross_gives_lanes_on_the_road_that_carla_reads(four_way):
    import carla

    v, f, lab, truth, net, text = four_way
    m = carla.Map("scan", text)  # parses offline
    assert len(m.get_topology()) > 0
    assert 'code="twinkit_road_source" value="scan"' in text
    # one junction where the four arms meet, four roads
    assert sum(nd["kind"] == "junction" for nd in net.nodes.values()) == 1
    assert len(net.arms) == 4
    j = next(nd for nd in net.nodes.values() if nd["kind"] == "junction")
    assert np.hypot(*j["xy"]) < 0.3
    # main road: 17.4 m curb to curb = 2 lanes of 3.25 m each way + a 2.2 m parking strip; side: 1 + 1
    widths = sorted(round(a.width_m, 1) for a in net.arms)
    assert widths[0] == pytest.approx(6.5, abs=0.25) and widths[-1] == pytest.approx(17.4, abs=0.25)
    main = [a for a in net.arms if a.width_m > 10]
    assert all(a.lanes["lanes"] == 2 and a.lanes["two_way"] and a.lanes["strip_m"] == pytest.approx(2.2, abs=0.2)
               for a in main)
    # lane centres match the true ones, and every driving lane lies on the carriageway
    rmse, n = centreline_rmse(text, truth, (-38, -38, 38, 38))
    assert n > 200 and rmse < 0.2
    cen = np.concatenate([ln["centre"] for ln in lane_lines(text, 1.0, junctions=True)])
    assert on_road(cen, 8.7, 3.25).all()
    share = scan.lanes_on_road(text, v, f, lab)
    assert share["on_road_share"] > 0.95
    # sidewalk lanes (OpenDRIVE type sidewalk) about 3.5 m wide on both sides of every arm
    assert text.count('type="sidewalk"') >= 8
    assert all(2.8 < a.sidewalk_left_m < 4.2 and 2.8 < a.sidewalk_right_m < 4.2 for a in net.arms)


def test_three_way_junction(tmp_path):
    v, f, lab, truth = cross_mesh(step_m=1.0, side_arms="n")
    net, text = derive_xodr(tmp_path, v, f, lab)
    assert sum(nd["kind"] == "junction" for nd in net.nodes.values()) == 1
    assert len(net.arms) == 3
    rmse, n = centreline_rmse(text, truth, (-38, -38, 38, 38))
    assert n > 150 and rmse < 0.25
    cen = np.concatenate([ln["centre"] for ln in lane_lines(text, 1.0)])
    assert on_road(cen, 8.7, 3.25, arms="n").all()


def test_curbs_keep_the_edge_where_the_labels_spill_onto_the_sidewalk(tmp_path):
    """Road labels spilling 1.2 m onto the north sidewalk of the main road: the curb (height step) keeps
    the carriageway's edge; the labels alone move the road's axis by half the spill."""
    v, f, lab, truth = cross_mesh(step_m=1.0)
    spill = (lab == SIDEWALK) & (v[:, 1] > 8.7) & (v[:, 1] < 9.95) & (np.abs(v[:, 0]) > 10)
    lab = lab.copy()
    lab[spill] = ROAD
    net, text = derive_xodr(tmp_path, v, f, lab)
    main = [a for a in net.arms if a.width_m > 10]
    assert all(a.width_m == pytest.approx(17.4, abs=0.25) for a in main)
    assert centreline_rmse(text, truth, (-38, -38, 38, 38))[0] < 0.2
    p = scan.ScanSourceParams(use_curbs=False)
    labels_only = scan.derive_network(v, f, lab, p)
    assert max(a.width_m for a in labels_only.arms) > 18.0  # the labels alone take the spill as road


def test_a_sweep_whose_ground_is_single_scan_lines_takes_the_carriageway_from_the_labels(tmp_path):
    """A single spinning sweep samples its ground in rings: most 16-point neighbourhoods are one line, and no
    kerb step can be measured across them (points_meta.json density.ground_two_way_share 0.3, as the real
    sweeps' 0.26-0.33). The road labels then draw the carriageway alone (use_curbs off); a street scan
    (0.99) keeps the curbs. Seen here by the labels spilling 1.2 m onto a sidewalk: the curbs hold the edge,
    the labels alone take the spill."""
    import json

    from twinkit import artefacts as A
    from twinkit.mesh import Mesh, write_ply
    from twinkit.testing import run_plugin

    v, f, lab, _ = cross_mesh(step_m=1.0)
    spill = (lab == SIDEWALK) & (v[:, 1] > 8.7) & (v[:, 1] < 9.95) & (np.abs(v[:, 0]) > 10)
    lab = lab.copy()
    lab[spill] = ROAD
    write_ply(tmp_path / "textured_mesh.ply", Mesh(v, f))
    np.save(tmp_path / "labels.npy", lab)
    site = {"name": "cross", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 0.0}}
    widths = {}
    for name, share in (("sweep", 0.3), ("street", 0.99)):
        meta = tmp_path / f"{name}_meta.json"
        A.write_points_meta(meta, {"source": {"reader": "test"}, "counts": {}, "fields": {}, "frame": {},
                                   "bounds_m": [], "density": {"points": 0, "spacing_m": 0.03, "capture": "mobile",
                                                               "ground_two_way_share": share}})
        out = run_plugin("road_source", "scan", tmp_path / name,
                         {"in_textured_mesh_ply": tmp_path / "textured_mesh.ply", "in_labels_npy": tmp_path / "labels.npy",
                          "in_points_meta_json": meta}, site=site)
        doc = json.loads(out["scan_roads.json"].read_text())
        assert doc["ground_two_way_share"] == share and doc["curbs"] is True
        widths[name] = (doc["params"]["use_curbs"], max(r["carriageway_m"] for r in doc["roads"]))
    assert widths["street"][0] is True and widths["street"][1] == pytest.approx(17.4, abs=0.25)
    assert widths["sweep"][0] is False and widths["sweep"][1] > 18.0


def test_curbs_alone_without_labels(tmp_path):
    v, f, lab, truth = cross_mesh(step_m=1.0)
    net, text = derive_xodr(tmp_path, v, f, None)
    assert len(net.arms) == 4
    assert centreline_rmse(text, truth, (-38, -38, 38, 38))[0] < 0.2
    assert net.stats["sidewalks_from"] == "raised level beside the curb"
    assert text.count('type="sidewalk"') >= 8


@pytest.mark.parametrize("width, lanes, lane_m, strip_m, two_way", [
    (17.4, 2, 3.25, 2.2, True),   # the demo's main road: 2 + 2 lanes, parking strips
    (6.5, 1, 3.25, 0.0, True),    # a two-lane street
    (6.7, 1, 3.25, 0.1, True),    # a little wider: the lanes stay clear of the curb
    (7.4, 1, 3.55, 0.15, True),   # wider lanes rather than a strip narrower than min_strip_m, curb_clearance_m free
    (4.0, 1, 3.7, 0.15, False),   # a narrow one-lane street
    # narrower than two nominal lanes: narrower lanes inside the edges (they were 3.25 m, 0.65 m over them)
    (5.2, 1, 2.5, 0.1, True),     # a village street: two lanes of min_lane_width_m
    (6.0, 1, 2.85, 0.15, True),   # curb_clearance_m kept free
])
def test_lane_layout(width, lanes, lane_m, strip_m, two_way):
    lay = scan.lane_layout(width, scan.ScanSourceParams())
    assert lay["lanes"] == lanes and lay["two_way"] == two_way
    assert lay["lane_m"] == pytest.approx(lane_m, abs=0.01) and lay["strip_m"] == pytest.approx(strip_m, abs=0.01)


def test_no_carriageway_is_a_clear_error():
    from twinkit import InputError

    v, f, lab, _ = cross_mesh(half_m=20.0, step_m=1.0)
    lab = np.full_like(lab, 9)  # all terrain, and all raised
    v = v.copy()
    v[:, 2] = np.where(np.hypot(v[:, 0], v[:, 1]) < 3, 0.0, 0.12)
    with pytest.raises(InputError, match="no carriageway|no road axis|no road at least"):
        scan.derive_network(v, f, lab, scan.ScanSourceParams())


def test_scan_source_through_the_engine_then_the_carla_check(tmp_path):
    """The registered road source (the engine's code path) on a mesh file and its labels, then
    osm_to_opendrive's carla.Map check of its opendrive.xodr: source scan, lanes inside the site."""
    import json

    from twinkit import artefacts as A
    from twinkit.mesh import Mesh, write_ply
    from twinkit.testing import run_plugin

    v, f, lab, truth = cross_mesh(step_m=1.0)
    # colours as a scanner's; labels as the segmentation writes them
    rgb = np.where(lab[:, None] == ROAD, 80, 170).astype(np.uint8).repeat(3, 1)
    mesh_p = tmp_path / "textured_mesh.ply"
    write_ply(mesh_p, Mesh(v, f, attrs={"red": rgb[:, 0], "green": rgb[:, 1], "blue": rgb[:, 2]}))
    np.save(tmp_path / "labels.npy", lab)
    A.write_roads_truth(tmp_path / "roads_truth.json",
                        {"roads": [], "frame": "site", "lanes": [{"road": "cross", "direction": 1,
                                                                  "points": [[*p, 0.0] for p in t.tolist()]}
                                                                 for t in truth]})
    site = {"name": "cross", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 0.0}}
    out = run_plugin("road_source", "scan", tmp_path / "scan",
                     {"in_textured_mesh_ply": mesh_p, "in_labels_npy": tmp_path / "labels.npy",
                      "in_roads_truth_json": tmp_path / "roads_truth.json"}, site=site)
    doc = json.loads(out["scan_roads.json"].read_text())
    assert doc["labels"] == "predicted" and len(doc["roads"]) == 4
    assert doc["centreline_rmse_m"] < 0.2 and doc["lanes_on_road"]["on_road_share"] > 0.95
    assert out["scan_roads.png"].stat().st_size > 5000
    chk = run_plugin("step", "osm_to_opendrive", tmp_path / "conv", {"in_opendrive_xodr": out["opendrive.xodr"]},
                     site=site)
    rep = json.loads(chk["roads_check.json"].read_text())
    assert rep["ok"] and rep["source"] == "scan" and rep["junctions"] == 1
    assert rep["carla"]["waypoints_inside"] > 100


def test_without_osm_the_default_recipe_takes_the_roads_from_the_scan(tmp_path):
    """pointcloud_site on a site whose OSM input is left empty (mex: osm: ???): the default road source
    (file) gives way to scan, said in the log; road_source=file typed on the command line keeps the error;
    road_source=none still leaves the roads out."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[3]
    cloud = tmp_path / "scan.ply"
    cloud.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
                      b"property float z\nend_header\n")
    env = {k: v for k, v in os.environ.items() if not k.startswith("TWINKIT_")}

    def status(*extra):
        return subprocess.run([sys.executable, "-m", "twinkit", "status", "recipe=pointcloud_site", "site=mex",
                               f"site.inputs.cloud={cloud}", f"engine.outputs_dir={tmp_path / 'out'}", *extra],
                              capture_output=True, text=True, cwd=root, env=env, timeout=300)

    p = status()
    assert p.returncode == 0, p.stderr[-2000:]
    assert "road_source=file cannot serve this site" in p.stderr and "using road_source=scan instead" in p.stderr
    assert "osm_to_opendrive" in p.stdout and "apply_alignment" in p.stdout and "carla" in p.stdout
    p = status("road_source=file")
    assert p.returncode != 0 and "site.inputs.osm" in p.stderr and "road_source=scan" not in p.stderr
    p = status("road_source=none")
    assert p.returncode == 0 and "road_source=none was chosen" in p.stdout and "scan" not in p.stderr


def test_an_aerial_scan_without_curbs_finds_the_grey_lane_on_its_embankment(tmp_path):
    """A scan too sparse to show curbs (points_meta.json: 0.3 m spacing, as aerial lidar): the carriageway is
    the road-labelled grey ground, not the local lowest level. The lane lies on a 0.4 m embankment on a
    5 % slope and the labels spill 10 m onto the field: the curb test put the road in the field (y = 9 m,
    10.6 m wide); without it the axis is on the lane and carla.Map reads lanes on it only."""
    import json

    import carla
    from twinkit.mesh import Mesh, write_ply
    from twinkit.testing import run_plugin

    v, f, lab, rgb, axis, _ = aerial_lane()
    mesh_p = tmp_path / "textured_mesh.ply"
    write_ply(mesh_p, Mesh(v, f, attrs={"red": rgb[:, 0], "green": rgb[:, 1], "blue": rgb[:, 2]}))
    np.save(tmp_path / "labels.npy", lab)
    meta = tmp_path / "points_meta.json"
    write_aerial_meta(meta)
    site = {"name": "lane", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 0.0}}
    out = run_plugin("road_source", "scan", tmp_path / "scan",
                     {"in_textured_mesh_ply": mesh_p, "in_labels_npy": tmp_path / "labels.npy",
                      "in_points_meta_json": meta}, site=site)
    doc = json.loads(out["scan_roads.json"].read_text())
    assert doc["curbs"] is False and doc["point_spacing_m"] == 0.3
    assert len(doc["roads"]) == 1 and abs(doc["roads"][0]["carriageway_m"] - 6.0) < 1.0
    assert 'type="sidewalk"' not in out["opendrive.xodr"].read_text()  # no curbs: no sidewalk told from the verge
    m = carla.Map("lane", out["opendrive.xodr"].read_text())
    w = [x for x in m.generate_waypoints(1.0) if x.lane_type == carla.LaneType.Driving]
    y = np.array([-x.transform.location.y for x in w])  # CARLA's y is flipped
    assert len(w) > 50 and np.abs(y).max() < 3.0
    # the lanes follow the slope and the embankment (2 cm typical, 6 cm at the ends of the scan)
    z = np.array([x.transform.location.z for x in w])
    xs = np.array([x.transform.location.x for x in w])
    dz = np.abs(z - (0.05 * xs + 0.4))
    assert np.median(dz) < 0.02 and dz.max() < 0.06
    # spacing unknown (no points_meta.json): the curb test, as for a street scan
    out2 = run_plugin("road_source", "scan", tmp_path / "scan2",
                      {"in_textured_mesh_ply": mesh_p, "in_labels_npy": tmp_path / "labels.npy"}, site=site)
    assert json.loads(out2["scan_roads.json"].read_text())["curbs"] is True


def _aerial_scan(tmp_path, name, v, f, lab, rgb, cloud, **params):
    """road_source=scan on an aerial-like mesh with its cloud (points.ply) and a 0.3 m spacing."""
    import json

    from twinkit.mesh import Mesh, write_ply
    from twinkit.testing import run_plugin

    d = tmp_path / name
    d.mkdir()
    write_ply(d / "textured_mesh.ply", Mesh(v, f, attrs={"red": rgb[:, 0], "green": rgb[:, 1], "blue": rgb[:, 2]}))
    write_ply(d / "points.ply", Mesh(cloud, None))
    np.save(d / "labels.npy", lab)
    write_aerial_meta(d / "points_meta.json")
    site = {"name": "lane", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 0.0}}
    out = run_plugin("road_source", "scan", d / "scan",
                     {"in_textured_mesh_ply": d / "textured_mesh.ply", "in_labels_npy": d / "labels.npy",
                      "in_points_meta_json": d / "points_meta.json", "in_points_ply": d / "points.ply"},
                     site=site, **params)
    return json.loads(out["scan_roads.json"].read_text()), out["opendrive.xodr"].read_text()


def _driving_y(text):
    import carla

    w = [x for x in carla.Map("lane", text).generate_waypoints(1.0) if x.lane_type == carla.LaneType.Driving]
    return np.array([-x.transform.location.y for x in w])  # CARLA's y is flipped


def test_an_aerial_street_among_grey_specks_half_called_sidewalk_beside_a_river(tmp_path):
    """What real aerial scans add to the grey lane (IGN, Autzen): half the street labelled sidewalk (a model
    looking down, no kerbs), grey road-labelled specks over a third of the fields, and a 12 m river, grey
    and labelled sidewalk, whose lidar returns are a tenth of the land's. With the defaults one road, on
    the lane, whose lanes carla.Map reads on the scanned surface; without the density test the river is a
    road too; without the majority test the specks leave the street's neighbourhood a patchwork."""
    v, f, lab, rgb, axis, water = aerial_lane(specks=0.35, river_m=12.0, sidewalk_share=0.5)
    keep = ~water | (np.arange(len(v)) % 10 == 0)  # the river returns a tenth of the points
    cloud = v[keep] + np.random.default_rng(1).normal(0, 0.05, (int(keep.sum()), 3)) * [1, 1, 0]
    doc, text = _aerial_scan(tmp_path, "default", v, f, lab, rgb, cloud)
    assert "road or sidewalk labels" in doc["carriageway_from"] and "measured" in doc["carriageway_from"]
    assert len(doc["roads"]) == 1 and abs(doc["roads"][0]["carriageway_m"] - 6.0) < 1.0
    y = _driving_y(text)
    assert len(y) > 50 and np.abs(y).max() < 3.0
    assert doc["lane_check"] and doc["lane_check"][-1]["on_share"] > 0.95
    assert doc["lane_check_settled"] is True  # the last check found nothing to change: the map is the one checked
    # the river is flat, grey and "sidewalk": only its few returns tell it from a road
    doc0, text0 = _aerial_scan(tmp_path, "no_density", v, f, lab, rgb, cloud, min_point_density=0.0)
    assert (_driving_y(text0) < -20.0).any()
    # single specks: the majority test keeps them out; without it they join the street's edges (a quarter
    # more carriageway, 560 against 450 m^2 for 480 true), and the lanes widen onto the fields (as derived,
    # before the lane check: the fields lie below the embankment, so the check then moves them back)
    doc1, text1 = _aerial_scan(tmp_path, "no_majority", v, f, lab, rgb, cloud, majority_m=0.0, lane_check_rounds=0)
    assert doc1["carriageway_m2"] > 1.15 * doc["carriageway_m2"] and np.abs(_driving_y(text1)).max() > 3.0
    assert doc1["lane_check_settled"] is None  # no lane check at all
    # one check that moves the lanes back, and no round left to check the map netconvert then builds: said so
    doc2, _ = _aerial_scan(tmp_path, "one_round", v, f, lab, rgb, cloud, majority_m=0.0, lane_check_rounds=1)
    assert doc2["lane_check_settled"] is False and len(doc2["lane_check"]) == 1


def test_a_junction_whose_lanes_leave_the_ground_is_taken_apart(four_way, tmp_path):
    """check_lanes reads the lanes netconvert built (junctions included) against the scan. On the cross they
    lie on it; on the same cross with a 1 m mound over the crossing, the junction's lanes are buried and it
    is taken apart: each road is cut back outside it and ends there, and the map netconvert builds then has
    no lane over the mound."""
    import copy

    import carla

    v, f, lab, truth, net, text = four_way
    p = scan.ScanSourceParams()
    good = scan.check_lanes(net, text, v, f, p)
    assert good["on_share"] > 0.99 and not good["bad_junctions"] and not good["bad_points"]
    mound = v.copy()
    r = np.hypot(mound[:, 0], mound[:, 1])
    mound[:, 2] += np.clip((14.0 - r) / 4.0, 0.0, 1.0)  # 1 m up within 10 m of the crossing, ramped to 14 m
    bad = scan.check_lanes(net, text, mound, f, p)
    (jid,) = [k for k, nd in net.nodes.items() if nd["kind"] == "junction"]
    assert list(bad["bad_junctions"]) == [jid] and bad["bad_junctions"][jid] < 0.5
    net2 = copy.deepcopy(net)
    assert scan.detach_junctions(net2, [jid], p) == 0
    assert len(net2.arms) == 4 and all(nd["kind"] == "end" for nd in net2.nodes.values())
    reach = 0.5 * max(a.width_m for a in net.arms) + 2.0
    assert min(np.hypot(*a.xy.T).min() for a in net2.arms) > reach - 1e-6
    nod, edg = scan.write_plain(net2, p, PROJ, tmp_path / "plain")
    scan.netconvert_plain(nod, edg, tmp_path / "apart.xodr", p)
    w = carla.Map("apart", (tmp_path / "apart.xodr").read_text()).generate_waypoints(1.0)
    assert w and min(np.hypot(x.transform.location.x, x.transform.location.y) for x in w) > 10.0


def test_each_direction_sits_on_its_half_of_a_cambered_street(tmp_path):
    """A street across a hillside (2 % from south to north), cambered 2 % from its crown, on a 3 % grade:
    the flat-street level test keeps only the gutters there, the step test takes the whole carriageway;
    each direction's edge takes its own half's height (one height for the carriageway put the north lanes
    14 cm under it). What is left is a lane's own cross slope (4 % on the south half: +-6.5 cm between its
    two lanes), out of reach: netconvert writes no cross slope, and carla.Map ignores superelevation."""
    import carla

    v, f, lab, surface = cambered_street()
    net, text = derive_xodr(tmp_path, v, f, lab)
    assert len(net.arms) == 1 and net.arms[0].lanes["two_way"]
    arm = net.arms[0]
    assert float(np.median(arm.z_left - arm.z_right)) > 0.1  # the two halves, a hillside apart
    m = carla.Map("camber", text)
    w = [x for x in m.generate_waypoints(1.0) if x.lane_type == carla.LaneType.Driving]
    p = np.array([[x.transform.location.x, -x.transform.location.y, x.transform.location.z] for x in w])
    inner = np.abs(p[:, 0]) < 34  # away from the scan's ends
    dz = np.abs(p[inner, 2] - surface(p[inner, 0], p[inner, 1]))
    assert inner.sum() > 200 and np.percentile(dz, 95) < 0.085
    north = p[inner, 1] > 0  # the north half is nearly level across (crown and hillside cancel): 2 cm
    assert np.percentile(dz[north], 95) < 0.025


def test_lanes_stay_on_scanned_ground_cut_at_a_free_end_and_split_under_a_roof():
    """trim_unsupported on a 60 m road over a 50 m ground (x -25..25; the road's east 10 m run past the
    scan's end) with a roof 4 m up over x -3..3 and no ground under it: the end is cut back to the scan,
    and the road is split in two around the roof, each piece with its own end nodes."""
    xs = np.arange(-25.0, 25.0 + 1e-9, 0.5)
    ys = np.arange(-6.0, 6.0 + 1e-9, 0.5)
    X, Y = np.meshgrid(xs, ys)
    v = np.stack([X.ravel(), Y.ravel(), np.where(np.abs(X.ravel()) < 3.2, 4.0, 0.0)], 1)
    nx = len(xs)
    i, j = np.meshgrid(np.arange(len(ys) - 1), np.arange(nx - 1), indexing="ij")
    a = (i * nx + j).ravel()
    f = np.concatenate([np.stack([a, a + 1, a + nx + 1], 1), np.stack([a, a + nx + 1, a + nx], 1)])
    xy = np.stack([np.arange(-24.0, 36.0 + 1e-9, 2.0), np.zeros(31)], 1)
    arm = scan.Arm(0, 1, xy, 6.5, z=np.zeros(31), z_left=np.zeros(31), z_right=np.zeros(31))
    net = scan.Network({0: {"xy": xy[0], "z": 0.0, "kind": "end"}, 1: {"xy": xy[-1], "z": 0.0, "kind": "end"}},
                       [arm], None, None, None, {})
    out = scan.trim_unsupported(net, v, f, scan.ScanSourceParams())
    assert len(net.arms) == 2 and out["dropped_roads"] == 0
    west, east = sorted(net.arms, key=lambda r: r.xy[0, 0])
    assert west.xy[0, 0] == -24.0 and west.xy[-1, 0] < -3.0  # the west end is on the scan: kept
    assert east.xy[0, 0] > 3.0 and east.xy[-1, 0] <= 25.0  # the east end ran off the scan: cut back to it
    assert 10.0 < out["cut_m"] < 22.0
    assert {west.a, west.b, east.a, east.b} == set(net.nodes) and len(net.nodes) == 4
    assert all(len(r.z) == len(r.xy) == len(r.z_left) for r in net.arms)


def test_the_scans_own_network_is_kept_when_the_alignment_finds_no_road_surface(tmp_path):
    """align_roads measures a network drawn from the scan (it never moves it). Where its cruder road surface
    (the ground level, or road labels) does not find the network's roads, the scan's network stays in place
    with the residual unmeasured, instead of stopping the run (Autzen: paths on paved-looking grey ground in
    a park); a map from elsewhere that finds no road surface still stops with the error."""
    import json

    from twinkit import InputError
    from twinkit.mesh import Mesh, write_ply
    from twinkit.testing import plugin_from_module, run_step

    import twinkit_roads.plugin as roads

    v, f, lab, rgb, axis, _ = aerial_lane()
    cloud = v.copy()
    doc, text = _aerial_scan(tmp_path, "lane", v, f, lab, rgb, cloud)
    assert 'value="scan"' in text
    far = v + np.array([300.0, 0.0, 0.0])  # the mesh 300 m away: no road cross-section finds it
    write_ply(tmp_path / "far.ply", Mesh(far, f))
    (tmp_path / "scan.xodr").write_text(text)
    site = {"name": "lane", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 0.0}}
    step = plugin_from_module(roads, "step", "align_roads")
    al = run_step(step, tmp_path / "al", {"in_roads_xodr": tmp_path / "scan.xodr",
                                          "in_textured_mesh_ply": tmp_path / "far.ply"}, site=site)
    a = json.loads(al["alignment.json"].read_text())
    assert a["kept_identity"] and a["yaw_deg"] == 0 and a["tx_m"] == 0 and a["ty_m"] == 0
    assert a["residual_rmse_m"] is None and a["dz_m"] == 0.0
    (tmp_path / "other.xodr").write_text(text.replace('<userData code="twinkit_road_source" value="scan"/>', ""))
    with pytest.raises(InputError, match="cross-sections"):
        run_step(step, tmp_path / "al2", {"in_roads_xodr": tmp_path / "other.xodr",
                                          "in_textured_mesh_ply": tmp_path / "far.ply"}, site=site)


def test_a_scan_without_roads_gives_a_map_without_roads_and_the_road_steps_pass_it_on(tmp_path):
    """No carriageway in the scan (a park, a yard: nothing paved-looking) is a twin without a road network:
    road_source=scan writes an OpenDRIVE with no roads (carla.Map reads it: no waypoints), says why, and the
    run goes on; osm_to_opendrive, align_roads and road_evidence pass it on. Roads derived and then all
    dropped by the checks (the scan shows carriageway, none of it held up) make the step degraded."""
    import json

    import carla
    from twinkit.testing import plugin_from_module, run_step

    import twinkit_roads.plugin as roads
    from scan_fixtures import TERRAIN

    v, f, lab, rgb, axis, _ = aerial_lane()
    park = np.full_like(lab, TERRAIN)
    doc, text = _aerial_scan(tmp_path, "park", v, f, park, rgb, v.copy())
    assert scan.is_empty_map(text) and doc["roads"] == [] and "no carriageway" in doc["no_roads"]
    assert not doc["derived_then_dropped"]
    assert len(carla.Map("park", text).generate_waypoints(1.0)) == 0
    step_json = json.loads((tmp_path / "park" / "scan" / "result" / "step.json").read_text())
    assert step_json["metrics"]["no_roads"] is True and "degraded" not in step_json["metrics"]
    # the road steps after it
    site = {"name": "lane", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 0.0}}
    d = tmp_path / "park"
    (d / "opendrive.xodr").write_text(text)
    conv = run_step(plugin_from_module(roads, "step", "osm_to_opendrive"), d / "conv",
                    {"in_opendrive_xodr": d / "opendrive.xodr"}, site=site)
    assert json.loads(conv["roads_check.json"].read_text())["no_roads"] is True
    al = run_step(plugin_from_module(roads, "step", "align_roads"), d / "al",
                  {"in_roads_xodr": conv["roads.xodr"], "in_textured_mesh_ply": d / "textured_mesh.ply"}, site=site)
    assert json.loads(al["alignment.json"].read_text())["no_roads"] is True
    ap = run_step(plugin_from_module(roads, "step", "apply_alignment"), d / "ap",
                  {"in_roads_xodr": conv["roads.xodr"], "in_alignment_json": al["alignment.json"],
                   "in_textured_mesh_ply": d / "textured_mesh.ply"}, site=site)
    assert scan.is_empty_map(ap["aligned.xodr"].read_text())
    ev = run_step(plugin_from_module(roads, "step", "road_evidence"), d / "ev",
                  {"in_aligned_xodr": ap["aligned.xodr"], "in_textured_mesh_ply": d / "textured_mesh.ply",
                   "in_labels_npy": d / "labels.npy"}, site=site)
    assert np.array_equal(np.load(ev["labels.npy"]), park)
    # roads derived, then none keeps its lanes on the scan (a 1 mm tolerance: every sample is off): degraded
    doc2, text2 = _aerial_scan(tmp_path, "dropped", v, f, lab, rgb, v.copy(), lane_tol_m=0.001)
    assert scan.is_empty_map(text2) and doc2["derived_then_dropped"]
    step2 = json.loads((tmp_path / "dropped" / "scan" / "result" / "step.json").read_text())
    assert any("none kept" in e["reason"] for e in step2["metrics"]["degraded"])


def test_taking_a_junction_apart_drops_the_roads_that_lie_inside_it():
    """detach_junctions on a T: the two long roads are cut back to outside the junction's reach (half the widest
    road + 2 m: 4 m) and end there, keeping what lies beyond (6 m on); the 6 m stub keeps one shape point beyond
    the reach, too short to stay a road, and goes with its end node."""
    xs = np.linspace(0.0, 20.0, 11)[:, None]
    east = np.c_[xs, np.zeros_like(xs)]
    west = -east
    stub = np.c_[np.zeros(4), np.linspace(6.0, 0.0, 4)]
    nodes = {0: {"xy": np.zeros(2), "z": 0.0, "kind": "junction"}, 1: {"xy": east[-1], "z": 0.0, "kind": "end"},
             2: {"xy": stub[0], "z": 0.0, "kind": "end"}, 3: {"xy": west[-1], "z": 0.0, "kind": "end"}}
    arms = [scan.Arm(0, 1, east, 4.0, z=np.zeros(len(east))), scan.Arm(2, 0, stub, 4.0, z=np.zeros(len(stub))),
            scan.Arm(0, 3, west, 4.0, z=np.zeros(len(west)))]
    net = scan.Network(nodes, arms, np.zeros((1, 1), bool), None, None, {})
    assert scan.detach_junctions(net, [0], scan.ScanSourceParams()) == 1
    assert len(net.arms) == 2 and 0 not in net.nodes and 2 not in net.nodes
    for arm in net.arms:
        assert np.isclose(np.hypot(*arm.xy.T).min(), 6.0) and len(arm.xy) == 8 and len(arm.z) == len(arm.xy)
        assert all(net.nodes[n]["kind"] == "end" for n in (arm.a, arm.b))


def test_a_road_wider_than_the_ground_that_holds_it_is_narrowed(tmp_path):
    """check_lanes against a scan where the south 0.5 m of the lane dropped 0.5 m (a bank the grey mask took
    as road; Autzen's path beside its dry grass): that side's outermost edge_band_m is off the scan while
    the rest is on, so narrow_arms takes 0.5 m off it and moves the axis 0.25 m north; netconvert's lanes
    then end 0.5 m further north on that side and no further on the other. On the lane as scanned nothing
    is narrowed."""
    import carla

    v, f, lab, rgb, axis, _ = aerial_lane()
    p = scan.ScanSourceParams()
    net = scan.derive_network(v, f, lab, p, curbs=False, rgb=rgb)
    scan.add_heights_and_signals(net, v, f, lab, p)

    def edges(tag):
        nod, edg = scan.write_plain(net, p, PROJ, tmp_path / tag)
        scan.netconvert_plain(nod, edg, tmp_path / f"{tag}.xodr", p)
        text = (tmp_path / f"{tag}.xodr").read_text()
        w = [x for x in carla.Map(tag, text).generate_waypoints(1.0)
             if x.lane_type == carla.LaneType.Driving and abs(x.transform.location.x) < 30]
        ys = [(-x.transform.location.y - x.lane_width / 2, -x.transform.location.y + x.lane_width / 2) for x in w]
        return text, min(a for a, _ in ys), max(b for _, b in ys)

    text, south, north = edges("before")
    assert not scan.check_lanes(net, text, v, f, p)["narrow"]
    bank = v.copy()
    bank[(bank[:, 1] >= -3.01) & (bank[:, 1] <= -2.49), 2] -= 0.5
    chk = scan.check_lanes(net, text, bank, f, p)
    (k, sides), = chk["narrow"].items()
    width = net.arms[k].width_m
    assert scan.narrow_arms(net, chk["narrow"], p) == 1 and net.arms[k].width_m == pytest.approx(width - 0.5)
    _, south2, north2 = edges("after")
    assert south2 == pytest.approx(south + 0.5, abs=0.1) and north2 == pytest.approx(north, abs=0.1)


def _aerial_net_and_map(tmp_path, p):
    v, f, lab, rgb, _, _ = aerial_lane()
    net = scan.derive_network(v, f, lab, p, curbs=False, rgb=rgb)
    scan.add_heights_and_signals(net, v, f, lab, p)
    nod, edg = scan.write_plain(net, p, PROJ, tmp_path / "plain")
    scan.netconvert_plain(nod, edg, tmp_path / "a.xodr", p)
    return v, f, net, (tmp_path / "a.xodr").read_text()


def test_a_lane_edge_over_a_low_wall_is_off_the_scan_though_within_the_height_tolerance(tmp_path):
    """A wall 0.25 m high along the lane's south edge (a garden wall the grey mask took as road; IGN's
    village): the surface there is within lane_tol_m (0.3 m) of the lane, so by height alone it is on. The
    step test sees the step between neighbouring samples across the lane and marks the samples
    beyond it off; check_lanes then narrows that side. With lane_step_m=0 (no step test) nothing is."""
    p = scan.ScanSourceParams()
    v, f, net, text = _aerial_net_and_map(tmp_path, p)
    wall = v.copy()
    wall[(wall[:, 1] >= -3.01) & (wall[:, 1] <= -2.49), 2] += 0.25
    lh = scan.lane_heights(text, wall, f, tol_m=p.lane_tol_m, step_m=p.lane_step_m)
    south = lh["xy"][:, 1] < -2.3  # the lanes reach y = -2.6 (a 5.2 m road on the 6 m lane)
    assert south.any() and lh["off"][south].mean() > 0.9 and lh["on"][lh["xy"][:, 1] > -2.0].mean() > 0.95
    flat = scan.lane_heights(text, wall, f, tol_m=p.lane_tol_m, step_m=0.0)
    assert flat["on"][south].mean() > 0.9  # by height alone: on
    assert scan.check_lanes(net, text, wall, f, p)["narrow"]
    assert not scan.check_lanes(net, text, wall, f, dataclasses.replace(p, lane_step_m=0.0))["narrow"]


def test_a_stretch_of_road_beside_a_hedge_moves_away_from_it(tmp_path):
    """A hedge 1.5 m high over the lane's south 0.5 m for 12 m (x from -6 to 6), open ground everywhere else:
    the road's south edge is off the scan only along that stretch, too short to narrow the whole road, so
    check_lanes asks to move that stretch north (away from the hedge) and nudge_arms moves those shape
    points half edge_band_m north, tapered to their neighbours; the road's far ends do not move."""
    p = scan.ScanSourceParams()
    v, f, net, text = _aerial_net_and_map(tmp_path, p)
    hedge = v.copy()
    hedge[(hedge[:, 1] >= -3.01) & (hedge[:, 1] <= -2.49) & (np.abs(hedge[:, 0]) <= 6.0), 2] += 1.5
    chk = scan.check_lanes(net, text, hedge, f, p)
    assert not chk["narrow"] and len(chk["nudge"]) == 1
    (k, move), = chk["nudge"].items()
    arm = net.arms[k]
    before = arm.xy.copy()
    assert scan.nudge_arms(net, chk["nudge"], p) == 1
    dy = arm.xy[:, 1] - before[:, 1]
    at = np.abs(before[:, 0]) <= 4.0
    assert at.any() and np.all(dy[at] == pytest.approx(0.5 * p.edge_band_m, abs=0.02))
    assert np.all(np.abs(dy[np.abs(before[:, 0]) > 14.0]) < 1e-9)
    assert not scan.check_lanes(net, text, v, f, p)["nudge"]  # the scan without the hedge: nothing to move


def test_a_lane_under_a_low_overhang_is_off_the_scan_though_its_ground_is_there(tmp_path):
    """A slab 1.2 m over the lane's south edge for 4 m (a hedge's overhang, a low wall's coping, a carport),
    the ground under it intact: by its height the lane is on the scan there, but a car would drive into the
    slab. With lane_clear_m (2 m) the samples under it are off and check_lanes asks to move that stretch;
    with lane_clear_m=0 nothing is off."""
    p = scan.ScanSourceParams()
    v, f, net, text = _aerial_net_and_map(tmp_path, p)
    under = (np.abs(v[:, 0] - 5.0) <= 2.0) & (v[:, 1] >= -3.0) & (v[:, 1] <= -2.0)
    z = float(v[under, 2].max()) + 1.2
    slab = np.array([[3.0, -3.0, z], [7.0, -3.0, z], [7.0, -2.0, z], [3.0, -2.0, z]])
    v2 = np.vstack([v, slab])
    n = len(v)
    f2 = np.vstack([f, [[n, n + 1, n + 2], [n, n + 2, n + 3]]])
    lh = scan.lane_heights(text, v2, f2, tol_m=p.lane_tol_m, clear_m=p.lane_clear_m)
    below = (np.abs(lh["xy"][:, 0] - 5.0) <= 1.8) & (lh["xy"][:, 1] <= -2.1)
    assert below.any() and lh["off"][below].all()
    assert scan.lane_heights(text, v2, f2, tol_m=p.lane_tol_m)["on"][below].all()
    chk = scan.check_lanes(net, text, v2, f2, p)
    assert chk["nudge"] or chk["narrow"] or chk["bad_points"]
    chk0 = scan.check_lanes(net, text, v2, f2, dataclasses.replace(p, lane_clear_m=0.0))
    assert not (chk0["nudge"] or chk0["narrow"] or chk0["bad_points"])


def test_a_lane_over_ground_the_scan_never_measured_is_off_an_enclosed_hole_is_left_to_the_drop_test(tmp_path):
    """A band 3 m wide across the whole tile with no surface (x from 20 to 23: a sweep's far range between two
    rings, open to the scan's edge) and a 1 m hole in the lane (x, y about -10, 1: a parked car's shadow, which
    lift_movables closes). Without the unscanned raster both are holes left to the drop test (neither on nor
    off; the seventeenth sweep's junction ran over such ground and the drop test lost 0.6 % of its rays there);
    with it the band's samples are off (and the road there is cut) while the enclosed hole stays neither. A car
    parked at the tile's edge covers nothing: lift_movables takes it out and no scan saw the ground beneath."""
    from twinkit.surface.watertight import OpenGround

    p = scan.ScanSourceParams()
    v, f, net, text = _aerial_net_and_map(tmp_path, p)
    c = v[f].mean(axis=1)
    band = (c[:, 0] > 20.0) & (c[:, 0] < 23.0)
    hole = (np.abs(c[:, 0] + 10.0) < 0.5) & (np.abs(c[:, 1] - 1.0) < 0.5)
    f2 = f[~band & ~hole]
    bare = OpenGround.of_mesh(v, f2, p.open_gap_m)
    assert bare.at(np.array([[21.5, 0.0], [21.5, -30.0]])).all()  # the band: never measured
    assert not bare.at(np.array([[-10.0, 1.0], [0.0, 0.0]])).any()  # the hole, the lane: no
    lh0 = scan.lane_heights(text, v, f2, tol_m=p.lane_tol_m)
    lh = scan.lane_heights(text, v, f2, tol_m=p.lane_tol_m, unscanned=bare)
    xy = lh["xy"]
    in_band = (xy[:, 0] > 20.3) & (xy[:, 0] < 22.7)
    in_hole = (np.abs(xy[:, 0] + 10.0) < 0.4) & (np.abs(xy[:, 1] - 1.0) < 0.4)
    assert in_band.sum() >= 7 and in_hole.any()
    assert not (lh0["on"] | lh0["off"])[in_band].any()  # without the raster: left to the drop test
    assert lh["off"][in_band].all() and lh["bare"][in_band].all()
    near_band = (xy[:, 0] > 19.5) & (xy[:, 0] < 23.5)
    assert not (lh["on"] | lh["off"])[in_hole].any() and not lh["bare"][~near_band].any()
    chk = scan.check_lanes(net, text, v, f2, p, unscanned=bare)
    assert chk["bare_samples"] == int(lh["bare"].sum()) and chk["bad_points"]
    assert not scan.check_lanes(net, text, v, f2, p)["bad_points"]
    # a car parked at the tile's edge (lift_movables takes it out): the ground under it was never measured
    c2 = v[f2].mean(axis=1)
    car = (c2[:, 0] > 37.0) & (np.abs(c2[:, 1]) < 1.0)
    at_car = np.array([[38.5, 0.0]])
    assert not bare.at(at_car).any()
    assert OpenGround.of_mesh(v, f2[~car], p.open_gap_m).at(at_car).all()
    # the mesh's open border along the lane's south edge (a strip 1.5 m wide the scan never measured, the length of
    # the tile): its samples are off, yet no side is narrowed or moved (an open border is no obstacle)
    strip = f[~((c[:, 1] > -3.9) & (c[:, 1] < -1.9))]
    bare3 = OpenGround.of_mesh(v, strip, p.open_gap_m)
    chk3 = scan.check_lanes(net, text, v, strip, p, unscanned=bare3)
    assert chk3["bare_samples"] > 20 and not chk3["narrow"] and not chk3["nudge"]


def test_a_road_end_over_ground_the_scan_never_measured_is_cut_back_until_its_lanes_are_whole(tmp_path):
    """A sweep's far range ends in a staircase of filled ground: the last metres of a road that runs out there
    have the outer edge of a lane over nothing (seq00_000000: 61 of its 179 failing drop-test rays, all within 5 m
    of a road's free end). Too few samples for the lane check's share (2 of 14 across the road), so the road was
    kept, and the drop test lost them. From a free end the road is now cut back to the last shape point with a
    sample over never-measured ground. Inside the road the same notch (1 of a shape point's 14 samples) cuts
    nothing; a deeper one, over more than a tenth of them (inner_unscanned_share), is off, and over 2 shape
    points it splits the road (spvnas_sample_000000: a road brushing the capture's border with its outer lane for
    5 m, 455 failing rays)."""
    from twinkit.surface.watertight import OpenGround

    p = scan.ScanSourceParams()
    v, f, net, text = _aerial_net_and_map(tmp_path, p)
    ends = [k for k, arm in enumerate(net.arms) if net.nodes[arm.b]["kind"] == "end" or net.nodes[arm.a]["kind"] == "end"]
    assert ends
    c = v[f].mean(axis=1)
    end_notch = (c[:, 0] > 33.0) & (c[:, 1] < -2.3)  # the south lane's outer edge, the last 7 m, open to the south
    mid_notch = (c[:, 0] > -5.0) & (c[:, 0] < -1.0) & (c[:, 1] < -2.3)  # the same 4 m inside the road
    deep_notch = (c[:, 0] > 10.0) & (c[:, 0] < 16.0) & (c[:, 1] < -1.7)  # 6 m, 0.6 m further into the lane
    f2 = f[~end_notch & ~mid_notch & ~deep_notch]
    bare = OpenGround.of_mesh(v, f2, p.open_gap_m)
    assert bare.at(np.array([[36.0, -2.7], [-3.0, -2.7]])).all()
    chk = scan.check_lanes(net, text, v, f2, p, unscanned=bare)
    assert chk["bad_points"], chk
    bad_x = np.concatenate([net.arms[k].xy[b][:, 0] for k, b in chk["bad_points"].items()])
    assert min(x for x in bad_x if x > 30.0) < 34.5  # the end, back to where the lanes are whole
    inside = bad_x[bad_x < 30.0]
    assert len(inside) >= 2 and (inside > 8.0).all() and (inside < 18.0).all(), bad_x  # the deep notch, no more
    ends_only = scan.check_lanes(net, text, v, f2, dataclasses.replace(p, inner_unscanned_share=1.0), unscanned=bare)
    for k, b in ends_only["bad_points"].items():
        assert (net.arms[k].xy[b][:, 0] > 30.0).all()  # the share rule alone keeps the road's inside
    old = scan.check_lanes(net, text, v, f2, dataclasses.replace(p, end_unscanned_share=1.0, inner_unscanned_share=1.0),
                           unscanned=bare)
    assert not old["bad_points"], old["bad_points"]  # the share rule alone keeps the whole road


def _turns(text: str) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """The driving connecting roads of a map, as carla.Map reads them: (junction id, first lane centre, last)."""
    from twinkit.street.lanes import LaneMap

    wp = LaneMap(text, "turns").waypoints(1.0)
    wp = wp.take(wp.is_type("driving") & (wp.junction >= 0))
    out = []
    for rid in np.unique(wp.road):
        m = wp.road == rid
        xy, s = wp.xyz[m, :2], wp.s[m]
        out.append((int(wp.junction[m][0]), xy[np.argmin(s)], xy[np.argmax(s)]))
    return out


def test_a_turn_over_ground_the_scan_never_measured_is_not_made_the_others_stay(four_way, tmp_path):
    """A junction's turn whose lane cuts a corner the scan never measured (seq00_000001: one connecting lane over
    a block's unscanned corner, 758 of its 1,047 failing drop-test rays) passed the lane check: the junction's
    share judges all its turns together (80 % of their samples on). Such a turn is now found on its own and
    netconvert is told not to make it (a connection file's ``delete``), while every lane keeps a way on: the
    turns that start where it starts stay, and so does the junction."""
    import copy

    from twinkit.surface.watertight import OpenGround

    v, f, lab, truth, net, text = four_way
    p = scan.ScanSourceParams()
    c = v[f].mean(axis=1)
    bite = (c[:, 0] > 2.05) & (c[:, 0] < 6.25) & (c[:, 1] > 7.5) & (c[:, 1] < 11.7)  # the north-east corner
    channel = (np.abs(c[:, 0] - c[:, 1] + 5.45) < 1.5) & (c[:, 1] > 8.7)  # to the tile's edge over the sidewalk
    f2 = f[~bite & ~channel]
    bare = OpenGround.of_mesh(v, f2, p.open_gap_m)
    chk = scan.check_lanes(net, text, v, f2, p, unscanned=bare)
    assert chk["bad_turns"] and not chk["bad_junctions"], chk["bad_junctions"]
    assert len(chk["bad_turns"]) == len(scan.check_lanes(net, text, v, f2, dataclasses.replace(p, turn_off_samples=0),
                                                         unscanned=bare)["bad_turns"])  # each turn once, both rules
    assert not scan.check_lanes(net, text, v, f2, dataclasses.replace(p, turn_unscanned_samples=0, turn_off_samples=0),
                                unscanned=bare)["bad_turns"]
    before = _turns(text)
    net2 = copy.deepcopy(net)
    net2.no_turns = list(chk["bad_turns"])
    nod, edg = scan.write_plain(net2, p, PROJ, tmp_path / "plain")
    con = scan.write_turns(net2, edg, tmp_path / "plain")
    assert con is not None and "<delete " in con.read_text()
    scan.netconvert_plain(nod, edg, tmp_path / "turns.xodr", p, con=con)
    after = _turns((tmp_path / "turns.xodr").read_text())
    assert len(after) < len(before)
    for _, a, b in chk["bad_turns"]:  # the dropped turns are gone...
        assert not any(np.hypot(*(a2 - a)) < 1.0 and np.hypot(*(b2 - b)) < 1.0 for _, a2, b2 in after)
        assert any(np.hypot(*(a2 - a)) < 1.0 for _, a2, _ in after)  # ...and their lane still leads on
    starts = {tuple(np.round(a, 0)) for _, a, _ in before}
    assert starts == {tuple(np.round(a, 0)) for _, a, _ in after}  # no lane without a way on
    # without a dropped turn no file is written and netconvert makes them all
    assert scan.write_turns(net, edg, tmp_path / "plain") is None and not (tmp_path / "plain" / "scan.con.xml").exists()


def test_a_turn_over_a_raised_corner_is_not_made_the_others_stay(four_way):
    """A junction's turn whose lane runs over a raised verge at the corner it cuts (seq00_000000: one turn over a
    verge, 106 of its 200 failing drop-test rays) is off the scanned surface there, although the ground is
    measured; the junction's share (80 % on over all its turns) kept it. Such a turn is now found on its own
    (``turn_off_samples``) as one over ground never measured is, and only while another turn leaves its lane."""
    v, f, lab, truth, net, text = four_way
    p = scan.ScanSourceParams()
    v2 = np.array(v, dtype=float)
    corner = (v2[:, 0] > 2.05) & (v2[:, 0] < 6.25) & (v2[:, 1] > 7.5) & (v2[:, 1] < 11.7)  # the north-east corner
    v2[corner, 2] += 0.5  # a bed or verge above the street, measured
    chk = scan.check_lanes(net, text, v2, f, p)
    assert chk["bad_turns"] and not chk["bad_junctions"], chk["bad_junctions"]
    assert chk["bare_samples"] == 0  # nothing over ground the scan never measured: the turn is off, not bare
    turns = _turns(text)
    for _, a, b in chk["bad_turns"]:  # each dropped turn is one of the map's, and its lane keeps another way on
        assert any(np.hypot(*(a2 - a)) < 1.0 and np.hypot(*(b2 - b)) < 1.0 for _, a2, b2 in turns)
        assert sum(np.hypot(*(a2 - a)) < 1.0 for _, a2, _ in turns) >= 2
    assert not scan.check_lanes(net, text, v2, f, dataclasses.replace(p, turn_off_samples=0))["bad_turns"]
    assert not scan.check_lanes(net, text, v, f, p)["bad_turns"]  # the flat corner: every turn stays


def test_every_scan_parameter_says_what_it_does():
    """Each road_source=scan parameter carries its one line of help (param(help=...)), not a # comment."""
    from twinkit.ranges import help_of

    missing = [f.name for f in dataclasses.fields(scan.ScanSourceParams) if not help_of(f)]
    assert not missing, missing


def test_the_lane_check_without_edge_bands_still_says_nothing_to_nudge(four_way):
    """edge_band_m=0 (no narrowing) leaves narrow and nudge empty; the source's round reads both."""
    v, f, lab, truth, net, text = four_way
    chk = scan.check_lanes(net, text, v, f, scan.ScanSourceParams(edge_band_m=0.0))
    assert chk["narrow"] == {} and chk["nudge"] == {}


def test_a_road_beside_lower_ground_takes_its_own_height_where_no_level_face_is_near():
    """A 60 m road at z 0 between a verge 0.5 m lower (south, its east half only) and a kerbed pavement (north):
    the level test keeps the verge's faces and none of the east half's carriageway (lower ground lies within its
    window), so the level raster nearest-filled from the verge put that road half a metre under its surface and
    trim_unsupported cut it away (a real sweep's far street, issue 46). With the carriageway mask the road's own
    faces give its height there; the west half, where the level faces are the road's, is as before."""
    from twinkit_roads.mesh2d import Grid
    from twinkit_roads.scan.masks import level_raster, rasterize_faces

    xs = np.arange(-30.0, 30.0 + 1e-9, 0.5)
    ys = np.arange(-10.0, 8.0 + 1e-9, 0.5)
    X, Y = np.meshgrid(xs, ys)
    x, y = X.ravel(), Y.ravel()
    road, verge = np.abs(y) <= 4.0, (y < -4.0) & (x > 0)
    v = np.stack([x, y, np.where(road, 0.0, np.where(verge, -0.5, 0.15))], 1)
    nx = len(xs)
    i, j = np.meshgrid(np.arange(len(ys) - 1), np.arange(nx - 1), indexing="ij")
    a = (i * nx + j).ravel()
    f = np.concatenate([np.stack([a, a + 1, a + nx + 1], 1), np.stack([a, a + nx + 1, a + nx], 1)]).astype(np.int64)
    c = v[f].mean(1)
    level = np.flatnonzero((c[:, 2] < -0.49) | ((c[:, 2] == 0.0) & (c[:, 0] < -9.0)))  # as level_faces finds them
    grid = Grid.around(v[:, :2], 0.25)
    mask = rasterize_faces(v, f, np.flatnonzero(np.all(np.abs(v[f][:, :, 1]) <= 4.0, axis=1)), grid)
    mid_east, mid_west = np.array([[15.0, 0.0], [25.0, 1.0]]), np.array([[-20.0, 0.0]])
    before = level_raster(v, f, level, grid)
    after = level_raster(v, f, level, grid, mask)
    assert np.allclose(grid.sample(before, mid_east), -0.5)  # nearest-filled from the verge
    assert np.allclose(grid.sample(after, mid_east), 0.0, atol=1e-6)
    assert np.allclose(grid.sample(after, mid_west), grid.sample(before, mid_west))
    # the road's shape points then lie on its surface, and the trim keeps the whole road
    xy = np.stack([np.arange(-28.0, 28.0 + 1e-9, 2.0), np.zeros(29)], 1)
    arm = scan.Arm(0, 1, xy, 8.0)
    net = scan.Network({0: {"xy": xy[0], "z": 0.0, "kind": "end"}, 1: {"xy": xy[-1], "z": 0.0, "kind": "end"}},
                       [arm], mask, grid, None, {}, level_faces=level)
    scan.add_heights_and_signals(net, v, f, None, scan.ScanSourceParams())
    assert np.abs(arm.z).max() < 0.05
    out = scan.trim_unsupported(net, v, f, scan.ScanSourceParams())
    assert out["cut_m"] == 0.0 and len(net.arms) == 1


def test_a_side_street_cut_off_by_a_mislabelled_mouth_is_bridged_to_its_junction():
    """A real sweep's 2D labels call 3 m of a side street's mouth sidewalk (SemanticKITTI seq00 000002): the road
    labels alone (a sweep's carriageway) leave the side street a stub apart from the main road. Its free end
    points at the main road across level scanned ground: bridged, one junction of three roads. The same gap
    raised 0.3 m (a planted island, a wall's foot) stays a gap; a small bump in it does not stop the bridge."""
    v, f, lab, _ = cross_mesh(step_m=0.5, side_arms="n")
    mouth = (np.abs(v[:, 0]) < 3.3) & (v[:, 1] > 9.2) & (v[:, 1] < 12.8)
    lab = lab.copy()
    lab[mouth] = SIDEWALK

    def junctions(vv, **kw):
        net = scan.derive_network(vv, f, lab, scan.ScanSourceParams(use_curbs=False, **kw))
        return sum(nd["kind"] == "junction" for nd in net.nodes.values()), len(net.arms), net.stats["bridges"]

    assert junctions(v, bridge_m=0.0)[:2] == (0, 2)  # the main road, and the side street apart from it
    n_j, n_arms, bridges = junctions(v)
    assert (n_j, n_arms) == (1, 3) and len(bridges) == 1
    assert 1.0 < bridges[0]["gap_m"] < 4.0 and abs(bridges[0]["from"][0]) < 1.0
    raised = v.copy()
    raised[mouth, 2] = 0.3
    assert junctions(raised)[:2] == (0, 2)
    # a small flat-topped bump 0.25 m up in the gap (a sweep's rough mesh: seq00_000002's mouth after its normals
    # faced up): a few per cent of the bridge's ground, not a wall across it
    bump = v.copy()
    bump[(np.abs(v[:, 0] - 1.25) < 0.3) & (np.abs(v[:, 1] - 10.75) < 0.55), 2] = 0.25
    assert junctions(bump)[:2] == (1, 3)
    assert junctions(bump, bridge_step_share=0.0)[:2] == (0, 2)  # as the rule was: no ground at all off the line


def test_a_street_sloping_away_from_its_junction_keeps_its_lanes_on_its_surface(tmp_path):
    """netconvert keeps a junction flat at its node's height and gives a road, at the junction's border, the
    junction's height, then smooths the jump along the road: a side street falling 8 % from the junction had its
    lanes up to 0.34 m over its surface past the border (a real sweep's north-west street, 0.33 m, was cut by the
    lane check for it). The map takes the heights the plain edges were given."""
    from twinkit.street.lanes import LaneMap

    v, f, lab, _ = cross_mesh(step_m=1.0, side_arms="n")
    v = v.copy()
    north = v[:, 1] > 8.7
    v[north, 2] -= 0.08 * (v[north, 1] - 8.7)
    net, text = derive_xodr(tmp_path, v, f, lab, use_curbs=False)
    assert sum(nd["kind"] == "junction" for nd in net.nodes.values()) == 1
    wp = LaneMap(text, "slope").waypoints(0.5)
    wp = wp.take(wp.is_type("driving") & ~wp.in_junction)
    side = (wp.xyz[:, 1] > 10) & (wp.xyz[:, 1] < 30) & (np.abs(wp.xyz[:, 0]) < 4)
    assert side.sum() > 40
    surface = -0.08 * (wp.xyz[side, 1] - 8.7)
    assert np.abs(wp.xyz[side, 2] - surface).max() < 0.05
    main = np.abs(wp.xyz[:, 1]) < 8.7
    assert np.abs(wp.xyz[main, 2]).max() < 0.05  # the flat main road stays on its surface

    # the junction's connecting lanes: straight between their roads' heights they miss the junction's surface
    # (flat, then falling) by up to 0.3 m; over the surface the scan source passes, tilted to meet their roads,
    # by less than 0.1 m
    def surface(xy):
        return np.where(xy[:, 1] > 8.7, -0.08 * (xy[:, 1] - 8.7), 0.0)

    plain = tmp_path / "plain"
    off = {}
    for name, surf in (("straight", None), ("surface", surface)):
        out = tmp_path / f"{name}.xodr"
        scan.netconvert_plain(plain / "scan.nod.xml", plain / "scan.edg.xml", out, scan.ScanSourceParams(), surface=surf)
        jw = LaneMap(out.read_text(encoding="utf-8"), name).waypoints(0.5)
        jw = jw.take(jw.is_type("driving") & jw.in_junction)
        off[name] = float(np.abs(jw.xyz[:, 2] - surface(jw.xyz[:, :2])).max())
    assert off["straight"] > 0.2 and off["surface"] < 0.1


def test_roads_follow_the_carriageway_under_their_lanes_not_the_edges_lean_into_the_junction(tmp_path):
    """A plain edge's heights are the carriageway sampled every 2 m, smoothed over three shape points, ending at
    the junction point's height: on a sweep the junction's middle is the blind circle under the sensor, and the
    roads' last metres leaned into it; the connecting lanes that start there lay 7-9 cm under the scanned
    ground. Here the edges dip 0.15 m towards the junction point over a flat surface: with the surface the
    roads' and the junction's lanes stay on it, with the edges' heights alone they lean."""
    import re

    from twinkit.street.lanes import LaneMap

    v, f, lab, _ = cross_mesh(step_m=1.0)
    net, text = derive_xodr(tmp_path, v, f, lab)
    plain = tmp_path / "plain"
    edg = (plain / "scan.edg.xml").read_text(encoding="utf-8")

    def dip(m):
        pts = []
        for pt in m.group(1).split():
            x, y, z = (float(c) for c in pt.split(","))
            pts.append(f"{x:.3f},{y:.3f},{z - 0.15 * max(0.0, 1 - np.hypot(x, y) / 14):.3f}")
        return f'shape="{" ".join(pts)}"'

    (plain / "scan.edg.xml").write_text(re.sub(r'shape="([^"]*)"', dip, edg), encoding="utf-8")
    off = {}
    for name, surf in (("edges", None), ("surface", lambda xy: np.zeros(len(xy)))):
        out = tmp_path / f"{name}.xodr"
        scan.netconvert_plain(plain / "scan.nod.xml", plain / "scan.edg.xml", out, scan.ScanSourceParams(), surface=surf)
        wp = LaneMap(out.read_text(encoding="utf-8"), name).waypoints(0.5)
        wp = wp.take(wp.is_type("driving") & (np.hypot(*wp.xyz[:, :2].T) < 16))
        off[name] = (float(np.abs(wp.xyz[~wp.in_junction, 2]).max()), float(np.abs(wp.xyz[wp.in_junction, 2]).max()))
    assert off["edges"][0] > 0.05 and off["edges"][1] > 0.05
    assert off["surface"][0] < 0.01 and off["surface"][1] < 0.01


def test_the_scans_own_network_keeps_its_heights_through_the_alignment(tmp_path):
    """align_roads measures a height offset between the road surface and the map; the scan's own network carries
    the scan's heights already (each direction's from its own lanes' surface), so the offset is reported, not
    applied: a real sweep's road vertices beside the axis sat 3-4 cm under its lanes' heights, and applying it took
    the drop test from 77 to 51 %. A map from elsewhere still gets its offset applied."""
    import json

    from twinkit.mesh import Mesh, write_ply
    from twinkit.testing import plugin_from_module, run_step

    import twinkit_roads.plugin as roads

    v, f, lab, _ = cross_mesh(step_m=1.0)
    _, text = derive_xodr(tmp_path, v, f, lab)
    low = v.copy()
    low[:, 2] -= 0.04  # the road surface 4 cm under the map's heights
    write_ply(tmp_path / "low.ply", Mesh(low, f))
    np.save(tmp_path / "labels.npy", lab)
    site = {"name": "cross", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 0.0}}
    step = plugin_from_module(roads, "step", "align_roads")
    dz = {}
    for name, xodr in (("scan", text), ("other", text.replace('<userData code="twinkit_road_source" value="scan"/>', ""))):
        (tmp_path / f"{name}.xodr").write_text(xodr)
        al = run_step(step, tmp_path / f"al_{name}", {"in_roads_xodr": tmp_path / f"{name}.xodr",
                                                      "in_textured_mesh_ply": tmp_path / "low.ply",
                                                      "in_labels_npy": tmp_path / "labels.npy"}, site=site)
        dz[name] = json.loads(al["alignment.json"].read_text())
    assert dz["scan"]["dz_m"] == 0.0 and dz["scan"]["dz_measured_m"] == pytest.approx(-0.04, abs=0.01)
    assert dz["other"]["dz_m"] == pytest.approx(-0.04, abs=0.01) and "dz_measured_m" not in dz["other"]


def test_sidewalk_lanes_are_kept_only_where_the_scanned_pavement_holds_them(four_way):
    """A sidewalk lane over no scanned ground is a fall for CARLA's walkers (the Lille corner's: its pavement
    scanned along three quarters of the road, the lane along all of it). On the intact cross no sidewalk
    changes; with the pavement north of the east arm gone past x = 14 m that sidewalk is dropped, with the
    outer 2 m of the pavement south of the west arm gone past x = -10 m that one is narrowed to the 1.5 m left."""
    from twinkit.surface.closest import Surface

    v, f, lab, truth, net0, text = four_way
    p = scan.ScanSourceParams()
    net = dataclasses.replace(net0, arms=[dataclasses.replace(a) for a in net0.arms])
    before = [(a.sidewalk_left_m, a.sidewalk_right_m) for a in net.arms]
    assert scan.check_sidewalks(net, text, p, Surface(v, f).scene) == []
    assert [(a.sidewalk_left_m, a.sidewalk_right_m) for a in net.arms] == before

    c = v[f].mean(axis=1)
    east_north = (c[:, 0] > 14) & (c[:, 1] > 8.7)
    west_south_outer = (c[:, 0] < -10) & (c[:, 1] < -8.7 - 1.5)
    cut = Surface(v, f[~(east_north | west_south_outer)]).scene
    rows = scan.check_sidewalks(net, text, p, cut)

    def side_towards(arm, y_sign):  # the arm's side whose normal points to +y (1) or -y (-1)
        from twinkit_roads.scan.geometry import normals

        return "left" if np.sign(normals(arm.xy)[:, 1].mean()) == y_sign else "right"

    east = next(k for k, a in enumerate(net.arms) if a.xy[:, 0].mean() > 10)
    west = next(k for k, a in enumerate(net.arms) if a.xy[:, 0].mean() < -10)
    got = {(r["road"], r["side"]): r for r in rows}
    assert set(got) == {(east, side_towards(net.arms[east], 1)), (west, side_towards(net.arms[west], -1))}
    assert got[(east, side_towards(net.arms[east], 1))]["to_m"] == 0.0
    assert getattr(net.arms[east], f"sidewalk_{side_towards(net.arms[east], 1)}_m") == 0.0
    narrowed = got[(west, side_towards(net.arms[west], -1))]
    assert 1.0 <= narrowed["to_m"] <= 2.0 and narrowed["from_m"] > 3.0
    # the other sides keep theirs
    assert getattr(net.arms[east], f"sidewalk_{side_towards(net.arms[east], -1)}_m") == before[east][
        0 if side_towards(net.arms[east], -1) == "left" else 1]


def test_the_lane_checks_outer_band_holds_the_driving_lanes_samples_beside_a_parking_strip(four_way):
    """The lane check narrows or moves a road where the outermost band of its driving lanes is off the scan; its
    samples are the driving lanes'. The band was taken at the parking strip's edge (the main road's 2.2 m strip
    at the kerb): it held no sample, and on a road with a strip neither narrowing nor moving could act."""
    from scipy.spatial import cKDTree

    from twinkit.surface.closest import Surface
    from twinkit_roads.scan.checks import lane_heights
    from twinkit_roads.scan.geometry import lanes_reach, normals

    v, f, lab, truth, net, text = four_way
    p = scan.ScanSourceParams()
    lh = lane_heights(text, v, f, scene=Surface(v, f).scene)
    main = [a for a in net.arms if a.lanes["strip_m"] > 1.0]
    assert main
    for arm in main:
        reach = lanes_reach(arm, p)
        assert reach == pytest.approx(arm.lanes["lanes"] * arm.lanes["lane_m"])
        d, i = cKDTree(arm.xy).query(lh["xy"])
        lateral = ((lh["xy"] - arm.xy[i]) * normals(arm.xy)[i]).sum(axis=1)
        mine = (d < reach + 1.0) & ~np.isin(lh["junction"], [j for j in set(lh["junction"]) if j])
        for sgn in (1, -1):
            band = mine & (sgn * lateral > reach - p.edge_band_m) & (sgn * lateral <= reach + 0.01)
            assert band.sum() >= 10


def test_a_small_recess_a_step_below_does_not_lift_the_street_off_the_carriageway_level():
    """The step test (``step_pieces``): a street's ground 20 x 20 m with a 3 m^2 entrance 15 cm lower beside
    it stays low; a pavement next to a carriageway a kerb lower is not low."""
    from twinkit_roads.mesh2d import step_pieces

    res = 0.2
    z = np.full((150, 100), np.inf)
    z[:100, :] = 0.0  # the street's ground, 20 x 20 m
    z[100:110, 40:55] = -0.15  # an entrance 2 x 3 m a step down, at its edge
    piece, low = step_pieces(z, res, 0.035)
    assert low[piece[50, 50]] and low[piece[105, 45]]
    z[110:150, :] = -0.15  # a carriageway 8 m wide, a kerb below the street's ground
    piece, low = step_pieces(z, res, 0.035)
    assert not low[piece[50, 50]] and low[piece[130, 50]]

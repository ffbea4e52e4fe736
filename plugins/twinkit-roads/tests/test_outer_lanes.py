"""Outer lanes (sidewalk, parking) at the map's ends narrowed to the scanned ground (ground_ends.trim_outer_lanes,
xodr_cut.narrow_lanes): a lane section where a sidewalk's ground ends, CARLA reads the result, and no sidewalk ray
is left without ground; a sidewalk inside the map is never narrowed."""
from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

carla = pytest.importorskip("carla")

from twinkit.street.lane_ground import on_ground  # noqa: E402
from twinkit.street.lanes import LaneMap  # noqa: E402

LANE_M, PARK_M, WALK_M = 3.25, 2.2, 2.0
KERB_Y = -(LANE_M + PARK_M)  # the kerb between the parking lane and the sidewalk (the road along +x at y = 0)


def _lane(lid: int, typ: str, w: float) -> str:
    return f'<lane id="{lid}" type="{typ}" level="false"><link/><width sOffset="0" a="{w}" b="0" c="0" d="0"/>' \
           f'<roadMark sOffset="0" type="solid" weight="standard" color="standard" width="0.13"/></lane>'


def street_map(linked_end: bool = False) -> str:
    """Road 1 along +x from x = 0 to 30 (a driving lane, a parking lane, a sidewalk on its right). Both of its
    ends are open (map ends); with ``linked_end`` its end leads on into road 2 (x 30 .. 40): not a map end."""
    road = """<road name="r" length="{L}" id="{id}" junction="-1"><link>{link}</link>
      <planView><geometry s="0" x="{x}" y="0" hdg="0" length="{L}"><line/></geometry></planView>
      <elevationProfile><elevation s="0" a="0" b="0" c="0" d="0"/></elevationProfile><lateralProfile/>
      <lanes><laneSection s="0"><center><lane id="0" type="none" level="false"><link/></lane></center>
      <right>{lanes}</right></laneSection></lanes></road>"""
    lanes = _lane(-1, "driving", LANE_M) + _lane(-2, "parking", PARK_M) + _lane(-3, "sidewalk", WALK_M)
    r1 = road.format(L=30, id=1, x=0, lanes=lanes,
                     link='<successor elementType="road" elementId="2" contactPoint="start"/>' if linked_end else "")
    r2 = road.format(L=10, id=2, x=30, lanes=lanes,
                     link='<predecessor elementType="road" elementId="1" contactPoint="end"/>') if linked_end else ""
    return f"""<?xml version="1.0"?><OpenDRIVE><header revMajor="1" revMinor="4" name="t" version="1"/>
      {r1}{r2}</OpenDRIVE>"""


def street_mesh(x_max: float = 31.0, pavement_from: float = 4.0, holes=()):
    """A 10 cm height field under the road's right side: carriageway and parking strip z = 0, the pavement 0.12 m
    higher beyond the kerb, scanned only from x = ``pavement_from`` on (behind a parked car at the scan's edge, the
    scanner never saw it); ``holes``: (x0, x1) spans of pavement the scan missed as well."""
    xs, ys = np.arange(-1.0, x_max + 1e-9, 0.1), np.arange(KERB_Y - WALK_M - 1.0, 1.0 + 1e-9, 0.1)
    gx, gy = np.meshgrid(xs, ys)
    v = np.c_[gx.ravel(), gy.ravel(), np.where(gy < KERB_Y, 0.12, 0.0).ravel()]
    i = np.arange(gx.size).reshape(gx.shape)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel()
    f = np.vstack([np.c_[a, b, d], np.c_[a, d, c]])
    cen = v[f].mean(axis=1)
    unseen = (cen[:, 1] < KERB_Y) & (cen[:, 0] < pavement_from)
    for x0, x1 in holes:
        unseen |= (cen[:, 1] < KERB_Y) & (cen[:, 0] > x0) & (cen[:, 0] < x1)
    return v, f[~unseen]


def sidewalk_rays_off_ground(text: str, v, f, spacing_m: float = 0.1) -> int:
    """Rays every ``spacing_m`` along and across the sidewalk lanes of width (as the drop test casts them) with no
    ground beneath (lane_ground.on_ground)."""
    ls = LaneMap(text).lanes(spacing_m)
    ls = ls.take(ls.is_type("sidewalk") & (ls.width > 1e-6))
    left, right = ls.borders()
    pts = np.vstack([np.c_[left + (right - left) * t, ls.xyz[:, 2]] for t in np.linspace(0.05, 0.95, 10)])
    return int((~on_ground(pts, v, f)).sum())


def _sections(text: str, rid: str) -> list[tuple[float, dict[str, float]]]:
    road = next(r for r in ET.fromstring(text).findall("road") if r.get("id") == rid)
    return [(float(sec.get("s")), {ln.get("id"): float(ln.find("width").get("a")) for ln in sec.iter("lane")
                                   if ln.find("width") is not None}) for sec in road.iter("laneSection")]


def test_sidewalk_whose_ground_ends_before_the_road_end_is_narrowed_there():
    from twinkit_roads.ground_ends import trim_outer_lanes

    text = street_map()
    v, f = street_mesh()
    assert sidewalk_rays_off_ground(text, v, f) >= 300  # today: 4 m of sidewalk over pavement the scan never saw
    out, rep = trim_outer_lanes(text, v, f)
    # a new lane section where the sidewalk's ground begins (+ the 0.5 m margin), the sidewalk without width before
    (s0, w0), (s1, w1) = _sections(out, "1")
    assert s0 == 0.0 and 4.0 <= s1 <= 5.0
    assert w0 == {"-1": LANE_M, "-2": PARK_M, "-3": 0.0} and w1 == {"-1": LANE_M, "-2": PARK_M, "-3": WALK_M}
    assert rep["narrowed"] == [{"road": "1", "end": "start", "lane": -3, "type": "sidewalk", "metres": s1}]
    assert rep["outer_off_ground_before"] > 0 == rep["outer_off_ground_after"]
    # CARLA reads it: the same driving waypoints, the lane of no width before the cut and the sidewalk after it
    before, after = carla.Map("a", text), carla.Map("b", out)
    assert len(after.generate_waypoints(1.0)) == len(before.generate_waypoints(1.0))
    assert after.get_crosswalks() == []
    assert after.get_waypoint_xodr(1, -3, 1.0).lane_width == pytest.approx(0.0)
    assert after.get_waypoint_xodr(1, -3, s1 + 1.0).lane_width == pytest.approx(WALK_M)
    assert after.get_waypoint_xodr(1, -2, 1.0).lane_width == pytest.approx(PARK_M)  # its ground is there
    w = after.get_waypoint_xodr(1, -1, 20.0).next(5.0)
    assert w and w[0].lane_id == -1
    assert sidewalk_rays_off_ground(out, v, f) == 0


def test_sidewalk_inside_the_map_is_never_narrowed():
    """Pavement missing in the middle of the road and next to an end that leads on into the next road: the map
    is not cut there (each block keeps one sidewalk); only the open end at x = 0 is."""
    from twinkit_roads.ground_ends import trim_outer_lanes

    text = street_map(linked_end=True)
    v, f = street_mesh(x_max=41.0, holes=[(14.0, 16.0), (27.0, 33.0)])
    out, rep = trim_outer_lanes(text, v, f)
    assert [(c["road"], c["end"]) for c in rep["narrowed"]] == [("1", "start")]
    assert len(_sections(out, "1")) == 2 and len(_sections(out, "2")) == 1
    assert _sections(out, "1")[-1][1]["-3"] == WALK_M


def test_outer_lanes_on_their_ground_leave_the_map_as_it_is():
    from twinkit_roads.ground_ends import trim_outer_lanes

    text = street_map()
    v, f = street_mesh(pavement_from=-1.0)
    out, rep = trim_outer_lanes(text, v, f)
    assert out == text and rep["narrowed"] == [] and rep["outer_off_ground_before"] == 0


def test_parking_lanes_step_narrows_the_sidewalk(tmp_path):
    """The step that moves the sidewalk lanes onto the pavement (parking_lanes) narrows them at the map's ends."""
    import json

    from twinkit.mesh import write_colored_ply
    from twinkit.testing import plugin_from_module, run_step

    import twinkit_roads.plugin as roads

    v, f = street_mesh()
    write_colored_ply(tmp_path / "textured_mesh.ply", v, f, np.full((len(v), 3), 128, np.uint8))
    np.save(tmp_path / "labels.npy", np.zeros(len(v), np.uint8))
    (tmp_path / "aligned.xodr").write_text(street_map())
    out = run_step(plugin_from_module(roads, "step", "parking_lanes"), tmp_path / "run",
                   {"in_aligned_xodr": tmp_path / "aligned.xodr", "in_textured_mesh_ply": tmp_path / "textured_mesh.ply",
                    "in_labels_npy": tmp_path / "labels.npy"}, roads.ParkingParams(osm_tags=False))
    doc = json.loads(out["parking.json"].read_text())
    assert [c["lane"] for c in doc["outer_lanes"]["narrowed"]] == [-3]
    assert sidewalk_rays_off_ground(out["aligned.xodr"].read_text(), v, f) == 0

"""Crosswalks: painted zebras found in a top view, OSM crossings, and the OpenDRIVE crosswalk objects as
CARLA 0.9.16 reads them (ObjectParser::Parse: cornerLocal only; Map::GetAllCrosswalkZones: the outline
around the reference line point at s), checked with the carla wheel's ``get_crosswalks``."""
from __future__ import annotations

import numpy as np
import pytest

from twinkit_roads.crosswalks import (Carriageway, OsmCrossing, merge, nearest_errors, osm_crossings,
                                      write_crosswalks)
from twinkit_roads.mesh2d import Grid
from twinkit_roads.zebras import find_zebras, zebras_in_mask

LANES = """<lanes><laneSection s="0">
  <left><lane id="1" type="driving" level="false"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane>
        <lane id="2" type="sidewalk" level="false"><width sOffset="0" a="2" b="0" c="0" d="0"/></lane></left>
  <center><lane id="0" type="none" level="false"/></center>
  <right><lane id="-1" type="driving" level="false"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane>
         <lane id="-2" type="driving" level="false"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane>
         <lane id="-3" type="sidewalk" level="false"><width sOffset="0" a="2" b="0" c="0" d="0"/></lane></right>
</laneSection></lanes>"""

# a straight road along +x through the site origin, reference line at y = 0, carriageway y = -6.5 .. 3.25
XODR = f"""<?xml version="1.0" encoding="UTF-8"?>
<OpenDRIVE><header revMajor="1" revMinor="4" name="" version="1.00"/>
<road name="A" length="50.0" id="1" junction="-1">
  <planView><geometry s="0" x="0" y="0" hdg="0" length="50.0"><line/></geometry></planView>
  <elevationProfile><elevation s="0" a="0" b="0" c="0" d="0"/></elevationProfile>
  {LANES}
</road>
</OpenDRIVE>
"""

BARS_X = (23.5, 26.5)  # the zebra's bars lie along the road, from x = 23.5 to 26.5


def lane_map(text: str):
    from twinkit.street.lanes import LaneMap

    return LaneMap(text, "test")


def bars_y(first: float = -6.25, last: float = 2.75) -> list[float]:
    """The bars' lower edges: 0.5 m wide, 1 m apart, across the carriageway."""
    return list(np.arange(first, last + 1e-9, 1.0))


def painted_mask(grid: Grid, ys: list[float], dashes: bool = True, stop_line: bool = True) -> np.ndarray:
    """A white-paint top view: zebra bars at ``ys`` (none when empty), lane dashes 0.12 m wide, a stop line."""
    xx = grid.x0 + (np.arange(grid.w) + 0.5) * grid.res
    yy = grid.y0 - (np.arange(grid.h) + 0.5) * grid.res
    X, Y = np.meshgrid(xx, yy)
    m = np.zeros(X.shape, bool)
    for y in ys:
        m |= (X >= BARS_X[0]) & (X <= BARS_X[1]) & (Y >= y) & (Y <= y + 0.5)
    if dashes:
        for x0 in np.arange(2.0, 48.0, 6.0):
            if not BARS_X[0] - 3 < x0 < BARS_X[1]:
                m |= (X >= x0) & (X <= x0 + 3.0) & (np.abs(Y + 3.25) <= 0.06)
    if stop_line:
        m |= (X >= 20.0) & (X <= 20.3) & (Y >= -6.5) & (Y <= 0.0)
    return m


def test_zebra_found_in_painted_stripes_and_not_in_lane_lines():
    grid = Grid(0.0, 10.0, 0.05, 1000, 400)
    zs = zebras_in_mask(painted_mask(grid, bars_y()), grid)
    assert len(zs) == 1
    z = zs[0]
    assert z.bars == 10
    assert abs(abs(z.axis[1]) - 1.0) < 1e-3  # walking across the bars: across the road
    assert np.allclose(z.centre, [25.0, -1.5], atol=0.1)
    assert z.length_m == pytest.approx(9.5, abs=0.15) and z.width_m == pytest.approx(3.0, abs=0.15)
    # the same street without a zebra: lane dashes and the stop line are no zebra
    assert zebras_in_mask(painted_mask(grid, []), grid) == []


def plane(colour_of) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A flat ground mesh x 20..30, y -8..5, 0.1 m grid, vertex colours from ``colour_of(x, y)``."""
    xs, ys = np.arange(20.0, 30.0 + 1e-9, 0.1), np.arange(-8.0, 5.0 + 1e-9, 0.1)
    X, Y = np.meshgrid(xs, ys)
    v = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], 1)
    nx = len(xs)
    i = np.arange(len(ys) - 1)[:, None] * nx + np.arange(nx - 1)[None, :]
    i = i.ravel()
    f = np.concatenate([np.stack([i, i + 1, i + nx + 1], 1), np.stack([i, i + nx + 1, i + nx], 1)])
    return v, f, np.array([colour_of(x, y) for x, y in v[:, :2]], np.uint8)


def test_find_zebras_in_a_mesh_with_painted_stripes_and_none_without():
    def zebra(x, y):
        on = BARS_X[0] <= x <= BARS_X[1] and any(b - 1e-6 <= y <= b + 0.5 + 1e-6 for b in bars_y())
        return (235, 235, 235) if on else (90, 90, 92)

    v, f, c = plane(zebra)
    zs = find_zebras(v, f, c, None)
    assert len(zs) == 1 and np.allclose(zs[0].centre, [25.0, -1.5], atol=0.2)
    v, f, c = plane(lambda x, y: (90, 90, 92))
    assert find_zebras(v, f, c, None) == []
    assert find_zebras(v, f, None, None) == []  # no colours: nothing to see, nothing claimed


def test_no_crosswalk_in_the_map_until_written_then_carla_reports_it_where_painted():
    assert lane_map(XODR).crosswalks() == []  # today's map: no crosswalk
    grid = Grid(0.0, 10.0, 0.05, 1000, 400)
    half = zebras_in_mask(painted_mask(grid, bars_y(-1.25, 2.75)), grid)  # the lower half hidden by a car
    assert len(half) == 1
    osm = [OsmCrossing("node/1", np.array([25.2, -1.0]))]
    cws, notes = merge(osm, half, Carriageway.of(lane_map(XODR)))
    assert notes == [] and [c.source for c in cws] == ["osm+scan"]
    text, records = write_crosswalks(XODR, cws)
    assert records[0]["written"] and records[0]["road"] == "1"
    got = lane_map(text).crosswalks()
    assert len(got) == 1
    g = got[0][:, :2]
    # kerb to kerb (y -6.5 .. 3.25) although half the paint was hidden; along the road where the paint is
    assert g[:, 1].min() == pytest.approx(-6.5, abs=0.15) and g[:, 1].max() == pytest.approx(3.25, abs=0.15)
    assert g[:, 0].min() == pytest.approx(23.5, abs=0.15) and g[:, 0].max() == pytest.approx(26.5, abs=0.15)
    assert np.allclose(g, cws[0].polygon, atol=0.01)  # CARLA's reading of cornerLocal is ours
    truth = np.array([[23.5, -6.5], [26.5, -6.5], [26.5, 3.25], [23.5, 3.25]])
    assert nearest_errors(got, [truth])[0] < 0.2


def test_osm_crossing_without_paint_and_zebra_without_osm_both_count():
    grid = Grid(0.0, 10.0, 0.05, 1000, 400)
    zs = zebras_in_mask(painted_mask(grid, bars_y()), grid)
    osm = [OsmCrossing("node/9", np.array([10.0, 0.0]))]  # 15 m from the zebra: another crossing
    cws, _ = merge(osm, zs, Carriageway.of(lane_map(XODR)), width_m=3.0)
    assert sorted(c.source for c in cws) == ["osm", "scan"]
    o = next(c for c in cws if c.source == "osm")
    assert np.ptp(o.polygon[:, 0]) == pytest.approx(3.0, abs=0.05)  # width_m along the road
    assert o.polygon[:, 1].min() == pytest.approx(-6.5, abs=0.3) and o.polygon[:, 1].max() == pytest.approx(3.25, abs=0.3)
    text, _ = write_crosswalks(XODR, cws)
    assert len(lane_map(text).crosswalks()) == 2
    # written again: the old crosswalk objects are replaced, not doubled
    assert len(lane_map(write_crosswalks(text, cws)[0]).crosswalks()) == 2


def test_osm_crossing_nodes_and_ways():
    from twinkit_roads.osmio import OsmData

    d = OsmData()
    d.nodes = {1: (0.0, 0.0, {"highway": "crossing", "crossing": "zebra"}), 2: (1.0, 1.0, {}),
               3: (1.0, 5.0, {}), 4: (1.0, 3.0, {"highway": "crossing"}), 5: (7.0, 7.0, {"highway": "traffic_signals"}),
               6: (-3.0, 0.0, {}), 7: (-1.0, 0.0, {}), 8: (9.0, 9.0, {"highway": "crossing"})}
    d.ways = {10: ([2, 4, 3], {"highway": "footway", "footway": "crossing"}),
              11: ([6, 7, 1], {"highway": "residential"})}
    got = osm_crossings(d, lambda ll: np.asarray(ll, float))
    by = {c.osm: c for c in got}
    assert set(by) == {"node/1", "node/8", "way/10"}  # node 4 lies on the way: one crossing
    assert np.allclose(by["way/10"].xy, [1.0, 3.0]) and np.allclose(by["way/10"].axis, [0.0, 1.0])
    assert np.allclose(np.abs(by["node/1"].axis), [0.0, 1.0])  # across the residential way (along x) at its end
    assert by["node/8"].axis is None  # on no road way: across the nearest lane later


def test_step_writes_the_crosswalks_carla_reports(tmp_path):
    import json

    from twinkit.mesh import write_colored_ply
    from twinkit.testing import plugin_from_module, run_step

    import twinkit_roads.plugin as roads

    def zebra(x, y):
        on = BARS_X[0] <= x <= BARS_X[1] and any(b - 1e-6 <= y <= b + 0.5 + 1e-6 for b in bars_y())
        return (235, 235, 235) if on else (90, 90, 92)

    v, f, c = plane(zebra)
    write_colored_ply(tmp_path / "textured_mesh.ply", v, f, c)
    (tmp_path / "aligned.xodr").write_text(XODR)
    out = run_step(plugin_from_module(roads, "step", "place_crosswalks"), tmp_path / "run",
                   {"in_aligned_xodr": tmp_path / "aligned.xodr", "in_textured_mesh_ply": tmp_path / "textured_mesh.ply"})
    assert set(out) == {"aligned.xodr", "crosswalks.json"}
    doc = json.loads(out["crosswalks.json"].read_text())
    assert doc["metrics"]["crosswalks"] == 1 and doc["metrics"]["carla_crosswalks"] == 1
    assert doc["crosswalks"][0]["source"] == "scan"
    assert len(lane_map(out["aligned.xodr"].read_text()).crosswalks()) == 1


def test_real_helsinki_osm_crossings():
    from conftest import need_shared

    from twinkit_roads.osmio import read_osm

    d = read_osm(need_shared("helsinki_center.osm.pbf"))
    lon0, lat0 = 24.94, 60.17  # a rough local frame is enough to count and orient

    def to_site(ll):
        ll = np.asarray(ll, float)
        return np.stack([(ll[:, 0] - lon0) * 55_500.0, (ll[:, 1] - lat0) * 111_200.0], 1)

    got = osm_crossings(d, to_site)
    ways = [c for c in got if c.osm.startswith("way/")]
    nodes = [c for c in got if c.osm.startswith("node/")]
    crossing_nodes = sum(1 for _, _, t in d.nodes.values() if t.get("highway") == "crossing")
    # 620 crossing nodes and 184 footway=crossing ways in the extract: the ways with two nodes or more inside
    # it, and the nodes that lie on none of them (the others are their way's crossing, not a second one)
    assert (crossing_nodes, len(ways), len(nodes)) == (620, 179, 308)
    assert sum(c.axis is not None for c in got) / len(got) > 0.75  # a walking direction from OSM alone


def test_report_section_lists_the_crosswalks(tmp_path):
    import json

    from twinkit_roads.report import sec_crosswalks

    f = tmp_path / "29_place_crosswalks" / "crosswalks.json"
    f.parent.mkdir()
    f.write_text(json.dumps({"enabled": True, "metrics": {"osm_crossings": 1, "zebras": 1, "carla_crosswalks": 1},
                             "crosswalks": [{"id": "880000", "source": "osm+scan", "osm": "node/2", "centre": [1.0, 2.0],
                                             "zebra": {"bars": 9}, "road": "5", "s": 3.0, "note": ""}]}))

    class Ctx:
        def find(self, name):
            return [({"folder": f.parent.name}, f)]

        def read_json(self, p):
            return json.loads(p.read_text())

        def esc(self, t):
            return str(t)

        def table(self, head, rows, cls=""):
            return "|".join(head) + "".join("|".join(str(c) for c in r) for r in rows)

    html = sec_crosswalks(Ctx())
    assert "carla.Map reports 1 crosswalks" in html and "node/2" in html and "osm+scan" in html


def test_zebra_without_osm_needs_five_bars_across_its_road():
    from twinkit_roads.zebras import Zebra

    cw = Carriageway.of(lane_map(XODR))
    few = Zebra(np.array([25.0, -1.5]), np.array([0.0, 1.0]), 2.5, 3.0, 3)  # 3 bars: a misread, unless OSM says
    along = Zebra(np.array([25.0, -1.5]), np.array([1.0, 0.0]), 6.0, 3.0, 6)  # walking along the lanes
    cws, notes = merge([], [few, along], cw)
    assert cws == [] and len(notes) == 2
    assert "3 bars" in notes[0] and "along the lane" in notes[1]
    cws, notes = merge([OsmCrossing("node/1", np.array([25.0, 0.0]))], [few], cw)  # confirmed by OSM
    assert [c.source for c in cws] == ["osm+scan"] and notes == []

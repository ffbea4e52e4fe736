"""The drop test's lane kinds: parking lanes measured apart from the driving lanes (their own share and target), and
a lane of no width (narrowed away at a map end) casting no ray."""
from __future__ import annotations

import json

import numpy as np
import pytest

from twinkit.mesh import Mesh, write_ply
from twinkit.testing import run_step

from conftest import SITE, plugin, straight_xodr
from twinkit_export import synthetic

pytest.importorskip("carla")

KERB_Y = -0.5  # the straight test road at y = 5: driving y 1.5..5, parking -0.5..1.5, sidewalk -2.5..-0.5


def _map() -> str:
    """The straight 40 m test road with a parking lane between its right driving lane and the sidewalk; the
    sidewalk has no width over its first 10 m (a second lane section from s = 10 on)."""
    text = straight_xodr(length_m=40.0)
    park = '<lane id="-2" type="parking" level="false"><link/><width sOffset="0" a="2.0" b="0" c="0" d="0"/></lane>'
    walk = '<lane id="-3" type="sidewalk" level="false"><link/><width sOffset="0" a="{w}" b="0" c="0" d="0"/></lane>'
    old = text[text.index('<lane id="-2" type="sidewalk"'):text.index("</right>")]
    sec = text[text.index("<laneSection"):text.index("</laneSection>") + len("</laneSection>")]
    first = sec.replace(old, park + walk.format(w=0.0))
    second = sec.replace(old, park + walk.format(w=2.0)).replace('<laneSection s="0">', '<laneSection s="10">')
    return text.replace(sec, first + second)


def _ground():
    """A 10 cm grid under the road, the pavement 0.12 m above the carriageway beyond the kerb."""
    xs, ys = np.arange(0, 40.0001, 0.1), np.arange(-3.0, 10.0001, 0.1)
    X, Y = np.meshgrid(xs, ys)
    v = np.c_[X.ravel(), Y.ravel(), np.where(Y < KERB_Y - 0.05, 0.12, 0.0).ravel()]
    i = np.arange(X.size).reshape(X.shape)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel()
    return v, np.vstack([np.c_[a, b, d], np.c_[a, d, c]])


def test_lane_rays_count_parking_apart_and_skip_lanes_of_no_width():
    from twinkit_export.ground_check import lane_rays

    rays = lane_rays(_map(), 0.1)
    assert set(rays) == {"driving", "parking", "sidewalk"}
    # driving: two 3.5 m lanes over 40 m; parking: one 2 m lane; sidewalk: 2 m over the 30 m where it has a width
    assert 26000 < len(rays["driving"]) < 30000 and 7500 < len(rays["parking"]) < 8500
    assert 5500 < len(rays["sidewalk"]) < 6500 and rays["sidewalk"][:, 0].min() > 9.9
    assert (rays["driving"][:, 1] > 1.5).all() and ((rays["parking"][:, 1] > -0.5) & (rays["parking"][:, 1] < 1.5)).all()


def test_step_reports_parking_with_its_own_target(tmp_path):
    v, f = _ground()
    uv = np.c_[v[:, 0] / 40.0, (v[:, 1] + 3) / 13.0].astype(np.float32)
    obj = synthetic.write_obj(tmp_path / "textured_mesh.obj", v, f, uv, texture_px=64)
    (tmp_path / "aligned.xodr").write_text(_map())
    pts = Mesh(v.copy(), None, attrs={"normals": np.tile(np.array([0, 0, 1], np.float32), (len(v), 1))})
    write_ply(tmp_path / "points.ply", pts)
    out = run_step(plugin("step", "drop_test"), tmp_path / "out",
                   {"in_textured_mesh_obj": obj, "in_aligned_xodr": tmp_path / "aligned.xodr",
                    "in_points_ply": tmp_path / "points.ply"}, site=SITE)
    rep = json.loads(out["drop_test.json"].read_text())
    drv, park, walk = (rep["lanes"][k] for k in ("driving", "parking", "sidewalk"))
    assert park["target_pct"] == 99.5 and drv["target_pct"] == 99.9
    assert park["rays"] > 6000 and drv["hit_pct"] == 100.0 and walk["hit_pct"] == 100.0
    assert park["widest_hole_m"] == 0.0 and park["ground_ok"] is True
    metrics = json.loads((out["drop_test.json"].parent / "step.json").read_text())["metrics"]
    assert metrics["parking_rays"] == park["rays"] and metrics["parking_hit_pct"] == park["hit_pct"]
    assert "degraded" not in metrics


def test_parking_lane_edge_over_the_kerb_is_judged_off_the_kerb_line():
    """The kerb stands 10 cm inside the parking lane (its outer edge over the kerb's foot, as the parking step
    draws it): the outer row of rays meets the kerb. A parking lane is judged off the kerb line (a parked car's
    tyres stand off the kerb), so it holds; the same misses on a driving lane fail it (test_drop_test.py)."""
    from twinkit.surface.closest import Surface
    from twinkit_export.ground_check import DropTestParams, check_lane, lane_rays

    v, f = _ground()
    v[:, 2] = np.where(v[:, 1] < KERB_Y + 0.1, 0.12, 0.0)
    rays = lane_rays(_map(), 0.1)["parking"]
    mesh = Mesh(v, f)
    lane, holes, _ = check_lane("parking", rays, 99.5, mesh, Surface(v, f).scene, DropTestParams())
    assert lane["hit_pct"] < 99.0 and lane["kerb_line"] == lane["rays"] - lane["hits"]
    assert lane["target_on"] == "hit_pct_off_kerb_line" and lane["hit_pct_off_kerb_line"] == 100.0
    assert lane["ok"] is True and lane["ground_ok"] is True and not holes
    drv, _, _ = check_lane("driving", rays, 99.9, mesh, Surface(v, f).scene, DropTestParams())
    assert drv["ok"] is False and drv["target_on"] == "hit_pct"


def test_the_failing_rays_say_why_they_fail():
    """The driving lanes over a ground that ends at x = 36 m (the road runs on to 40 m: the capture ends), with
    a 0.4 m hole in the mesh at (10, 3) and a 15 cm bump along the lane's outer edge (y 4.8-5.0 m, x 20-30 m): the
    failing rays are told apart as falling through ground the scan never measured, through a hole of the mesh,
    or meeting a step or a bump, and those at a lane's edge are counted; the degraded message says so."""
    from twinkit.surface.closest import Surface
    from twinkit.surface.watertight import OpenGround
    from twinkit_export.ground_check import DropTestParams, _causes, check_lane, lane_rays

    v, f = _ground()
    bump = (v[:, 1] > 4.75) & (v[:, 1] < 5.05) & (v[:, 0] >= 20.0) & (v[:, 0] <= 30.0)
    v[bump, 2] += 0.15
    c = v[f].mean(axis=1)
    f = f[(c[:, 0] < 36.0) & ~((np.abs(c[:, 0] - 10.0) < 0.2) & (np.abs(c[:, 1] - 3.0) < 0.2))]
    rays, edges = lane_rays(_map(), 0.1, edges=True)
    r, e = rays["driving"], edges["driving"]
    assert len(e) == len(r) and e.min() >= 0 and e.max() <= 1.76
    lane, _, _ = check_lane("driving", r, 99.9, Mesh(v, f), Surface(v, f).scene, DropTestParams(), e,
                            lambda: OpenGround.of_mesh(v, f, 8.0))
    why = lane["failing"]
    off_end = int((r[:, 0] > 36.2).sum())
    assert why["fall_unscanned"] >= off_end and why["fall_unscanned"] <= off_end + 300
    in_hole = int(((np.abs(r[:, 0] - 10.0) < 0.25) & (np.abs(r[:, 1] - 3.0) < 0.25)).sum())
    seam = int(((r[:, 0] > 35.8) & (r[:, 0] < 36.3)).sum())  # the mesh's last column: a raster pixel's width
    assert 4 <= why["fall_hole"] <= in_hole + seam
    assert why["step_or_bump"] >= 100 and why["at_lane_edge"] >= 0.8 * why["step_or_bump"]
    assert why["rays"] == why["fall_unscanned"] + why["fall_hole"] + why["step_or_bump"]
    assert f"{why['fall_unscanned']} fall through ground the scan never measured" in _causes(why)

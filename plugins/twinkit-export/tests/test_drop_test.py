"""The drop test step: vertical rays over the lanes of a real carla.Map find the static mesh."""
from __future__ import annotations

import json

import numpy as np
import pytest

from twinkit.mesh import Mesh, write_ply
from twinkit.testing import run_step

from conftest import SITE, plugin, straight_xodr
from twinkit_export import synthetic

pytest.importorskip("carla")


def _street(hole_at=None, sidewalk_z=0.12):
    """A 40 x 12 m ground grid (10 cm) under the straight test road (driving lanes y 1.5..8.5, sidewalk
    y -0.5..1.5); the sidewalk stands ``sidewalk_z`` above the road (a kerb at y = 1.5); optionally a
    30 x 30 cm hole centred at ``hole_at``."""
    xs, ys = np.arange(0, 40.0001, 0.1), np.arange(-2.0, 10.0001, 0.1)
    X, Y = np.meshgrid(xs, ys)
    z = np.where(Y < 1.45, sidewalk_z, 0.0)
    v = np.c_[X.ravel(), Y.ravel(), z.ravel()]
    n, m = len(xs), len(ys)
    idx = np.arange(n * m).reshape(m, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    f = np.vstack([np.c_[a, b, d], np.c_[a, d, c]])
    if hole_at is not None:
        cen = v[f].mean(axis=1)
        f = f[~((np.abs(cen[:, 0] - hole_at[0]) < 0.15) & (np.abs(cen[:, 1] - hole_at[1]) < 0.15))]
    return v, f


def _run(tmp_path, v, f, name, from_scan=False):
    d = tmp_path / name
    d.mkdir()
    uv = np.c_[v[:, 0] / 40.0, (v[:, 1] + 2) / 12.0].astype(np.float32)
    obj = synthetic.write_obj(d / "textured_mesh.obj", v, f, uv, texture_px=64)
    text = straight_xodr(length_m=40.0)
    if from_scan:  # the tag road_source=scan writes into the header (docs/roads.md)
        i = text.index(">", text.index("<header"))
        text = text[:i + 1] + '<userData code="twinkit_road_source" value="scan"/>' + text[i + 1:]
        assert text[i - 1] != "/"  # the test map's header has children
    (d / "aligned.xodr").write_text(text)
    pts = Mesh(v.copy(), None, attrs={"normals": np.tile(np.array([0, 0, 1], np.float32), (len(v), 1))})
    write_ply(d / "points.ply", pts)
    out = run_step(plugin("step", "drop_test"), d / "out",
                   {"in_textured_mesh_obj": obj, "in_aligned_xodr": d / "aligned.xodr", "in_points_ply": d / "points.ply"},
                   site=SITE)
    return json.loads(out["drop_test.json"].read_text()), out


def _metrics(out: dict) -> dict:
    return json.loads((out["drop_test.json"].parent / "step.json").read_text())["metrics"]


def test_whole_street_holds_every_ray(tmp_path):
    v, f = _street()
    rep, out = _run(tmp_path, v, f, "whole")
    drv, sw = rep["lanes"]["driving"], rep["lanes"]["sidewalk"]
    # two 3.5 m lanes and a 2 m sidewalk over the 38 m inside the site (1 m margin at each end)
    assert 24000 < drv["rays"] < 29000 and 6500 < sw["rays"] < 8500
    assert drv["hit_pct"] == 100.0 and sw["hit_pct"] == 100.0  # the kerb-high sidewalk counts as on its lane
    assert rep["ok"] is True and rep["open_border_over_driving_lanes_m"] == 0.0
    assert drv["widest_hole_m"] == 0.0
    assert out["drop_test.png"].stat().st_size > 1000
    assert "degraded" not in _metrics(out)  # a whole ground is not a degraded result


def test_a_30cm_hole_in_a_lane_fails_and_is_located(tmp_path):
    v, f = _street(hole_at=(20.0, 3.0))
    rep, out_ = _run(tmp_path, v, f, "hole")
    drv = rep["lanes"]["driving"]
    missed = drv["rays"] - drv["hits"]
    assert 4 <= missed <= 16 and drv["fall_through"] == missed  # nothing under them: they fall through
    assert drv["hit_pct"] > 99.9  # one hole is a tiny share of the rays ...
    assert drv["widest_hole_m"] >= 0.29 and drv["ok"] is False and rep["ok"] is False  # ... but a wheel drops in
    top = drv["miss_clusters"][0]
    assert abs(top["x"] - 20.0) < 0.2 and abs(top["y"] - 3.0) < 0.2
    assert rep["open_border_over_driving_lanes_m"] > 1.0 and rep["open_chains_over_driving_lanes"] == 1
    assert rep["lanes"]["sidewalk"]["hit_pct"] == 100.0
    # the run ends "degraded" (exit 4), naming the lane kind and the hole
    reasons = [e["reason"] for e in _metrics(out_)["degraded"]]
    assert len(reasons) == 1 and "driving lanes" in reasons[0] and "hole 0." in reasons[0]


def test_a_lane_off_the_surface_misses_without_falling_through(tmp_path):
    v, f = _street(sidewalk_z=0.45)  # a sidewalk higher than any kerb: the rays meet it at another height
    rep, out = _run(tmp_path, v, f, "high", from_scan=True)
    sw = rep["lanes"]["sidewalk"]
    assert sw["hit_pct"] < 10.0 and sw["fall_through"] == 0 and sw["ok"] is False  # (the kerb slope row hits)
    # the degraded hint says what the misses are and, for a map derived from the scan, where to look
    (entry,) = _metrics(out)["degraded"]
    assert "sidewalk lanes" in entry["reason"]
    assert "find the ground at another height" in entry["hint"] and "road_source=scan" in entry["hint"]


def test_lane_edge_over_the_kerb_is_told_apart_and_does_not_fail_the_ground(tmp_path):
    """The kerb stands 5 cm inside the driving lane (the map's lane edge runs over the scanned kerb, as an
    alignment residual of a few cm does): the outer row of rays meets the kerb's slope. Those misses are
    counted as on the kerb line, the share stays below the target (ok false, a warning), but the ground
    holds (nothing falls through, every other ray hits): the run is not degraded."""
    v, f = _street()
    v[:, 2] = np.where(v[:, 1] < 1.55, 0.12, 0.0)
    rep, out = _run(tmp_path, v, f, "kerb")
    drv = rep["lanes"]["driving"]
    assert drv["fall_through"] == 0 and drv["hit_pct"] < 99.9 and drv["ok"] is False
    assert drv["kerb_line"] == drv["rays"] - drv["hits"] > 100  # every miss is on the kerb line
    assert drv["hit_pct_off_kerb_line"] == 100.0 and drv["ground_ok"] is True
    assert "degraded" not in _metrics(out)


def test_a_long_narrow_slit_is_not_a_hole_a_wheel_drops_into(tmp_path):
    """A slit 0.6 m long and 0.1 m wide (a crack along a kerb's face) is measured by its width: not a hole a tyre
    or a shoe drops into; the 30 cm square hole above still is."""
    v, f = _street()
    cen = v[f].mean(axis=1)
    f = f[~((np.abs(cen[:, 0] - 20.0) < 0.3) & (np.abs(cen[:, 1] - 3.0) < 0.05))]
    rep, out = _run(tmp_path, v, f, "slit")
    drv = rep["lanes"]["driving"]
    assert drv["fall_through"] > 0  # the rays over the slit fall through ...
    top = max(drv["fall_through_clusters"], key=lambda h: h["extent_m"])
    assert top["extent_m"] >= 0.4 and top["width_m"] <= 0.1  # ... along 0.5 m, across one ray
    assert drv["widest_hole_m"] <= 0.25 and drv["ok"] is True and "degraded" not in _metrics(out)

"""A photo set without GPS, GCPs or a scale: the scale estimated from a nominal eye height and marked as such,
the log saying what was done with a given scale, and the core report's lengths in the frame's units (issue 46,
item 6)."""
from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from twinkit.testing import make_context

import twinkit_photo.plugin as photo

from test_no_gps import _far_facade_model


def _georeference(tmp_path, caplog=None, **kw) -> tuple[dict, dict, dict, list]:
    """The georeference and roi steps on a model in units of 5 m (cameras 1.6 m over the ground):
    (georef.json, cameras_site.json, roi.json, the degraded reasons)."""
    sfm_dir = _far_facade_model(tmp_path, unit_m=5.0)
    ctx = make_context(tmp_path / "w", site={"name": "t"})
    out = tmp_path / "g"
    out.mkdir()
    photo.georeference(photo.GeorefParams(vertical_lines=False, **kw), ctx, in_sfm_dir=sfm_dir,
                       out_cameras_site_json=out / "cameras_site.json", out_georef_json=out / "georef.json",
                       out_sparse_site_ply=out / "sparse_site.ply")
    photo.roi(photo.RoiParams(), ctx, in_cameras_site_json=out / "cameras_site.json",
              in_sparse_site_ply=out / "sparse_site.ply", out_roi_json=out / "roi.json")
    docs = [json.loads((out / n).read_text()) for n in ("georef.json", "cameras_site.json", "roi.json")]
    return docs[0], docs[1], docs[2], ctx.degraded_reasons


def test_without_any_scale_the_nominal_eye_height_gives_metres_marked_as_an_estimate(tmp_path):
    """No GPS, GCPs, scale or distance: the cameras' height over the sparse ground (0.32 model units of 5 m)
    at a nominal 1.6 m gives 5 m per model unit; every file says the scale is estimated; the run is degraded
    (main: model units, scale 1)."""
    g, cams, roi, reasons = _georeference(tmp_path)
    assert g["scale_from"] == "eye height" and g["scaled"] is True
    assert abs(g["transform"]["scale"] - 5.0) < 0.1
    assert abs(g["eye_height"]["camera_height_model"] - 0.32) < 0.01
    for units in (g["units"], cams["units"], roi["units"]):
        assert "nominal eye height of 1.6 m" in units and "±20 %" in units
    assert cams["scale_from"] == "eye height"
    assert abs(roi["ground"]["z_m"] - (-1.6)) < 0.05  # the cameras' mean is the origin
    assert any("nominal eye height" in r["reason"] and "not a georeference" in r["reason"] for r in reasons)
    assert all("steps.georeference.distance_m" in r.get("hint", "") for r in reasons)


def test_eye_height_0_keeps_model_units(tmp_path):
    g, cams, roi, reasons = _georeference(tmp_path, eye_height_m=0.0)
    assert g["scaled"] is False and g["transform"]["scale"] == 1.0 and "scale_from" not in g
    assert roi["units"].startswith("model units")
    assert any("unscaled" in r["reason"] for r in reasons)


def test_a_given_scale_is_not_reported_as_only_levelled(tmp_path, caplog):
    """steps.georeference.scale=4.8: the log says the model was scaled by it (main: 'only levelled and centred
    (scale 4.800)'); no estimate, not degraded."""
    with caplog.at_level(logging.WARNING):
        g, _, roi, reasons = _georeference(tmp_path, scale=4.8)
    text = caplog.text
    assert "only levelled" not in text
    assert "scaled by steps.georeference.scale=4.8" in text
    assert g["scale_from"] == "steps.georeference.scale" and "eye_height" not in g
    assert roi["units"] == "metres" and not reasons


def test_a_known_distance_wins_over_the_eye_height(tmp_path, caplog):
    pts = [0, 0, 0, 2.0, 0, 0]  # 2 model units = 10 m
    with caplog.at_level(logging.WARNING):
        g, _, _, reasons = _georeference(tmp_path, distance_points_model=pts, distance_m=10.0)
    assert g["scale_from"] == "known distance" and abs(g["transform"]["scale"] - 5.0) < 1e-9
    assert "scaled by the known distance" in caplog.text and not reasons


def test_no_ground_under_the_cameras_leaves_model_units(tmp_path):
    """Too few points below the cameras: no estimate, the reason in georef.json, the run degraded as unscaled."""
    from twinkit_photo.georef_fit import eye_height_scale

    C = np.c_[np.linspace(0, 1, 5), np.zeros(5), np.ones(5)]
    est = eye_height_scale(C, np.c_[np.zeros(10), np.ones(10), np.zeros(10)], 1.6)
    assert "scale" not in est and "50 needed" in est["why_not"]


def test_the_core_report_says_model_units_for_an_unscaled_frame(tmp_path):
    """The core report's unit helper reads the steps' ``scaled`` metric (the georeference step's, from its
    georef.json): "model units" for an unscaled photo run, "m" otherwise (main: the core sections and the
    point-cloud section print "m")."""
    from twinkit.report.run import frame_unit

    g, _, _, _ = _georeference(tmp_path, eye_height_m=0.0)
    unscaled = [{"metrics": {"method": g["method"], "scaled": g["scaled"]}}, {"metrics": {"faces": 10}}]
    assert frame_unit(unscaled) == "model units"
    assert frame_unit([{"metrics": {"scaled": True, "scale_from": "eye height"}}]) == "m"
    assert frame_unit([{"metrics": {"faces": 10}}, {}]) == "m"


def test_the_point_cloud_and_core_sections_print_the_frame_unit(tmp_path):
    """The reconstruction metrics and the orthophoto's extent of an unscaled photo run say "model units"."""
    from types import SimpleNamespace

    from twinkit.report.sections import _orthophotos
    from twinkit_pointcloud.report import sec_recon_metrics

    f = tmp_path / "recon_metrics.json"
    f.write_text(json.dumps({"cloud_to_mesh": {"mean": 0.01, "p95": 0.03}, "cloud_within_m": {"0.05": 0.9},
                             "cloud_far": {"share": 0.1, "far_m": 0.5, "points": 10}}))
    ctx = SimpleNamespace(esc=str, length_unit=lambda: "model units", first=lambda pattern: ({"folder": "10_e"}, f),
                          read_json=lambda p: json.loads(Path(p).read_text()),
                          table=lambda head, rows, *a: "<table>" + " | ".join(map(str, head)) + "</table>")
    html = sec_recon_metrics(ctx)
    assert "distance (model units)" in html and "within (model units)" in html
    assert "0.5 model units from the mesh" in html and "(m)" not in html
    ortho = {"bounds": (0, 0, 30.0, 20.0), "texture": "img/o.png", "segmentation": None, "mesh": Path("m.ply")}
    ctx2 = SimpleNamespace(ortho=lambda: ortho, length_unit=lambda: "model units")
    assert "30.0 × 20.0 model units" in _orthophotos(ctx2)  # type: ignore[arg-type]


def test_the_photo_section_marks_an_estimated_scale(tmp_path):
    from test_report_section import _ctx, _step
    from twinkit_photo.report import sec_photos

    _georeference(tmp_path)
    html = sec_photos(_ctx([_step("georeference", tmp_path / "g", ["georef.json"])]))
    assert "Scale estimated" in html and "nominal eye height of 1.6 m" in html and "eye height" in html

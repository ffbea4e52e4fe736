"""twinkit-photo's section of the run report: photos registered and dropped, the georeference (levelling,
scale, outlier cameras), cameras against GPS on a top-down map, and a row per photo."""
from __future__ import annotations

import json
import types

from twinkit.plugins import load_registry
from twinkit.report.context import SectionContext
from twinkit.testing import plugin_from_module, run_step

import twinkit_photo.plugin as photo
from twinkit_photo.report import sec_photos

from test_steps import SITE, _arbitrary, _model_dir, _truth


def test_the_report_section_is_registered():
    reg = load_registry(extra=[("photo", photo)], entry_points=False)
    assert [(s.name, s.order) for s in reg.report_sections] == [("photos", 650.0)]


def _ctx(steps):
    ctx = SectionContext.__new__(SectionContext)
    ctx.run = types.SimpleNamespace(steps=steps)
    ctx.distribution = "twinkit-photo"
    return ctx


def _step(sid, folder, outputs):
    return {"id": sid, "folder": folder.name, "dir": folder,
            "record": {"distribution": "twinkit-photo", "descriptor": {"outputs": outputs}}}


def test_the_section_shows_dropped_photos_outliers_the_gps_map_and_coverage(tmp_path):
    from twinkit.geo import SiteFrame

    T = _arbitrary()
    _, C = _truth()
    C = C * [5.0, 1.0, 1.0]
    ll = SiteFrame.from_site(SITE).local_to_lonlat(C[:, :2])
    gps = {f"{k:02d}.jpg": [float(ll[k, 1]), float(ll[k, 0]), 13.6] for k in range(len(C))}
    sfm_dir, _, _ = _model_dir(tmp_path, T, gps)
    doc = json.loads((sfm_dir / "cameras_model.json").read_text())
    for k, cam in enumerate(doc["cameras"]):
        cam["center"] = T.apply(C[k] + ([0.0, 70.0, 0.0] if k == 5 else 0.0))[0].tolist()
    (sfm_dir / "cameras_model.json").write_text(json.dumps(doc))
    geo = run_step(plugin_from_module(photo, "step", "georeference"), tmp_path / "g", {"in_sfm_dir": sfm_dir},
                   photo.GeorefParams(), site=SITE)
    s1 = tmp_path / "01_sfm"
    s1.mkdir()
    (s1 / "sfm_report.json").write_text(json.dumps({"photos": 9, "registered": 8, "unregistered": ["08.jpg"],
                                                     "mean_reprojection_error_px": 0.7}))
    s3 = tmp_path / "04_dense"
    s3.mkdir()
    (s3 / "points_meta.json").write_text(json.dumps({"dense": {
        "valid_ratio": {"00.jpg": 0.42},
        "per_photo": {"00.jpg": 21000, "01.jpg": 20000, "02.jpg": 19000, "03.jpg": 1200}}}))
    steps = [_step("sfm", s1, ["sfm_report.json"]), _step("georeference", geo["georef.json"].parent, ["georef.json"]),
             _step("dense", s3, ["points_meta.json"])]
    html = sec_photos(_ctx(steps))
    assert "08.jpg" in html and "dropped" in html  # the photo sfm could not register
    assert "05.jpg" in html and "from its own GPS fix" in html  # the outlier camera and why
    assert html.count("<circle") == 8 and "#c0392b" in html  # 8 cameras on the map, the outlier in red
    assert "42.0 %" in html  # depth-map coverage from the dense step
    assert "21,000" in html and "1,200 (under a tenth of the median" in html  # points kept; the thin photo flagged
    assert "20,000 (" not in html
    assert "Unscaled" not in html and "up from" in html and "final vertical vs. the photos&#x27; horizon" in html
    # nothing of this plugin ran: no section
    assert sec_photos(_ctx([])) == ""

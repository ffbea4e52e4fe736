"""The demo site's photos end to end through sfm and georeference: every photo registers, and the GCP route
puts every camera centre within 5 cm of the truth (issue target). About two minutes on two cores."""
from __future__ import annotations

import json

import numpy as np

from twinkit.signature import parse_signature
from twinkit.testing import make_context, plugin_from_module, run_step

import twinkit_photo.plugin as photo

SITE = {"name": "demo", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 12.0}}


def _demo_site(folder):
    from twinkit_demo_site.plugin import DemoSiteParams, generate_demo_site

    sig = parse_signature(generate_demo_site)
    kw = {o.param: folder / o.filename for o in sig.outputs}
    generate_demo_site(DemoSiteParams(size="small", seed=0), make_context(folder, site=dict(SITE), step_id="site"), **kw)
    return folder


def test_demo_photos_register_and_georeference_within_5cm(tmp_path):
    site = _demo_site(tmp_path / "site")
    s = run_step(plugin_from_module(photo, "step", "sfm"), tmp_path / "sfm",
                 {"in_photos_dir": site / "photos", "in_cameras_json": site / "cameras.json"}, photo.SfmParams())
    rep = json.loads(s["sfm_report.json"].read_text())
    assert rep["registered"] == rep["photos"] == 40
    assert rep["mean_reprojection_error_px"] < 1.0
    g = run_step(plugin_from_module(photo, "step", "georeference"), tmp_path / "geo",
                 {"in_sfm_dir": s["sfm"], "in_gcp_json": site / "gcp.json", "in_cameras_json": site / "cameras.json"},
                 photo.GeorefParams(), site=dict(SITE))
    geo = json.loads(g["georef.json"].read_text())
    assert geo["method"] == "gcp" and geo["gcp"]["used"] >= 8
    err = geo["camera_centre_error_m"]
    assert err["n"] == 40 and err["max"] < 0.05 and err["mean"] < 0.03
    # the cameras file the dense step reads agrees with the truth too (not only the report)
    truth = {c["image"]: np.array(c["center"]) for c in json.loads((site / "cameras.json").read_text())["cameras"]}
    cams = json.loads(g["cameras_site.json"].read_text())["cameras"]
    d = [np.linalg.norm(np.array(c["center"]) - truth[c["image"]]) for c in cams]
    assert max(d) < 0.05

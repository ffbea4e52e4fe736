"""twinkit-pointcloud adds its own sections to the run report (hook twinkit_register_report_sections)."""
import json
from pathlib import Path
from types import SimpleNamespace

from twinkit.plugins import load_registry

import twinkit_pointcloud.plugin as plugin


def test_the_report_sections_are_registered():
    reg = load_registry(extra=[("pointcloud", plugin)], entry_points=False)
    assert [(s.name, s.title, s.order) for s in reg.report_sections] == [('pictures', '', 410.0), ('recon', 'Reconstruction metrics', 700.0)]


def test_the_reconstruction_metrics_print_the_frame_unit(tmp_path):
    """An unscaled photo run's reconstruction metrics say "model units", not metres."""
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

"""The example plugin's section of the run report."""
import json
from types import SimpleNamespace

from twinkit.plugins import load_registry
from twinkit.report import write_report

import twinkit_example.plugin as example


def _run(tmp_path, distribution: str):
    """A run folder with one finished xyz export, as the engine leaves it."""
    step = tmp_path / "02_export"
    step.mkdir()
    (step / "points.xyz").write_text("0 0 0\n1 0 0\n0 2 0\n")
    (step / "step.json").write_text(json.dumps({"distribution": distribution,
                                                "descriptor": {"plugin": {"kind": "exporter", "name": "xyz"},
                                                               "outputs": ["points.xyz"]}}))
    run = tmp_path / "runs" / "1"
    run.mkdir(parents=True)
    manifest = {"status": "ok", "steps": [{"id": "export", "folder": "02_export", "plugin": "exporter/xyz",
                                           "status": "ran", "metrics": {"points": 3}}]}
    return run, manifest


def test_the_report_shows_the_exported_points(tmp_path):
    registry = load_registry(extra=[("example", example)], entry_points=False)
    run, manifest = _run(tmp_path, distribution="example")
    page = write_report(run, manifest, SimpleNamespace(workspace=tmp_path, site_root=tmp_path, registry=registry))
    text = page.read_text()
    sec = text.split('<section id="xyz_points">', 1)[1].split("</section>", 1)[0]
    assert "<h2>Exported points</h2>" in sec and "02_export" in sec and ">3</td>" in sec
    assert 'href="../../../02_export/points.xyz"' in sec


def test_no_export_no_section(tmp_path):
    registry = load_registry(extra=[("example", example)], entry_points=False)
    run, manifest = _run(tmp_path, distribution="someone-else")  # not this plugin's step
    page = write_report(run, manifest, SimpleNamespace(workspace=tmp_path, site_root=tmp_path, registry=registry))
    assert 'id="xyz_points"' not in page.read_text()

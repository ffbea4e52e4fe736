"""A run that fails at a step still writes its HTML report, marked with the failing step (issue 28)."""
from __future__ import annotations

import json


def test_a_failed_run_writes_its_report_naming_the_failing_step(project):
    assert project.run("site=t", "recipe=chain").rc == 0
    r = project.run("site=t", "recipe=chain", "steps.make.fail=true")
    assert r.rc == 1, r.text
    run = sorted((project.ws / "runs").iterdir())[-1]
    manifest = json.loads((run / "manifest.json").read_text())
    assert manifest["status"] == "failed"
    assert manifest["failed_step"]["id"] == "make" and manifest["failed_step"]["folder"] == "01_make"
    assert "boom on purpose" in manifest["failed_step"]["error"]
    html = (run / "report" / "report.html").read_text()
    assert "Failed run:" in html and "<b>make</b>" in html and "boom on purpose" in html
    # the failing step is a red row of the timeline
    row = html[html.index('<td><a href="#step-01_make"'):]
    assert 'class="badge st-failed">failed<' in row[:row.index("</tr>")]
    assert "report file://" in r.err


def test_a_refused_run_writes_no_report(project):
    """A run refused before any step (a bad parameter) has nothing to report."""
    r = project.run("site=t", "recipe=chain", "steps.make.nope=1")
    assert r.rc != 0
    runs = sorted((project.ws / "runs").iterdir()) if (project.ws / "runs").exists() else []
    assert not any((d / "report" / "report.html").exists() for d in runs)

"""One quality gate (issue 46, item 2): ctx.gate records every gate's figure (passed or failed) in the step's
metrics, its log line, the report's "Quality gates" table; a failed gate makes the run degraded (exit 4); the
report lists every warning and names "no road network" beside the status."""
from __future__ import annotations

import json

import pytest

from twinkit.quality import DEGRADED_EXIT
from twinkit.testing import make_context


def _env(project):
    return project.env(TWINKIT_PLUGIN_MODULES="tests.support.engine_plugins,tests.support.gate_plugins")


def _last_run(project):
    return sorted((project.ws / "runs").iterdir())[-1]


def _gauge_project(project):
    project.recipe("gauged", ["{id: make, uses: step/make}", "{id: gauge, uses: step/gauge}"])
    return _env(project)


def test_gate_records_the_figure_passed_or_failed(tmp_path):
    from twinkit.quality import gate_entry, gate_text

    ctx = make_context(tmp_path, step_id="drop")
    assert ctx.gate("continuity driving", 99.95, 99.9, ">=", "%") is True
    assert ctx.degraded_reasons == []
    assert ctx.gate("widest hole", 0.4, 0.25, "<=", "m", why="a wheel drops in", hint="see drop_test.png") is False
    assert [g["ok"] for g in ctx._gates] == [True, False] and ctx._gates[1]["value"] == 0.4
    assert ctx.degraded_reasons[0]["reason"] == "widest hole 0.4 m (<= 0.25 m) FAILED: a wheel drops in"
    assert gate_text(gate_entry("x", None, 1.0)) == "x n/a (>= 1) ok"  # nothing measured: passes
    with pytest.raises(ValueError):
        gate_entry("x", 1.0, 1.0, "=~")


def test_a_passing_and_a_failing_gate_are_both_shown(project):
    env = _gauge_project(project)
    r = project.run("site=t", "recipe=gauged", "steps.gauge.need=60", env=env)  # cover 40 % < 60 %: fails
    assert r.rc == DEGRADED_EXIT, r.text
    step = json.loads((project.ws / "02_gauge" / "step.json").read_text())
    gates = {g["name"]: g for g in step["metrics"]["gates"]}
    assert (gates["cover"]["value"], gates["cover"]["ok"]) == (40.0, False)
    assert (gates["hole"]["value"], gates["hole"]["ok"]) == (0.1, True)
    line = next(x for x in r.text.splitlines() if "02_gauge" in x and "ran" in x)
    assert "cover 40 % (>= 60 %) FAILED" in line and "hole 0.1 m (<= 0.25 m) ok" in line, line
    m = json.loads((_last_run(project) / "manifest.json").read_text())
    assert m["status"] == "degraded" and [g["name"] for g in m["gates"]] == ["cover", "hole"]
    assert "cover 40 % (>= 60 %) FAILED" in m["degraded"][0]["reason"]
    html = (_last_run(project) / "report" / "report.html").read_text()
    assert 'id="gates"' in html and "Quality gates" in html
    table = html.split('id="gates"')[1].split("</section>")[0]
    assert "cover" in table and "40 %" in table and "&gt;= 60 %" in table and "FAIL" in table
    assert "hole" in table and "0.1 m" in table and "pass" in table
    st = project.run("status", "site=t", "recipe=gauged", "steps.gauge.need=60", env=env)
    assert any("DEGRADED" in x and "cover 40 %" in x for x in st.out.splitlines()), st.out
    # the same gates passing: ok, exit 0, the figures still printed
    r2 = project.run("site=t", "recipe=gauged", "steps.gauge.need=30", env=env)
    assert r2.rc == 0, r2.text
    assert "cover 40 % (>= 30 %) ok" in r2.text


def test_the_report_lists_a_warning_that_is_not_degraded(project):
    env = _gauge_project(project)
    r = project.run("site=t", "recipe=gauged", "steps.gauge.warn=true", "steps.gauge.gates=false", env=env)
    assert r.rc == 0, r.text
    html = (_last_run(project) / "report" / "report.html").read_text()
    assert 'id="warnings"' in html, "no Warnings section"
    warned = html.split('id="warnings"')[1].split("</section>")[0]
    assert "02_gauge" in warned and "the kerb is 7 cm lower than expected" in warned
    # a cached step keeps its warnings (they are stored with its result)
    r2 = project.run("site=t", "recipe=gauged", "steps.gauge.warn=true", "steps.gauge.gates=false", env=env)
    assert r2.rc == 0 and project.status_of(r2, "02_gauge") in ("reused", "cached")
    html2 = (_last_run(project) / "report" / "report.html").read_text()
    assert "the kerb is 7 cm lower than expected" in html2.split('id="warnings"')[1]


def test_the_status_names_no_road_network(project):
    env = _gauge_project(project)
    r = project.run("site=t", "recipe=gauged", "steps.gauge.no_roads=true", "steps.gauge.need=30", env=env)
    assert r.rc == 0, r.text
    m = json.loads((_last_run(project) / "manifest.json").read_text())
    assert m["status"] == "ok" and m["notes"] == ["no road network"]
    html = (_last_run(project) / "report" / "report.html").read_text()
    assert "ok · no road network" in html and "(ok · no road network)" in r.text

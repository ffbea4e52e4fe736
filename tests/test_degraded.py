"""A degenerate result never looks like success: ctx.degraded -> "degraded" run status, exit 4, red report,
`twinkit status` names it; cached and reused steps stay degraded."""
from __future__ import annotations

import json

from twinkit.quality import DEGRADED_EXIT, degraded_of, describe, with_degraded
from twinkit.testing import make_context


def _manifest(project) -> dict:
    run = sorted((project.ws / "runs").iterdir())[-1]
    return json.loads((run / "manifest.json").read_text())


def test_ctx_degraded_is_stored_with_the_metrics(tmp_path):
    ctx = make_context(tmp_path, step_id="clean")
    assert ctx.degraded_reasons == []
    ctx.degraded("trimming removed 99 % of the faces", "try reconstructor.max_dist_m=0.6")
    metrics = with_degraded({"faces": 7, "degraded": ["views are blank"]}, ctx.degraded_reasons)
    reasons = [e["reason"] for e in degraded_of(metrics, "clean")]
    assert reasons == ["views are blank", "trimming removed 99 % of the faces"]
    assert describe(degraded_of(metrics, "clean")[1]) == \
        "clean: trimming removed 99 % of the faces (try reconstructor.max_dist_m=0.6)"
    assert with_degraded({"faces": 9}, []) == {"faces": 9}  # a fine result carries no key


def test_a_degraded_step_makes_the_run_degraded_with_exit_4(project):
    r = project.run("site=t", "recipe=chain", "steps.scale.degrade_below=100")
    assert r.rc == DEGRADED_EXIT, r.text
    assert "DEGRADED" in r.text and "scaled value 6 is below 100" in r.text and "steps.scale.factor=10" in r.text
    m = _manifest(project)
    assert m["status"] == "degraded"
    assert [(e["step"], e["reason"]) for e in m["degraded"]] == [("scale", "scaled value 6 is below 100")]
    html = (sorted((project.ws / "runs").iterdir())[-1] / "report" / "report.html").read_text()
    assert 'class="degraded"' in html and "scaled value 6 is below 100" in html
    # reused from the folder: still degraded, and `status` says so
    r2 = project.run("site=t", "recipe=chain", "steps.scale.degrade_below=100")
    assert r2.rc == DEGRADED_EXIT and project.status_of(r2, "03_scale") == "reused"
    assert _manifest(project)["status"] == "degraded"
    st = project.run("status", "site=t", "recipe=chain", "steps.scale.degrade_below=100")
    assert st.rc == 0
    assert any(line.split()[:2] == ["03_scale", "DEGRADED"] and "below 100" in line for line in st.out.splitlines()), st.out
    # a fine result is "ok" with exit 0; the setting makes a degraded run exit 0 but keeps its status
    assert project.run("site=t", "recipe=chain").rc == 0
    assert _manifest(project)["status"] == "ok" and _manifest(project)["degraded"] == []
    r3 = project.run("site=t", "recipe=chain", "steps.scale.degrade_below=100", "engine.degraded_exit_code=0")
    assert r3.rc == 0 and _manifest(project)["status"] == "degraded"


def test_a_degraded_fan_out_item_is_named(project):
    project.recipe("fan", ["{id: make, uses: step/make}", "{id: tiles, uses: step/tiles}",
                           "{id: per_tile, uses: step/per_tile, foreach: tiles.json}"])
    r = project.run("site=t", "recipe=fan", "steps.tiles.n=3", "executor.workers=1",
                    env=project.env(TWINKIT_TEST_DEGRADE_TILE="1"))
    assert r.rc == DEGRADED_EXIT, r.text
    assert _manifest(project)["degraded"] == [{"reason": "tile 1 came out empty", "step": "per_tile", "item": 1}]


def test_a_sweep_with_a_degraded_job_exits_4(project):
    r = project.run("-m", "site=t", "recipe=chain", "steps.scale.degrade_below=0,100")
    assert r.rc == DEGRADED_EXIT, r.text
    jobs = sorted(p for p in (project.out / "t" / "sweeps").glob("*/*") if (p / "manifest.json").is_file())
    assert sorted(json.loads((j / "manifest.json").read_text())["status"] for j in jobs) == ["degraded", "ok"]

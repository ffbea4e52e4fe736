"""The profile of a run (issue 48, item 1): a step times its parts with ``ctx.substep``; the engine stores them in
step.json; the report's timeline and ``twinkit profile`` show them; two runs compare row by row."""
from __future__ import annotations

import json
from pathlib import Path

from twinkit.profile import OTHER, profile_delta, profile_rows, profile_table, read_profile
from twinkit.testing import make_context


def _env(project):
    return project.env(TWINKIT_PLUGIN_MODULES="tests.support.engine_plugins,tests.support.substep_plugins")


def test_substeps_add_up_and_nest(tmp_path):
    ctx = make_context(tmp_path)
    for _ in range(3):
        with ctx.substep("io"):
            pass
    with ctx.substep("model"):
        with ctx.substep("load"):
            pass
    subs = ctx.substeps
    assert list(subs) == ["io", "model/load", "model"]
    assert subs["io"]["calls"] == 3 and "calls" not in subs["model"]
    assert {"seconds", "peak_rss_mb", "delta_peak_mb", "start_s"} <= set(subs["model"])
    assert subs["io"]["start_s"] <= subs["model"]["start_s"]


def test_the_engine_records_the_substeps_a_step_declares(project):
    env = _env(project)
    project.recipe("timed", ["{id: make, uses: step/make}", "{id: timed, uses: step/timed}"])
    r = project.run("site=t", "recipe=timed", env=env)
    assert r.rc == 0, r.text
    rec = json.loads((project.ws / "02_timed" / "step.json").read_text())
    subs = rec["metrics"]["substeps"]
    assert set(subs) == {"read", "work", "work/inner"}, subs
    assert subs["read"]["calls"] == 2 and subs["work/inner"]["peak_rss_mb"] > 0
    assert rec["metrics"]["value"] == 1  # the step's own metrics are kept
    # the report's timeline: the step's bar in parts and a folded table of them
    run = sorted((project.ws / "runs").iterdir())[-1]
    html = (run / "report" / "report.html").read_text()
    timeline = html.split('<table class="timeline">', 1)[1].split("</table></details>")[0]
    assert 'class="bar st-ran split"' in timeline and 'title="read: ' in timeline
    assert '<tr class="substeps">' in timeline and "work/inner" in timeline
    # twinkit profile on the site folder and on the run folder
    for where in (project.ws, run):
        p = project.run("profile", str(where), env=env, outputs=False)
        assert p.rc == 0, p.text
        lines = p.out.splitlines()
        assert lines[0].split()[:5] == ["step", "substep", "seconds", "peak", "MB"]
        assert any(x.split()[:1] == ["timed"] for x in lines), p.out
        assert any(x.split()[:2] == ["read", "x2"] for x in lines), p.out
    bad = project.run("profile", str(project.tmp / "nothing"), env=env, outputs=False)
    assert bad.rc != 0 and "no step.json" in bad.text


def _fake_run(root: Path, steps: dict[str, tuple[float, dict]]) -> Path:
    for i, (sid, (sec, subs)) in enumerate(steps.items(), 1):
        d = root / f"{i:02d}_{sid}"
        d.mkdir(parents=True)
        d.joinpath("step.json").write_text(json.dumps({"step": sid, "status": "ran", "duration_s": sec,
                                                       "peak_rss_mb": 100.0 * i, "metrics": {"substeps": subs}}))
    return root


def _sub(sec: float, start: float, peak: float = 50.0) -> dict:
    return {"seconds": sec, "peak_rss_mb": peak, "delta_peak_mb": 1.0, "start_s": start}


def test_profile_table_and_delta_of_two_runs(tmp_path):
    old = read_profile(_fake_run(tmp_path / "a", {
        "site": (10.0, {"write": _sub(2.0, 8.0), "scan": _sub(6.0, 1.0)}),
        "texture": (20.0, {"bake": _sub(18.0, 1.0, 900.0)}),
        "gone": (1.0, {})}))
    new = read_profile(_fake_run(tmp_path / "b", {
        "site": (9.0, {"write": _sub(2.0, 7.0), "scan": _sub(5.0, 1.0)}),
        "texture": (8.0, {"bake": _sub(6.0, 1.0, 700.0)})}))
    assert old["total_s"] == 31.0 and new["total_s"] == 17.0
    rows = profile_rows(old)
    # substeps in the order they ran (start_s), then the rest of the step as (other)
    assert [(r["step"], r["substep"]) for r in rows] == [
        ("site", ""), ("site", "scan"), ("site", "write"), ("site", OTHER),
        ("texture", ""), ("texture", "bake"), ("texture", OTHER), ("gone", "")]
    other = next(r for r in rows if r["step"] == "site" and r["substep"] == OTHER)
    assert other["seconds"] == 2.0 and abs(other["share"] - 2.0 / 31.0) < 1e-9
    table = profile_table(old)
    assert table.splitlines()[-1].split()[:2] == ["total", "31.0"]
    bake = next(x for x in table.splitlines() if x.split()[:1] == ["bake"])
    assert bake.split()[1:] == ["18.0", "900", "58.1%"]
    delta = profile_delta(old, new).splitlines()
    bake = next(x for x in delta if x.split()[:1] == ["bake"])
    assert bake.split()[1:5] == ["18.0", "6.0", "-12.0", "-67%"] and bake.split()[-3:] == ["900", "->", "700"]
    assert next(x for x in delta if x.split()[:1] == ["gone"]).split()[1:4] == ["1.0", "-", "-"]
    assert delta[-1].split()[:4] == ["total", "31.0", "17.0", "-14.0"]
    # a delta that hides small changes keeps the big ones
    small = profile_delta(old, new, min_s=1.5)
    assert "bake" in small and "write" not in small


def test_fanout_items_are_added_up(tmp_path):
    d = tmp_path / "01_tiles"
    d.mkdir()
    items = [{"substeps": {"mesh": _sub(2.0, 0.5, 300.0)}}, {"substeps": {"mesh": _sub(3.0, 0.2, 500.0)}}]
    d.joinpath("step.json").write_text(json.dumps({"step": "tiles", "status": "ran", "duration_s": 6.0,
                                                   "metrics": {"per_item": items}}))
    rows = profile_rows(read_profile(tmp_path))
    mesh = next(r for r in rows if r["substep"] == "mesh")
    assert (mesh["seconds"], mesh["peak_rss_mb"], mesh["calls"]) == (5.0, 500.0, 2)

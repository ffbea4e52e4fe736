"""The step engine's rules, each exercised through the real ``twinkit`` command."""
from __future__ import annotations

import json
import os
import re
import signal
import sqlite3
import time
from pathlib import Path


def test_first_run_then_everything_reused(project):
    r = project.run("site=t", "recipe=chain")
    assert r.rc == 0, r.text
    assert (project.ws / "03_scale" / "scaled.txt").read_text() == "6\n"
    assert [project.status_of(r, f) for f in ("01_make", "02_double", "03_scale")] == ["ran"] * 3
    project.reset_counts()
    r2 = project.run("site=t", "recipe=chain")
    assert r2.rc == 0, r2.text
    assert [project.status_of(r2, f) for f in ("01_make", "02_double", "03_scale")] == ["reused"] * 3
    assert project.counts() == {}


def test_parameter_change_reruns_only_what_depends_on_it(project):
    assert project.run("site=t", "recipe=chain").rc == 0
    project.reset_counts()
    r = project.run("site=t", "recipe=chain", "steps.scale.factor=5")
    assert r.rc == 0, r.text
    assert project.counts() == {"scale": 1}
    assert "factor 3 -> 5" in r.text
    assert (project.ws / "03_scale" / "scaled.txt").read_text() == "10\n"
    # going back finds the earlier result by key, without computing
    project.reset_counts()
    r = project.run("site=t", "recipe=chain")
    assert project.status_of(r, "03_scale") == "cached"
    assert project.counts() == {}
    assert (project.ws / "03_scale" / "scaled.txt").read_text() == "6\n"


def test_input_content_change_and_touch(project):
    seed = project.tmp / "seed.txt"
    seed.write_text("4\n")
    project.site("s", f"name: t\ninputs:\n  seed: {seed}\n")
    project.recipe("fromseed", ["{id: read, uses: step/read_seed}", "{id: double, uses: step/double}"])
    assert project.run("site=s", "recipe=fromseed").rc == 0
    assert (project.ws / "02_double" / "double.txt").read_text() == "8\n"
    # touching without changing re-runs nothing
    project.reset_counts()
    future = time.time() + 100
    os.utime(seed, (future, future))
    r = project.run("site=s", "recipe=fromseed")
    assert r.rc == 0 and project.counts() == {}, r.text
    # changing the content re-runs both
    seed.write_text("5\n")
    r = project.run("site=s", "recipe=fromseed")
    assert project.counts() == {"read_seed": 1, "double": 1}, r.text
    assert "input changed: in_seed_txt" in r.text
    assert (project.ws / "02_double" / "double.txt").read_text() == "10\n"


def test_hand_edit_is_kept_and_downstream_reruns(project):
    assert project.run("site=t", "recipe=chain").rc == 0
    edited = project.ws / "02_double" / "double.txt"
    edited.unlink()  # like an editor that saves a new file
    edited.write_text("100\n")
    project.reset_counts()
    r = project.run("site=t", "recipe=chain")
    assert r.rc == 0, r.text
    assert project.status_of(r, "02_double") == "edited"
    assert "kept hand-edited double.txt" in r.text
    assert project.counts() == {"scale": 1}
    assert edited.read_text() == "100\n"
    assert (project.ws / "03_scale" / "scaled.txt").read_text() == "300\n"
    # the next run keeps the edit and reuses what depends on it
    project.reset_counts()
    r = project.run("site=t", "recipe=chain")
    assert project.status_of(r, "02_double") == "edited" and project.counts() == {}
    # forcing the step discards the edit, but sets it aside first
    r = project.run("site=t", "recipe=chain", "rerun=[double]")
    assert r.rc == 0, r.text
    assert edited.read_text() == "2\n"
    kept = list((project.ws / ".cache" / "edits").glob("02_double-*/double.txt"))
    assert kept and kept[0].read_text() == "100\n"
    # scale's first result (for the computed input) is still stored by key: found, not recomputed
    assert project.counts() == {"double": 1}
    assert project.status_of(r, "03_scale") == "cached"


def test_in_place_edit_of_hardlinked_output_does_not_poison_the_cache(project):
    assert project.run("site=t", "recipe=chain").rc == 0
    with open(project.ws / "01_make" / "data.txt", "w") as f:  # in place: same inode as the stored copy
        f.write("7\n")
    r = project.run("site=t", "recipe=chain")
    assert project.status_of(r, "01_make") == "edited"
    assert (project.ws / "03_scale" / "scaled.txt").read_text() == "42\n"
    r = project.run("site=t", "recipe=chain", "rerun=[make]")
    assert r.rc == 0, r.text
    assert (project.ws / "01_make" / "data.txt").read_text() == "1\n"
    assert (project.ws / "03_scale" / "scaled.txt").read_text() == "6\n"


def test_killed_step_is_not_taken_as_done(project):
    p = project.popen("site=t", "recipe=chain", env=project.env(TWINKIT_TEST_SLEEP="60"))
    store_tmp = project.ws / ".cache" / "steps" / ".tmp"
    deadline = time.time() + 60
    while not list(store_tmp.glob("*/started")) and time.time() < deadline:
        time.sleep(0.1)
    assert list(store_tmp.glob("*/started")), "step never started"
    os.killpg(p.pid, signal.SIGKILL)
    p.wait()
    assert not (project.ws / "01_make").exists()
    assert not [d for d in (project.ws / ".cache" / "steps").iterdir() if d.is_dir() and d.name != ".tmp"]
    project.reset_counts()
    r = project.run("site=t", "recipe=chain")
    assert r.rc == 0, r.text
    assert project.status_of(r, "01_make") == "ran" and project.counts()["make"] == 1
    assert not list(store_tmp.iterdir()), "leftovers of the killed run were not cleaned"


def test_failing_step_keeps_earlier_results(project):
    assert project.run("site=t", "recipe=chain").rc == 0
    before = (project.ws / "01_make" / "data.txt").read_text()
    r = project.run("site=t", "recipe=chain", "steps.make.fail=true")
    assert r.rc == 1
    assert "step 'make' (step/make" in r.err and "boom on purpose" in r.err
    assert "Traceback" not in r.err
    assert (project.ws / "01_make" / "data.txt").read_text() == before
    assert (project.ws / "03_scale" / "scaled.txt").exists()
    runs = sorted((project.ws / "runs").iterdir())
    assert "boom on purpose" in (runs[-1] / "run.log").read_text()
    assert json.loads((runs[-1] / "manifest.json").read_text())["status"] == "failed"


def test_manual_step_exits_then_resumes(project):
    project.recipe("withmanual", ["{id: make, uses: step/make}",
                                  "{id: pick, manual: {instructions: 'Write a number into {path}', outputs: [picked.txt]}}",
                                  "{id: double, uses: step/double}"])
    r = project.run("site=t", "recipe=withmanual")
    assert r.rc == 3, r.text
    assert "waits for" in r.err and "picked.txt" in r.err
    assert (project.ws / "02_pick" / "INSTRUCTIONS.txt").exists()
    assert not (project.ws / "03_double").exists()
    (project.ws / "02_pick" / "picked.txt").write_text("9\n")
    r = project.run("site=t", "recipe=withmanual")
    assert r.rc == 0, r.text
    assert project.status_of(r, "02_pick") == "manual"
    assert project.status_of(r, "01_make") == "reused"


def test_manual_step_waits_when_interactive(project):
    project.recipe("withmanual", ["{id: make, uses: step/make}",
                                  "{id: pick, manual: {instructions: 'Put it at {path}', outputs: [picked.txt]}}"])
    p = project.popen("site=t", "recipe=withmanual", "engine.interactive=true", "engine.manual_timeout_s=60")
    target = project.ws / "02_pick" / "picked.txt"
    deadline = time.time() + 60
    while not (project.ws / "02_pick" / "INSTRUCTIONS.txt").exists() and time.time() < deadline:
        time.sleep(0.1)
    assert p.poll() is None, "the run should be waiting"
    target.write_text("1\n")
    out, err = p.communicate(timeout=60)
    assert p.returncode == 0, err
    assert "manual" in err


def test_fan_out_runs_items_in_parallel_and_caches_each(project):
    project.recipe("fan", ["{id: make, uses: step/make}", "{id: tiles, uses: step/tiles}",
                           "{id: per_tile, uses: step/per_tile, foreach: tiles.json}",
                           "{id: gather, uses: step/gather}"])
    # each item takes 1 s, so that one worker cannot finish them all before the second has started (spawned
    # workers start in 0.5-2 s on a busy 2-core machine)
    r = project.run("site=t", "recipe=fan", "steps.tiles.n=4", "executor.workers=2",
                    env=project.env(TWINKIT_TEST_TILE_SLEEP="1"))
    assert r.rc == 0, r.text
    assert (project.ws / "04_gather" / "merged.txt").read_text() == f"{4 * 1 + 0 + 1 + 2 + 3}\n"
    # without a terminal to draw a bar on, the log says how far the items are
    assert "03_per_tile: 1 of 4 items done" in r.err and "03_per_tile: 4 of 4 items done" in r.err, r.err
    pids = {(project.ws / "03_per_tile" / f"{i:03d}" / "tile.txt").read_text().split()[1] for i in range(4)}
    assert len(pids) == 2, "items should run in two worker processes"
    per_item = json.loads((project.ws / "03_per_tile" / "step.json").read_text())["metrics"]["per_item"]
    assert len(per_item) == 4
    for m in per_item:  # each item reports its worker's memory: before the item and at its peak
        assert 0 < m["start_rss_mb"] <= m["peak_rss_mb"] and m["duration_s"] >= 0
        # two workers share the cores: each worker's OpenMP/BLAS pools are capped at cores / 2
        assert m["omp_threads"] == str(max(1, (os.cpu_count() or 1) // 2))
    project.reset_counts()
    r = project.run("site=t", "recipe=fan", "steps.tiles.n=5", "executor.workers=2")
    assert r.rc == 0, r.text
    assert project.counts() == {"tiles": 1, "per_tile4": 1, "gather": 1}
    r = project.run("site=t", "recipe=fan", "steps.tiles.n=7", "executor.workers=2", "executor.threads_per_worker=3")
    assert r.rc == 0, r.text
    per_item = json.loads((project.ws / "03_per_tile" / "step.json").read_text())["metrics"]["per_item"]
    assert [m["omp_threads"] for m in per_item[5:]] == ["3", "3"]
    # a fresh worker process per item: no item inherits another's memory
    r = project.run("site=t", "recipe=fan", "steps.tiles.n=9", "executor.workers=2", "executor.max_items_per_worker=1",
                    "rerun=[per_tile]")
    assert r.rc == 0, r.text
    pids = {(project.ws / "03_per_tile" / f"{i:03d}" / "tile.txt").read_text().split()[1] for i in range(9)}
    assert len(pids) == 9, pids
    # ... with one worker too (not this process): each item's peak memory is its own
    r = project.run("site=t", "recipe=fan", "steps.tiles.n=3", "executor.workers=1", "executor.max_items_per_worker=1",
                    "rerun=[per_tile]")
    assert r.rc == 0, r.text
    pids = {(project.ws / "03_per_tile" / f"{i:03d}" / "tile.txt").read_text().split()[1] for i in range(3)}
    assert len(pids) == 3, pids
    # items that carry a "cost" start costliest first (here in one process, so strictly in that order)
    r = project.run("site=t", "recipe=fan", "steps.tiles.n=5", "steps.tiles.costs=true", "executor.workers=1")
    assert r.rc == 0, r.text
    started = [m["started"] for m in json.loads((project.ws / "03_per_tile" / "step.json").read_text())["metrics"]["per_item"]]
    assert started == sorted(started, reverse=True), started


def test_multirun_computes_shared_upstream_once(project):
    r = project.run("-m", "site=t", "recipe=chain", "steps.scale.factor=2,3,4", "steps.make.sleep_s=1")
    assert r.rc == 0, r.text
    c = project.counts()
    assert c == {"make": 1, "double": 1, "scale": 3}, c
    jobs = sorted((project.ws / "sweeps").glob("*/job*"))
    assert len(jobs) == 3
    values = sorted(int((j / "03_scale" / "scaled.txt").read_text()) for j in jobs)
    assert values == [4, 6, 8]
    for j in jobs:
        assert json.loads((j / "manifest.json").read_text())["status"] == "ok"


def test_two_runs_on_one_site_are_refused(project):
    p = project.popen("site=t", "recipe=chain", env=project.env(TWINKIT_TEST_SLEEP="30"))
    try:
        deadline = time.time() + 60
        while not list((project.ws / ".cache" / "steps" / ".tmp").glob("*/started")) and time.time() < deadline:
            time.sleep(0.1)
        r = project.run("site=t", "recipe=chain")
        assert r.rc == 2
        assert "another twinkit run is using" in r.err and str(project.ws) in r.err
    finally:
        os.killpg(p.pid, signal.SIGKILL)
        p.wait()


def test_status_shows_decisions_without_running(project):
    assert project.run("site=t", "recipe=chain").rc == 0
    project.reset_counts()
    r = project.run("status", "site=t", "recipe=chain", "steps.scale.factor=7")
    assert r.rc == 0, r.text
    lines = {l.split()[0]: l for l in r.out.splitlines() if l.startswith("  ")}
    assert "up to date" in lines["01_make"] and "up to date" in lines["02_double"]
    assert "would run" in lines["03_scale"] and "factor 3 -> 7" in lines["03_scale"]
    assert project.counts() == {}
    assert (project.ws / "03_scale" / "scaled.txt").read_text() == "6\n"


def test_manifest_records_and_verifies(project):
    project.run("site=t", "recipe=chain")
    run_dir = sorted((project.ws / "runs").iterdir())[-1]
    m = json.loads((run_dir / "manifest.json").read_text())
    assert m["schema_version"] == 1 and m["status"] == "ok"
    assert [s["status"] for s in m["steps"]] == ["ran", "ran", "ran"]
    assert all(len(s["key"]) == 32 for s in m["steps"])
    assert m["config"]["recipe"]["name"] == "chain"
    assert "numpy" in m["libraries"] and m["python"]["version"]
    assert any(p["name"] == "make" for p in m["plugins"])
    assert "git" in m and "commit" in m["git"]
    outs = {Path(o["path"]).name: o for o in m["outputs"]}
    assert outs["scaled.txt"]["size"] == 2
    raw = (run_dir / "manifest.json").read_text()
    assert raw == json.dumps(m, indent=2, sort_keys=True) + "\n", "manifest keys must be sorted"
    ok = project.run("verify", str(run_dir))
    assert ok.rc == 0, ok.text
    (project.ws / "03_scale" / "scaled.txt").unlink()
    (project.ws / "03_scale" / "scaled.txt").write_text("99\n")
    bad = project.run("verify", str(run_dir / "manifest.json"))
    assert bad.rc == 1 and "scaled.txt" in bad.out


def test_step_records_beside_outputs(project):
    assert project.run("site=t", "recipe=chain", "steps.scale.factor=4").rc == 0
    rec = json.loads((project.ws / "03_scale" / "step.json").read_text())
    assert rec["plugin"] == "step/scale" and rec["params"] == {"factor": 4, "degrade_below": 0}
    assert rec["status"] == "ran" and rec["files"]["scaled.txt"]["size"] == 2
    assert rec["duration_s"] is not None


def test_ctrl_c_leaves_no_partial_result_and_says_so(project):
    p = project.popen("site=t", "recipe=chain", env=project.env(TWINKIT_TEST_SLEEP="60"))
    store_tmp = project.ws / ".cache" / "steps" / ".tmp"
    deadline = time.time() + 60
    while not list(store_tmp.glob("*/started")) and time.time() < deadline:
        time.sleep(0.1)
    os.kill(p.pid, signal.SIGINT)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 130, err
    assert "interrupted" in err
    assert not (project.ws / "01_make").exists()
    assert not list(store_tmp.iterdir()), "the interrupted step's temporary folder must be removed"
    manifest = json.loads(sorted((project.ws / "runs").glob("*/manifest.json"))[-1].read_text())
    assert manifest["status"] == "interrupted"


def test_gc_removes_only_unreferenced_results(project):
    project.recipe("fan", ["{id: make, uses: step/make}", "{id: tiles, uses: step/tiles}",
                           "{id: per_tile, uses: step/per_tile, foreach: tiles.json}", "{id: gather, uses: step/gather}"])
    assert project.run("site=t", "recipe=fan", "steps.make.value=2").rc == 0
    assert project.run("site=t", "recipe=fan").rc == 0  # value 1: make, per_tile x3, gather change; tiles too
    store = project.ws / ".cache" / "steps"
    before = {d.name for d in store.iterdir() if d.is_dir() and d.name != ".tmp"}
    dry = project.run("gc", "--dry-run", "site=t", "recipe=fan")
    assert dry.rc == 0 and "would remove" in dry.out
    assert {d.name for d in store.iterdir() if d.is_dir() and d.name != ".tmp"} == before
    db = project.ws / ".cache" / "hashes.sqlite"
    rows_before = sqlite3.connect(db).execute("SELECT count(*) FROM hashes").fetchone()[0]
    r = project.run("gc", "site=t", "recipe=fan")
    assert r.rc == 0, r.text
    after = {d.name for d in store.iterdir() if d.is_dir() and d.name != ".tmp"}
    assert len(after) == 1 + 1 + 3 + 1 and after < before
    # the hashes of the removed results are forgotten; those of files still there are kept
    rows_after = sqlite3.connect(db).execute("SELECT count(*) FROM hashes").fetchone()[0]
    m = re.search(r"forgot (\d+) remembered", r.out)
    assert m and int(m.group(1)) > 0 and rows_after == rows_before - int(m.group(1)), r.out
    project.reset_counts()
    r = project.run("site=t", "recipe=fan")
    assert r.rc == 0 and project.counts() == {}, "gc removed a result still in use"


def test_optional_step_is_skipped_when_its_input_is_missing(project):
    seed = project.tmp / "seed.txt"
    seed.write_text("4\n")
    project.recipe("opt", ["{id: make, uses: step/make}",
                           "{id: read, uses: step/read_seed, optional: true}",
                           "{id: double, uses: step/double}"])
    r = project.run("site=t", "recipe=opt")
    assert r.rc == 0, r.text
    assert "read" in r.text and "skipped" in r.text and "no seed (in_seed_txt)" in r.text
    assert (project.ws / "02_double" / "double.txt").read_text() == "2\n"
    (project.conf / "site" / "s.yaml").write_text(f"name: t\ninputs:\n  seed: {seed}\n")
    r = project.run("site=s", "recipe=opt")
    assert r.rc == 0, r.text
    assert (project.ws / "03_double" / "double.txt").read_text() == "8\n"


def test_kind_none_leaves_out_its_step_and_the_optional_steps_that_depend_on_it(project):
    """road_source=none: the road steps are left out with a logged reason, the later steps take what exists;
    a site input left for the user ('???') that only the left-out steps read does not stop the run (issue 28)."""
    project.site("r", "name: t\ninputs:\n  osm: ???\n")
    project.recipe("twin", ["{id: make, uses: step/make}",
                            "{id: fetch, uses: road_source}",
                            "{id: convert, uses: step/convert_roads, optional: true}",
                            "{id: align, uses: step/align_net, optional: true}",
                            "{id: double, uses: step/double}",
                            "{id: export, uses: step/export_all}"], extra="defaults:\n  - /road_source: toy\n  - _self_\n")
    # the default: roads from the toy source; every step runs (the site's osm is not read: fetch writes it)
    r = project.run("site=t", "recipe=twin")
    assert r.rc == 0, r.text
    assert (project.ws / "06_export" / "export.txt").read_text() == "roads\n"
    assert project.counts() == {"make": 1, "toy_roads": 1, "convert_roads": 1, "align_net": 1, "double": 1,
                                "export_all": 1}
    project.reset_counts()
    r = project.run("site=r", "recipe=twin", "road_source=none")
    assert r.rc == 0, r.text
    assert "road_source=none was chosen" in r.text
    assert re.search(r"convert\s+skipped\s+.*road_source=none", r.text), r.text
    assert re.search(r"convert\s+skipped\s+optional step: no osm \(in_osm_txt\)", r.text), r.text  # the empty input named
    assert re.search(r"align\s+skipped\s+optional step: its input in_net_txt comes from convert, which was left out", r.text), r.text
    assert (project.ws / "03_export" / "export.txt").read_text() == "no roads\n"
    assert set(project.counts()) == {"export_all"}  # make and double reused; no road step ran
    # without a '<kind>=none' choice, an optional step whose site input is left empty ('???') still fails
    # the plan, naming the key (behaviour kept)
    project.recipe("conv", ["{id: make, uses: step/make}", "{id: convert, uses: step/convert_roads, optional: true}"])
    r = project.run("site=r", "recipe=conv")
    assert r.rc != 0 and "site.inputs.osm" in r.text, r.text


def test_default_road_source_falls_back_when_it_cannot_serve_the_site(project):
    """A recipe's default plugin that cannot serve the site (no OSM file, or one that does not cover it) is
    replaced by its registered fallback (road_source=file -> scan), logged; a plugin typed on the command
    line is never replaced (issue 28: roads from the scan when no OSM is given or it does not cover the site)."""
    osm = project.tmp / "area.txt"
    osm.write_text("osm roads\n")
    project.site("given", f"name: t\ninputs:\n  osm: {osm}\n")
    project.site("far", f"name: t\nosm_far: true\ninputs:\n  osm: {osm}\n")
    project.site("empty", "name: t\ninputs:\n  osm: ???\n")
    project.recipe("twin", ["{id: make, uses: step/make}",
                            "{id: fetch, uses: road_source}",
                            "{id: convert, uses: step/convert_roads, optional: true}",
                            "{id: export, uses: step/export_all, inputs: {in_double_txt: net.txt}}"],
                   extra="defaults:\n  - /road_source: toy_file\n  - _self_\n")
    r = project.run("site=given", "recipe=twin")
    assert r.rc == 0, r.text
    assert project.counts().get("toy_file_roads") == 1 and "toy_scan_roads" not in project.counts()
    assert (project.ws / "03_convert" / "net.txt").read_text() == "osm roads\n"
    assert "fallback" not in r.text
    for site, why in (("empty", "needs input 'osm'"), ("far", "does not cover the site")):
        project.reset_counts()
        r = project.run(f"site={site}", "recipe=twin")
        assert r.rc == 0, r.text
        assert "toy_file_roads" not in project.counts(), r.text  # (the scan roads: computed once, then reused)
        assert re.search(r"fetch\s+fallback road_source=toy_scan instead of road_source=toy_file", r.text), r.text
        assert why in r.text, r.text
        assert (project.ws / "03_convert" / "net.txt").read_text().startswith("scan "), site
    # chosen on the command line: the file source is kept, and its problem stops the run
    r = project.run("site=far", "recipe=twin", "road_source=toy_file")
    assert r.rc == 2 and "does not cover the site" in r.text, r.text
    assert "fallback" not in r.text
    # the scan source typed on the command line on a site whose OSM is left empty: the later step's optional
    # OSM input is not given (it has the scan's file), instead of "needs input 'osm'" stopping the run
    r = project.run("site=empty", "recipe=twin", "road_source=toy_scan")
    assert r.rc == 0, r.text
    assert (project.ws / "03_convert" / "net.txt").read_text().startswith("scan "), r.text


def test_preflight_refuses_before_the_first_step_runs(project):
    """Cheap checks of every planned step run before any step: a missing site input of the last step and a
    plugin's own check are both reported, one line each, with exit 2, and nothing runs (issue 28)."""
    project.site("p", f"name: t\nroads_offline: true\ninputs:\n  seed: {project.tmp / 'missing_seed.txt'}\n")
    project.recipe("late", ["{id: make, uses: step/make}", "{id: fetch, uses: road_source}",
                            "{id: double, uses: step/double}", "{id: read, uses: step/read_seed}"],
                   extra="defaults:\n  - /road_source: toy\n  - _self_\n")
    r = project.run("site=p", "recipe=late")
    assert r.rc == 2, r.text
    assert "preflight found 2 problems before the first step ran" in r.err, r.err
    assert "missing_seed.txt does not exist (needed by step 'read')" in r.err
    assert "step 'fetch' (road_source/toy): the toy road server is offline" in r.err
    assert project.counts() == {} and not (project.ws / "01_make").exists()
    # the same with the problems gone runs every step
    seed = project.tmp / "missing_seed.txt"
    seed.write_text("5\n")
    r = project.run("site=p", "recipe=late", "site.roads_offline=false")
    assert r.rc == 0, r.text
    assert project.counts() == {"make": 1, "toy_roads": 1, "double": 1, "read_seed": 1}


def _open_and_hash(args):
    """One process of a sweep: a hash cache on the shared database, released at one instant."""
    from twinkit.hashing import HashCache
    db, path, start = args
    while time.time() < start:
        pass
    cache = HashCache(Path(db))
    try:
        cache.hash(Path(path))
        cache.remember(Path(path), "0" * 64)
        return "ok"
    except sqlite3.OperationalError as exc:
        return str(exc)
    finally:
        cache.close()


def test_parallel_jobs_opening_a_new_hash_cache_together_wait_for_each_other(tmp_path):
    """A sweep's jobs open a new site's hash database at the same moment; SQLite refuses the second
    switch to WAL at once ('database is locked', no busy wait): each job must wait, not fail."""
    import multiprocessing as mp
    src = tmp_path / "input.txt"
    src.write_text("street")
    ctx = mp.get_context("fork")
    with ctx.Pool(4) as pool:
        for trial in range(12):
            db = tmp_path / f"site{trial}" / ".cache" / "hashes.sqlite"
            start = time.time() + 0.2
            answers = pool.map(_open_and_hash, [(str(db), str(src), start)] * 4)
            assert answers == ["ok"] * 4, (trial, answers)
            rows = sqlite3.connect(db).execute("SELECT count(*) FROM hashes").fetchone()[0]
            assert rows == 1


def test_a_recipe_step_renames_its_outputs(project):
    """``outputs: {out_double_txt: twice.txt}`` makes the step write twice.txt, which later steps read by that
    name (export_demo's labels.npy from the segmentation's transfer_gt_labels); a changed extension fails the plan."""
    project.recipe("renamed", ["{id: make, uses: step/make}",
                               "{id: double, uses: step/double, outputs: {out_double_txt: twice.txt}}",
                               "{id: scale, uses: step/scale, inputs: {in_double_txt: twice.txt}}"])
    r = project.run("site=t", "recipe=renamed")
    assert r.rc == 0, r.text
    assert (project.ws / "02_double" / "twice.txt").read_text() == "2\n"
    assert not (project.ws / "02_double" / "double.txt").exists()
    assert (project.ws / "03_scale" / "scaled.txt").read_text() == "6\n"
    project.recipe("bad", ["{id: make, uses: step/make}",
                           "{id: double, uses: step/double, outputs: {out_double_txt: twice.json}}"])
    r = project.run("site=t", "recipe=bad")
    assert r.rc != 0 and "keep its kind" in r.text, r.text


def test_a_recipe_asks_a_generated_site_for_what_it_reads(project):
    """``recipe.site_params`` reach the site generator (the point-cloud recipes ask the demo for no photos);
    keys it does not know are ignored, and a site field typed on the command line beats the recipe."""
    project.site("g", "name: t\ngenerator: toy_site\npoints: 5\nphotos: true\n")
    project.recipe("cloudonly", ["{id: double, uses: step/double}"])
    text = (project.conf / "recipe" / "cloudonly.yaml").read_text()
    (project.conf / "recipe" / "cloudonly.yaml").write_text(
        text.replace("  name: cloudonly\n", "  name: cloudonly\n  site_params: {photos: false, colour: red}\n"))
    r = project.run("site=g", "recipe=cloudonly")
    assert r.rc == 0, r.text
    assert (project.ws / "01_site" / "data.txt").read_text() == "5\n"  # the site's own field still counts
    assert (project.ws / "01_site" / "photos.txt").read_text() == ""  # the recipe's ask beats the site's default
    assert (project.ws / "02_double" / "double.txt").read_text() == "10\n"
    # the same recipe without the ask renders them; on the command line the user's word wins
    r = project.run("site=g", "recipe=cloudonly", "site.photos=true")
    assert r.rc == 0, r.text
    assert (project.ws / "01_site" / "photos.txt").read_text() == "photos\n"
    assert project.counts() == {"toy_site": 2, "double": 1}  # the cloud did not change: double is reused

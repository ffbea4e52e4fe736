"""No stale or silently changed result: the site fields a step reads are in its key, edits stay where they
were made, nothing a person wrote is deleted, and gc never runs beside a run (issue 27)."""
from __future__ import annotations

import json
import os
import time
from pathlib import Path


def _site_with_base(project, x: int) -> None:
    project.site("t", f"name: t\nbase_point: {{x: {x}, y: 0}}\n")


def test_base_point_change_reruns_the_steps_that_read_it_and_status_says_why(project):
    project.recipe("placed", ["{id: make, uses: step/make}", "{id: place, uses: step/place}",
                              "{id: double, uses: step/double}"])
    _site_with_base(project, 100)
    r = project.run("site=t", "recipe=placed")
    assert r.rc == 0, r.text
    assert (project.ws / "02_place" / "placed.txt").read_text() == "101\n"
    rec = json.loads((project.ws / "02_place" / "step.json").read_text())
    assert rec["descriptor"]["site"] == {"base_point": {"x": 100, "y": 0}, "tag": None}
    assert "site" not in json.loads((project.ws / "01_make" / "step.json").read_text())["descriptor"]
    project.reset_counts()
    assert [project.status_of(project.run("site=t", "recipe=placed"), f) for f in ("01_make", "02_place")] == \
        ["reused", "reused"]
    _site_with_base(project, 174)  # moved by 74 m
    st = project.run("status", "site=t", "recipe=placed")
    assert st.rc == 0, st.text
    line = next(ln for ln in st.out.splitlines() if "02_place" in ln)
    assert "would run" in line and "site.base_point" in line and "174" in line, st.out
    assert "up to date" in next(ln for ln in st.out.splitlines() if "01_make" in ln)
    r = project.run("site=t", "recipe=placed")
    assert r.rc == 0, r.text
    assert project.status_of(r, "01_make") == "reused"
    assert project.status_of(r, "02_place") == "ran"
    assert "site.base_point" in next(ln for ln in r.text.splitlines() if "02_place" in ln)
    assert (project.ws / "02_place" / "placed.txt").read_text() == "175\n"
    # back to the old base point: the stored result for it is linked, not recomputed
    _site_with_base(project, 100)
    project.reset_counts()
    r = project.run("site=t", "recipe=placed")
    assert project.status_of(r, "02_place") == "cached" and project.counts() == {}, r.text
    assert (project.ws / "02_place" / "placed.txt").read_text() == "101\n"


def test_fan_out_items_in_workers_are_keyed_by_the_site_fields_they_read(project):
    project.recipe("ptiles", ["{id: make, uses: step/make}", "{id: tiles, uses: step/tiles}",
                              "{id: place_tile, uses: step/place_tile, foreach: tiles.json}"])
    _site_with_base(project, 10)
    r = project.run("site=t", "recipe=ptiles", "executor.workers=2")
    assert r.rc == 0, r.text
    assert (project.ws / "03_place_tile" / "002" / "ptile.txt").read_text() == "12\n"
    _site_with_base(project, 20)
    project.reset_counts()
    r = project.run("site=t", "recipe=ptiles", "executor.workers=2")
    assert r.rc == 0, r.text
    assert project.status_of(r, "03_place_tile") == "ran"
    assert (project.ws / "03_place_tile" / "002" / "ptile.txt").read_text() == "22\n"
    assert sorted(project.counts()) == ["place_tile0", "place_tile1", "place_tile2"]


def _inodes(folder: Path) -> dict[str, int]:
    return {p.relative_to(folder).as_posix(): p.stat().st_ino for p in folder.rglob("*") if p.is_file()}


def test_no_editable_folder_shares_an_inode_with_the_store(project):
    assert project.run("site=t", "recipe=chain").rc == 0
    store = project.ws / ".cache" / "steps"
    stored = {p.stat().st_ino for p in store.rglob("*") if p.is_file()}
    for d in ("01_make", "02_double", "03_scale"):
        shared = {rel for rel, ino in _inodes(project.ws / d).items() if ino in stored}
        assert not shared, f"{d}: {shared} share an inode with the store"
        assert all(os.stat(p).st_nlink == 1 for p in (project.ws / d).rglob("*") if p.is_file())
    # stored files are read-only; the folder's copies are not
    f = next(p for p in store.glob("*/data.txt"))
    assert not os.stat(f).st_mode & 0o222
    assert os.stat(project.ws / "01_make" / "data.txt").st_mode & 0o200


def test_in_place_edit_in_one_folder_leaves_a_sweep_job_verify_green(project):
    r = project.run("-m", "site=t", "recipe=chain", "steps.scale.factor=3,4")
    assert r.rc == 0, r.text
    jobs = sorted(p.parent for p in (project.ws / "sweeps").glob("*/*/manifest.json"))
    assert len(jobs) == 2, jobs
    assert project.run("site=t", "recipe=chain").rc == 0
    with open(project.ws / "01_make" / "data.txt", "r+") as f:  # in place, same size
        f.write("9")
    for job in jobs:
        v = project.run("verify", str(job))
        assert v.rc == 0, v.text
    # and the edit is the site folder's own: kept, later steps re-run from it
    r = project.run("site=t", "recipe=chain")
    assert project.status_of(r, "01_make") == "edited"
    assert (project.ws / "03_scale" / "scaled.txt").read_text() == "54\n"


def test_edit_that_keeps_size_and_mtime_is_seen(project):
    assert project.run("site=t", "recipe=chain").rc == 0
    p = project.ws / "01_make" / "data.txt"
    st = p.stat()
    with open(p, "r+") as f:
        f.write("5")
    os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns))  # like `touch -r`
    assert p.stat().st_size == st.st_size and p.stat().st_mtime_ns == st.st_mtime_ns
    r = project.run("site=t", "recipe=chain")
    assert r.rc == 0, r.text
    assert project.status_of(r, "01_make") == "edited", r.text
    assert (project.ws / "03_scale" / "scaled.txt").read_text() == "30\n"


def test_damaged_store_entry_is_never_served(project):
    """An edit made inside .cache/steps/<key>/ (size and mtime kept) is not linked into a folder as the
    stored result: the entry is dropped and computed again."""
    assert project.run("site=t", "recipe=chain").rc == 0
    assert project.run("site=t", "recipe=chain", "steps.make.value=2").rc == 0
    store = project.ws / ".cache" / "steps"
    entry = next(d for d in store.iterdir() if d.is_dir() and (d / "data.txt").is_file()
                 and (d / "data.txt").read_text() == "1\n")
    p = entry / "data.txt"
    st = p.stat()
    os.chmod(p, 0o644)
    p.write_text("8\n")
    os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns))
    project.reset_counts()
    r = project.run("site=t", "recipe=chain")  # value 1 again: the stored result would be linked
    assert r.rc == 0, r.text
    assert (project.ws / "01_make" / "data.txt").read_text() == "1\n"
    assert (project.ws / "03_scale" / "scaled.txt").read_text() == "6\n"
    assert project.counts().get("make") == 1, "the damaged entry was served"
    runs = sorted((project.ws / "runs").iterdir())
    m = json.loads((runs[-1] / "manifest.json").read_text())
    assert project.run("verify", str(runs[-1])).rc == 0
    assert any(o["path"].endswith("01_make/data.txt") for o in m["outputs"])


def test_folder_without_readable_record_is_set_aside_not_deleted(project):
    assert project.run("site=t", "recipe=chain").rc == 0
    folder = project.ws / "02_double"
    (folder / "double.txt").write_text("my own numbers\n")
    (folder / "notes.md").write_text("keep me\n")
    (folder / "step.json").write_text("{ not json")
    r = project.run("site=t", "recipe=chain")
    assert r.rc == 0, r.text
    assert (folder / "double.txt").read_text() == "2\n"
    kept = sorted((project.ws / ".cache" / "edits").glob("02_double-*"))
    assert kept, r.text
    assert (kept[-1] / "notes.md").read_text() == "keep me\n"
    assert (kept[-1] / "double.txt").read_text() == "my own numbers\n"
    assert "set aside" in r.text


def test_unknown_file_in_a_rerun_folder_is_set_aside(project):
    assert project.run("site=t", "recipe=chain").rc == 0
    (project.ws / "03_scale" / "mine.txt").write_text("a note\n")
    r = project.run("site=t", "recipe=chain", "steps.scale.factor=5")
    assert r.rc == 0, r.text
    assert not (project.ws / "03_scale" / "mine.txt").exists()
    kept = sorted((project.ws / ".cache" / "edits").glob("03_scale-*"))
    assert kept and (kept[-1] / "mine.txt").read_text() == "a note\n", r.text


def test_gc_refuses_while_a_sweep_job_runs_and_removes_nothing_it_needs(project):
    assert project.run("site=t", "recipe=chain", "steps.make.value=7").rc == 0  # garbage once value changes
    proc = project.popen("-m", "site=t", "recipe=chain", "steps.make.sleep_s=6", "steps.scale.factor=3,4")
    try:
        store = project.ws / ".cache" / "steps"
        deadline = time.time() + 60
        while time.time() < deadline and not list((store / ".tmp").glob("*")):
            time.sleep(0.2)
        assert list((store / ".tmp").glob("*")), "the sweep did not start"
        before = {d.name for d in store.iterdir() if d.is_dir()}
        g = project.run("gc", "site=t", "recipe=chain")
        assert g.rc == 2, g.text
        assert "sweep job" in g.text and "store.lock" in g.text
        assert {d.name for d in store.iterdir() if d.is_dir()} >= before
    finally:
        out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err[-2000:]
    g = project.run("gc", "site=t", "recipe=chain")
    assert g.rc == 0, g.text
    jobs = sorted(p.parent for p in (project.ws / "sweeps").glob("*/*/manifest.json"))
    assert jobs and all(project.run("verify", str(j)).rc == 0 for j in jobs)


def test_gc_keeps_results_of_folders_numbered_100_and_up(project):
    steps = [f"{{id: m{i:03d}, uses: step/make, params: {{value: {i}}}}}" for i in range(101)]
    project.recipe("long", steps)
    assert project.run("site=t", "recipe=long", timeout=300).rc == 0
    assert (project.ws / "101_m100" / "data.txt").read_text() == "100\n"
    g = project.run("gc", "site=t", "recipe=long")
    assert g.rc == 0 and "removed 0 stored" in g.out, g.out
    project.reset_counts()
    r = project.run("site=t", "recipe=long", "rerun=[m100]")
    assert r.rc == 0 and project.counts() == {"make": 1}


def test_status_writes_nothing(project):
    st = project.run("status", "site=t", "recipe=chain")
    assert st.rc == 0, st.text
    assert not (project.ws / ".cache").exists()
    assert project.run("site=t", "recipe=chain").rc == 0
    (project.ws / "01_make" / "data.txt").write_text("3\n")  # a new file: status hashes it
    cache = project.ws / ".cache"
    before = {p.name: (p.stat().st_size, p.stat().st_mtime_ns) for p in cache.iterdir() if p.is_file()}
    st = project.run("status", "site=t", "recipe=chain")
    assert st.rc == 0 and "edited" in st.out, st.text
    after = {p.name: (p.stat().st_size, p.stat().st_mtime_ns) for p in cache.iterdir() if p.is_file()}
    assert after == before


def test_two_recipes_on_one_site_keep_their_folders_apart(project):
    project.recipe("other", ["{id: make, uses: step/make, params: {value: 5}}", "{id: place, uses: step/place}"])
    assert project.run("site=t", "recipe=chain").rc == 0
    (project.ws / "03_scale" / "scaled.txt").write_text("60\n")  # a hand edit in the first recipe's folder
    r = project.run("site=t", "recipe=other")
    assert r.rc == 0, r.text
    top = sorted(d.name for d in project.ws.iterdir() if d.is_dir() and d.name[:2].isdigit())
    assert top == ["01_make", "02_place"], top
    parked = project.ws / "recipes" / "chain"
    assert sorted(d.name for d in parked.iterdir()) == ["01_make", "02_double", "03_scale"]
    assert (parked / "03_scale" / "scaled.txt").read_text() == "60\n"
    assert json.loads((project.ws / "01_make" / "step.json").read_text())["recipe"] == "other"
    st = project.run("status", "site=t", "recipe=chain")  # status looks at the parked folders
    assert "03_scale" in st.out and "edited" in next(ln for ln in st.out.splitlines() if "03_scale" in ln), st.out
    first = sorted((project.ws / "runs").iterdir())[0]
    v = project.run("verify", str(first))  # the first run's files are found where they were parked
    assert v.rc == 1 and [ln for ln in v.out.splitlines() if "changed" in ln and "manifest" not in ln] == \
        [ln for ln in v.out.splitlines() if "recipes/chain/03_scale/scaled.txt" in ln], v.out
    project.reset_counts()
    r = project.run("site=t", "recipe=chain")
    assert r.rc == 0, r.text
    assert project.status_of(r, "01_make") == "reused" and project.status_of(r, "03_scale") == "edited"
    assert (project.ws / "03_scale" / "scaled.txt").read_text() == "60\n"
    assert sorted(d.name for d in (project.ws / "recipes" / "other").iterdir()) == ["01_make", "02_place"]
    assert project.counts() == {}


def test_secret_read_by_a_step_stays_out_of_its_step_record(project):
    secret = "98765"
    project.recipe("placed", ["{id: make, uses: step/make}", "{id: place, uses: step/place}"])
    project.site("t", "name: t\nbase_point: {x: 7, y: 0}\ntag: ${oc.env:TWINKIT_TEST_SECRET_X}\n")
    env = project.env(TWINKIT_TEST_SECRET_X=secret)
    r = project.run("site=t", "recipe=placed", env=env)
    assert r.rc == 0, r.text
    assert (project.ws / "02_place" / "tag.txt").is_file()  # the step read it
    for rec in project.ws.glob("[0-9][0-9]_*/step.json"):
        assert secret not in rec.read_text(), rec
    r = project.run("site=t", "recipe=placed", env=env)
    assert project.status_of(r, "02_place") == "reused", r.text
    r = project.run("site=t", "recipe=placed", env=project.env(TWINKIT_TEST_SECRET_X="12345"))
    assert project.status_of(r, "02_place") == "ran" and secret not in r.text, r.text

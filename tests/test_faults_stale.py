"""Issue 46, item 8: no stale artefact in sight. Folders of steps the current plan does not have move out of the
top of the site's folder (to ``stale/<recipe>/``) and come back, reused and with their hand edits, when the plan
has them again (docs/engine.md, "Where things go" and "Faults")."""
from __future__ import annotations

import json

FULL = ["{id: make, uses: step/make}", "{id: double, uses: step/double}", "{id: scale, uses: step/scale}"]


def _top(project) -> list[str]:
    return sorted(d.name for d in project.ws.iterdir() if d.is_dir() and d.name[:2].isdigit())


def _report_steps(project) -> list[str]:
    """The steps of the newest run's manifest, after checking its report names no other numbered folder."""
    run = sorted(project.ws.glob("runs/*/manifest.json"))[-1].parent
    steps = [s["folder"] for s in json.loads((run / "manifest.json").read_text())["steps"]]
    html = (run / "report" / "report.html").read_text()
    assert not [f for f in ("01_make", "02_double", "03_scale", "02_place") if f in html and f not in steps]
    return steps


def test_a_step_dropped_from_the_plan_moves_out_and_comes_back_reused(project):
    assert project.run("site=t", "recipe=chain").rc == 0
    project.recipe("chain", FULL[:2])  # the recipe's step list changed: scale is gone
    r = project.run("site=t", "recipe=chain")
    assert r.rc == 0, r.text
    assert _top(project) == ["01_make", "02_double"], r.text
    kept = project.ws / "stale" / "chain" / "03_scale"
    assert (kept / "scaled.txt").read_text() == "6\n" and "03_scale" in r.text and "stale" in r.text, r.text
    assert _report_steps(project) == ["01_make", "02_double"]
    st = project.run("status", "site=t", "recipe=chain")
    assert st.rc == 0 and "03_scale" not in st.out, st.text
    assert "1 folder(s) of steps not in this plan are kept in" in st.out, st.text
    first = sorted(project.ws.glob("runs/*/manifest.json"))[0]
    v = project.run("verify", str(first))  # the older run's files are found where they were moved
    assert v.rc == 0, v.text
    project.recipe("chain", FULL)  # back in the plan: the folder comes back as it was, nothing computed
    project.reset_counts()
    r = project.run("site=t", "recipe=chain")
    assert r.rc == 0, r.text
    assert _top(project) == ["01_make", "02_double", "03_scale"] and not (project.ws / "stale").exists(), r.text
    assert project.status_of(r, "03_scale") == "reused" and project.counts() == {}, r.text


def test_a_renumbered_plan_leaves_only_its_own_folders_at_the_top(project):
    assert project.run("site=t", "recipe=chain").rc == 0
    project.recipe("chain", [FULL[0], "{id: place, uses: step/place}", *FULL[1:]])
    r = project.run("site=t", "recipe=chain")
    assert r.rc == 0, r.text
    assert _top(project) == ["01_make", "02_place", "03_double", "04_scale"], r.text
    assert sorted(d.name for d in (project.ws / "stale" / "chain").iterdir()) == ["02_double", "03_scale"]
    st = project.run("status", "site=t", "recipe=chain")
    assert [ln.split()[0] for ln in st.out.splitlines() if ln.startswith("  ")] == _top(project), st.text


def test_an_edited_stale_folder_keeps_its_edit(project):
    assert project.run("site=t", "recipe=chain").rc == 0
    edited = project.ws / "03_scale" / "scaled.txt"
    edited.unlink()
    edited.write_text("99\n")
    note = project.ws / "03_scale" / "notes.md"  # a file of the user's own
    note.write_text("mine\n")
    project.recipe("chain", FULL[:2])
    assert project.run("site=t", "recipe=chain").rc == 0
    kept = project.ws / "stale" / "chain" / "03_scale"
    assert (kept / "scaled.txt").read_text() == "99\n" and (kept / "notes.md").read_text() == "mine\n"
    project.recipe("chain", FULL)
    r = project.run("site=t", "recipe=chain")
    assert r.rc == 0, r.text
    assert edited.read_text() == "99\n" and note.read_text() == "mine\n", r.text
    assert project.status_of(r, "03_scale") == "edited", r.text


def test_a_stale_folder_of_the_same_name_is_set_aside_never_overwritten(tmp_path):
    from twinkit.engine.recipes import JOURNAL, _journalled, stale_moves

    ws, edits = tmp_path / "t", tmp_path / "t" / ".cache" / "edits"
    (ws / "03_scale").mkdir(parents=True)
    (ws / "03_scale" / "new.txt").write_text("new\n")
    (ws / "stale" / "chain" / "03_scale").mkdir(parents=True)
    (ws / "stale" / "chain" / "03_scale" / "old.txt").write_text("old\n")
    (ws / "01_make").mkdir()
    _journalled(ws, "chain", "chain", stale_moves(ws, "chain", {"01_make"}, edits))
    assert (ws / "stale" / "chain" / "03_scale" / "new.txt").read_text() == "new\n"
    assert [p.read_text() for p in edits.glob("stale-chain-03_scale-*/old.txt")] == ["old\n"]
    assert (ws / "01_make").is_dir() and not (ws / JOURNAL).exists()


def test_road_source_none_moves_the_road_steps_folders_out_and_back(project):
    project.recipe("twin", ["{id: make, uses: step/make}", "{id: fetch, uses: road_source}",
                            "{id: convert, uses: step/convert_roads, optional: true}",
                            "{id: align, uses: step/align_net, optional: true}",
                            "{id: double, uses: step/double}", "{id: export, uses: step/export_all}"],
                   extra="defaults:\n  - /road_source: toy\n  - _self_\n")
    assert project.run("site=t", "recipe=twin").rc == 0
    full = _top(project)
    r = project.run("site=t", "recipe=twin", "road_source=none")
    assert r.rc == 0, r.text
    assert _top(project) == ["01_make", "02_double", "03_export"], r.text
    assert (project.ws / "03_export" / "export.txt").read_text() == "no roads\n"
    assert sorted(d.name for d in (project.ws / "stale" / "twin").iterdir()) == full[1:], r.text
    st = project.run("status", "site=t", "recipe=twin", "road_source=none")
    assert "06_export" not in st.out and "5 folder(s) of steps not in this plan" in st.out, st.text
    project.reset_counts()
    r = project.run("site=t", "recipe=twin")  # the roads back: their folders come back, nothing computed
    assert r.rc == 0 and _top(project) == full, r.text
    assert (project.ws / "06_export" / "export.txt").read_text() == "roads\n" and project.counts() == {}, r.text
    assert sorted(d.name for d in (project.ws / "stale" / "twin").iterdir()) == ["02_double", "03_export"]

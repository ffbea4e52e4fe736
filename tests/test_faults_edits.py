"""Issue 47, cases 1 and 2: a hand edit never drops out of the twin silently (a setting changed and set back, a
recipe switch killed half-way), and a file a parameter names is in its step's key (docs/engine.md, "Faults")."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest


def _edit(project, rel: str, text: str) -> None:
    path = project.ws / rel
    path.unlink()  # like an editor that saves a new file
    path.write_text(text)


def test_an_edit_set_aside_comes_back_with_its_setting(project):
    assert project.run("site=t", "recipe=chain").rc == 0
    _edit(project, "02_double/double.txt", "100\n")
    assert project.run("site=t", "recipe=chain").rc == 0  # kept: scale gives 300
    r = project.run("site=t", "recipe=chain", "steps.make.value=2")  # another upstream value: set aside
    assert r.rc == 0, r.text
    assert (project.ws / "02_double" / "double.txt").read_text() == "4\n"
    assert "set aside" in r.text
    st = project.run("status", "site=t", "recipe=chain")
    assert "02_double" in st.out and "would re-apply hand-edited double.txt" in st.out, st.text
    assert "03_scale" in st.out and "cached" in st.out.splitlines()[-1], st.text
    project.reset_counts()
    r = project.run("site=t", "recipe=chain")  # the value set back: the edit comes back with its result
    assert r.rc == 0, r.text
    assert (project.ws / "02_double" / "double.txt").read_text() == "100\n", r.text
    assert (project.ws / "03_scale" / "scaled.txt").read_text() == "300\n", r.text
    assert project.status_of(r, "02_double") == "edited" and "re-applied hand-edited double.txt" in r.text, r.text
    assert project.counts() == {}, "everything was stored: nothing computed"
    r = project.run("site=t", "recipe=chain")  # and it stays, as any kept edit does
    assert project.status_of(r, "02_double") == "edited" and project.status_of(r, "03_scale") == "reused", r.text
    # rerun=[double] drops it (still in .cache/edits) and it is not re-applied afterwards
    r = project.run("site=t", "recipe=chain", "rerun=[double]")
    assert r.rc == 0 and (project.ws / "02_double" / "double.txt").read_text() == "2\n", r.text
    assert project.run("site=t", "recipe=chain", "steps.make.value=2").rc == 0
    r = project.run("site=t", "recipe=chain")
    assert (project.ws / "02_double" / "double.txt").read_text() == "2\n", r.text


def test_an_edit_of_a_fan_out_item_comes_back_with_its_setting(project):
    project.recipe("tiles", ["{id: make, uses: step/make}", "{id: tiles, uses: step/tiles}",
                             "{id: per_tile, uses: step/per_tile, foreach: tiles.json}",
                             "{id: gather, uses: step/gather}"])
    assert project.run("site=t", "recipe=tiles", "executor.workers=1").rc == 0
    _edit(project, "03_per_tile/001/tile.txt", "50\n")
    assert project.run("site=t", "recipe=tiles", "executor.workers=1").rc == 0
    assert project.run("site=t", "recipe=tiles", "executor.workers=1", "steps.make.value=4").rc == 0
    r = project.run("site=t", "recipe=tiles", "executor.workers=1")
    assert r.rc == 0, r.text
    assert (project.ws / "03_per_tile" / "001" / "tile.txt").read_text() == "50\n", r.text
    assert project.status_of(r, "03_per_tile") == "edited", r.text
    assert (project.ws / "04_gather" / "merged.txt").read_text() == "54\n", r.text  # 1 + 50 + 3


def test_an_edit_made_on_a_result_that_came_out_different_stops_the_run(project):
    assert project.run("site=t", "recipe=chain").rc == 0
    _edit(project, "02_double/double.txt", "100\n")
    assert project.run("site=t", "recipe=chain", "steps.make.value=2").rc == 0
    # the stored result the edit was made on is lost (gc, a damaged entry) and computes differently now
    edits = sorted((project.ws / ".cache" / "edits").glob("02_double-*"))
    note = json.loads((edits[-1] / ".twinkit-edit.json").read_text())
    note["files"]["double.txt"]["base"] = "0" * 64
    (edits[-1] / ".twinkit-edit.json").write_text(json.dumps(note))
    r = project.run("site=t", "recipe=chain")
    assert r.rc == 2, r.text
    errors = [ln for ln in r.err.splitlines() if ln.startswith("twinkit: error:")]
    assert len(errors) == 1 and str(edits[-1] / "double.txt") in errors[0] and "rerun=[double]" in errors[0], r.err
    assert (project.ws / "02_double" / "double.txt").read_text() == "4\n"  # nothing replaced
    r = project.run("site=t", "recipe=chain", "rerun=[double]")  # the documented way on
    assert r.rc == 0 and (project.ws / "02_double" / "double.txt").read_text() == "2\n", r.text
    assert (edits[-1] / "double.txt").read_text() == "100\n"


_KILL_AFTER = """
import os, re, runpy, signal, sys
n = int(os.environ["KILL_AFTER_MOVES"]); real = os.replace; done = [0]
def replace(src, dst, *a, **k):
    moving = re.match(r"^\\d{2,}_", os.path.basename(os.fspath(src))) and "recipes" in os.fspath(src) + os.fspath(dst)
    if moving and done[0] == n:
        os.kill(os.getpid(), signal.SIGKILL)
    real(src, dst, *a, **k)
    done[0] += bool(moving)
os.replace = replace
sys.argv = ["twinkit", *sys.argv[1:]]
runpy.run_module("twinkit", run_name="__main__")
"""


def _killed_switch(project, recipe: str, moves: int) -> int:
    argv = [sys.executable, "-c", _KILL_AFTER, "site=t", f"recipe={recipe}", f"engine.outputs_dir={project.out}"]
    p = subprocess.run(argv, env=project.env(KILL_AFTER_MOVES=str(moves)), cwd=project.tmp, capture_output=True,
                       text=True, timeout=120)
    return p.returncode


@pytest.mark.parametrize("moves", [1, 3])
def test_a_recipe_switch_killed_between_its_moves_loses_no_edit(project, moves):
    project.recipe("other", ["{id: make, uses: step/make, params: {value: 5}}", "{id: place, uses: step/place}"])
    assert project.run("site=t", "recipe=chain").rc == 0
    with open(project.ws / "01_make" / "data.txt", "w") as f:
        f.write("7\n")
    assert (r := project.run("site=t", "recipe=chain")).rc == 0, r.text  # the edit kept: 7 * 2 * 3
    assert project.run("site=t", "recipe=other").rc == 0  # chain parked, its edit with it
    # back to chain, killed after `moves` folder moves (other's 2 parked, then chain's 3 back)
    assert _killed_switch(project, "chain", moves) == -9
    st = project.run("status", "site=t", "recipe=chain")
    assert st.rc == 0 and ".twinkit.switch.json" in st.out and "unfinished" in st.out, st.text
    r = project.run("site=t", "recipe=chain")
    assert r.rc == 0, r.text
    assert (project.ws / "01_make" / "data.txt").read_text() == "7\n", r.text
    assert (project.ws / "03_scale" / "scaled.txt").read_text() == "42\n", r.text
    assert project.status_of(r, "01_make") == "edited", r.text
    assert sorted(d.name for d in (project.ws / "recipes" / "other").iterdir()) == ["01_make", "02_place"]
    assert not list((project.ws / ".cache" / "edits").glob("parked-*")), "a park was set aside as if it were old"
    r = project.run("site=t", "recipe=other")
    assert r.rc == 0 and project.status_of(r, "01_make") == "reused", r.text


def test_a_switch_killed_on_the_way_out_is_finished_by_the_next_run(project):
    project.recipe("other", ["{id: make, uses: step/make, params: {value: 5}}", "{id: place, uses: step/place}"])
    assert project.run("site=t", "recipe=chain").rc == 0
    with open(project.ws / "01_make" / "data.txt", "w") as f:
        f.write("7\n")
    assert project.run("site=t", "recipe=chain").rc == 0
    assert _killed_switch(project, "other", 1) == -9  # 01_make parked, 02_double and 03_scale not yet
    assert project.run("site=t", "recipe=other").rc == 0
    assert sorted(d.name for d in (project.ws / "recipes" / "chain").iterdir()) == ["01_make", "02_double",
                                                                                     "03_scale"]
    r = project.run("site=t", "recipe=chain")
    assert r.rc == 0 and (project.ws / "03_scale" / "scaled.txt").read_text() == "42\n", r.text
    assert not list((project.ws / ".cache" / "edits").glob("parked-*"))


def _path_project(project):
    project.recipe("named", ["{id: read_named, uses: step/read_named}", "{id: predict, uses: step/predict}"],
                   extra="defaults:\n  - /image_model: toy_model\n  - _self_\n")
    return project.env(TWINKIT_PLUGIN_MODULES="tests.support.engine_plugins,tests.support.path_plugins")


@pytest.mark.parametrize("weights", ["file", "folder"])
def test_a_file_a_parameter_names_is_in_the_key(project, weights):
    env = _path_project(project)
    roads = project.tmp / "map.osm"
    roads.write_text("1\n")
    w = project.tmp / "weights"
    if weights == "folder":
        w.mkdir()
        (w / "a.bin").write_text("2\n")
    else:
        w.write_text("2\n")
    args = ("site=t", "recipe=named", f"steps.read_named.path={roads}", f"image_model.weights_path={w}")

    def run(*extra):
        project.reset_counts()
        res = project.run(*args, *extra, env=env)
        assert res.rc == 0, res.text
        return res

    run()
    roads.write_text("3\n")  # the map's content changes, its name does not
    st = project.run("status", *args, env=env)
    assert st.rc == 0 and "file changed: path" in st.out, st.text
    r = run()
    assert project.status_of(r, "01_read_named") == "ran" and project.status_of(r, "02_predict") == "reused", r.text
    assert (project.ws / "01_read_named" / "named.txt").read_text() == "3\n"
    (w / "a.bin" if weights == "folder" else w).write_text("4\n")  # so do the weights
    st = project.run("status", *args, env=env)
    assert st.rc == 0 and "file changed: image_model.weights_path" in st.out, st.text
    r = run()
    assert project.status_of(r, "02_predict") == "ran" and project.counts() == {"predict": 1}, r.text
    assert (project.ws / "02_predict" / "predicted.txt").read_text() == "4\n"
    os.utime(roads)  # touched, same content: reused
    os.utime(w / "a.bin" if weights == "folder" else w)
    r = run()
    assert project.counts() == {}, r.text
    assert project.status_of(r, "01_read_named") == "reused" and project.status_of(r, "02_predict") == "reused"
    roads.write_text("1\n")  # back to the first content: its stored result comes back
    r = run()
    assert project.status_of(r, "01_read_named") == "cached" and project.counts() == {}, r.text


def test_a_missing_file_a_parameter_names_is_still_the_steps_error(project):
    env = _path_project(project)
    r = project.run("site=t", "recipe=named", f"steps.read_named.path={project.tmp / 'nope.osm'}",
                    f"image_model.weights_path={project.tmp}", env=env)
    assert r.rc == 2 and "nope.osm does not exist; set steps.read_named.path" in r.err, r.text


def test_the_parameters_that_name_input_files_are_declared_as_paths():
    from twinkit.ranges import path_fields
    from twinkit_efficientvit.efficientvit import EfficientViTParams
    from twinkit_efficientvit.hf import HFParams
    from twinkit_efficientvit.tflite import DeepLabTFLiteParams
    from twinkit_roads.sources import FileSourceParams, OpenDriveSourceParams

    assert path_fields(FileSourceParams) == {"path": ()}
    assert path_fields(OpenDriveSourceParams) == {"path": ()}
    assert path_fields(EfficientViTParams) == {"weights_path": ()}
    assert path_fields(DeepLabTFLiteParams) == {"weights_path": ()}
    assert path_fields(HFParams) == {"model": ()}

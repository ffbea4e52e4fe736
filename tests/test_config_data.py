"""Configs are data, secrets stay out of the records, and errors name their cause (issue 27, findings 6, 9, 10)."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from twinkit.config import config_file_problem


def test_a_recipe_with_callbacks_is_refused_under_multirun_and_its_callback_never_runs(project):
    """Hydra instantiates hydra.callbacks.* under -m; a recipe that adds one is refused before Hydra reads it."""
    marker = project.tmp / "ran"
    project.recipe("evil", ["{id: make, uses: step/make}"],
                   extra=f"hydra:\n  callbacks:\n    x:\n      _target_: subprocess.call\n"
                         f"      _args_: [[touch, {marker}]]\n")
    r = project.run("-m", "site=t", "recipe=evil", "steps.make.value=1,2")
    assert r.rc == 2, r.text
    assert "recipe/evil.yaml: refused, it sets 'hydra.callbacks.x._target_'" in r.err
    assert not marker.exists() and not project.counts()
    # the shipped sweep files (hydra.sweeper.params) and the root config's own callback stay allowed
    (project.conf / "recipe" / "evil.yaml").unlink()
    r = project.run("-m", "site=t", "recipe=chain", "steps.make.value=1,2")
    assert r.rc == 0, r.text


@pytest.mark.parametrize("text,group,why", [
    ("# @package _global_\nhydra:\n  launcher:\n    n_jobs: 64\n", "recipe", "hydra.launcher.n_jobs"),
    ("# @package hydra\ncallbacks: {}\n", "site", "hydra.callbacks"),
    ("# @package _global_\nhydra:\n  job_logging:\n    root: {level: INFO}\n", "site", "hydra.job_logging"),
    ("name: x\nsteps: [{a: {_target_: os.system}}]\n", "recipe", "steps[0].a._target_"),
    ("defaults:\n  - /hydra/callbacks: evil\n", "recipe", "/hydra/callbacks"),
    ("n_jobs: 2\n", "hydra/launcher", "Hydra config group"),
])
def test_what_a_config_file_may_not_set(tmp_path, text, group, why):
    f = tmp_path / "x.yaml"
    f.write_text(text)
    assert why in (config_file_problem(f, group) or "")


def test_what_a_config_file_may_set(tmp_path):
    f = tmp_path / "x.yaml"
    f.write_text("# @package _global_\nhydra:\n  sweeper:\n    params:\n      a.b: 1,2\nsite: {target: 3}\n")
    assert config_file_problem(f, "sweep") is None
    for sweep in (Path(__file__).resolve().parents[1] / "conf" / "sweep").glob("*.yaml"):
        assert config_file_problem(sweep, "sweep") is None, sweep


def test_an_oc_env_value_is_absent_from_the_manifest_and_the_report(project):
    secret = "s3cr3t-token-4711"
    project.site("t", "name: t\napi_token: ${oc.env:TWINKIT_TEST_SECRET}\n")
    r = project.run("site=t", "recipe=chain", env=project.env(TWINKIT_TEST_SECRET=secret))
    assert r.rc == 0, r.text
    run = next(project.ws.glob("runs/*"))
    manifest = (run / "manifest.json").read_text()
    assert secret not in manifest
    assert json.loads(manifest)["config"]["site"]["api_token"] == "<from env TWINKIT_TEST_SECRET>"
    report = run / "report" / "report.html"
    assert report.is_file() and secret not in report.read_text(errors="replace")
    assert secret not in r.text


def test_config_errors_inside_multirun_exit_2(project):
    r = project.run("-m", "site=t", "recipe=chain", "steps.scale.factr=1,2")  # composition, in the parent
    assert r.rc == 2 and "factr" in r.err, r.text
    project.site("g", "name: t\nbase_point: {lat: abc, lon: 24.9}\n")  # checked in each job
    r = project.run("-m", "site=g", "recipe=chain", "steps.make.value=1,2")
    assert r.rc == 2 and "site.base_point.lat='abc' is not a number" in r.err, r.text
    assert not project.counts()
    r = project.run("-m", "site=t", "recipe=chain", "steps.make.fail=true,false")  # a step's failure stays 1
    assert r.rc == 1 and "boom on purpose" in r.err, r.text


def test_outputs_dir_from_conf_local_is_checked_at_start(project):
    blocker = project.tmp / "a-file"
    blocker.write_text("")
    (project.conf / "local").mkdir()
    (project.conf / "local" / "t.yaml").write_text(f"# @package _global_\nengine:\n  outputs_dir: {blocker}/sub\n")
    r = project.run("site=t", "recipe=chain", outputs=False)
    assert r.rc == 2 and f"cannot write to the outputs folder {blocker}/sub" in r.err, r.text
    assert "Traceback" not in r.text
    r = project.run("-m", "site=t", "recipe=chain", "steps.make.value=1,2", outputs=False)
    assert r.rc == 2 and "cannot write to the outputs folder" in r.err, r.text


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_disk_full_names_the_cause_and_the_path(project):
    """Writes to /dev/full fail with a real ENOSPC (no file name in the error): the message says disk full and
    where, and the run still writes its manifest."""
    r = project.run("site=t", "recipe=chain", env=project.env(TWINKIT_TEST_FULL="/dev/full"))
    assert r.rc == 1, r.text
    line = [ln for ln in r.err.splitlines() if ln.startswith("twinkit: error:")]
    assert len(line) == 1 and "step 'make'" in line[0] and "disk full (no space left on the device)" in line[0]
    assert str(project.ws) in line[0] and "engine.outputs_dir" in line[0]
    m = json.loads(next(project.ws.glob("runs/*/manifest.json")).read_text())
    assert m["status"] == "failed" and "disk full" in m["error"]


def test_a_sweep_value_out_of_range_is_refused_before_any_job_runs(project):
    """-m reconstructor.depth=11,30: every job's values are checked in the parent, as a single run's are;
    sweep files' hydra.sweeper.params too."""
    project.recipe("mesh", ["{id: make, uses: step/make}", "{id: reconstruct, uses: reconstructor}"],
                   extra="defaults:\n  - /reconstructor: poisson\n  - _self_\n")
    (project.conf / "sweep").mkdir()
    (project.conf / "sweep" / "d.yaml").write_text(
        "# @package _global_\nhydra:\n  sweeper:\n    params:\n      reconstructor.depth: 9,31\n")
    env = project.env(TWINKIT_PLUGINS="builtins,pointcloud")
    for args, bad in ((["reconstructor.depth=11,30"], "30"), (["+sweep=d"], "31")):
        r = project.run("-m", "site=t", "recipe=mesh", *args, env=env)
        assert r.rc == 2, r.text
        assert f"reconstructor.depth={bad} is out of range (plugin reconstructor/poisson)" in r.err
        assert not project.counts() and not list(project.out.glob("t/sweeps/*/job*/0*"))


def test_an_input_path_read_from_the_environment_still_verifies(project):
    """oc.env is used for paths too: the config shows <from env VAR>, the file lists keep the real path."""
    data = project.tmp / "data"
    data.mkdir()
    (data / "seed.txt").write_text("3\n")
    project.site("s", "name: t\ninputs:\n  seed: ${oc.env:TWINKIT_TEST_DATA}/seed.txt\n")
    project.recipe("fromseed", ["{id: read, uses: step/read_seed}"])
    r = project.run("site=s", "recipe=fromseed", env=project.env(TWINKIT_TEST_DATA=str(data)))
    assert r.rc == 0, r.text
    run = next(project.ws.glob("runs/*"))
    m = json.loads((run / "manifest.json").read_text())
    assert m["config"]["site"]["inputs"]["seed"] == "<from env TWINKIT_TEST_DATA>/seed.txt"
    assert [e["path"] for e in m["inputs"]] == [str(data / "seed.txt")]
    v = project.run("verify", str(run))
    assert v.rc == 0, v.text

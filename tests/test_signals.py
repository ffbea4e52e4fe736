"""Processes, signals and deaths: multirun with fan-out, native crashes, SIGTERM, Ctrl-C during a native
call, workers that outlive their run, the thread budget across concurrent runs, sweep folders.

Real processes and real signals, through the real ``twinkit`` command."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

FAN = ["{id: make, uses: step/make}", "{id: tiles, uses: step/tiles}",
       "{id: per_tile, uses: step/per_tile, foreach: tiles.json}", "{id: gather, uses: step/gather}"]


def _wait_for(pred, timeout=60.0, what="condition"):
    deadline = time.time() + timeout
    while time.time() < deadline:
        v = pred()
        if v:
            return v
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def _pid_in(files) -> int | None:
    """The pid written in the first of ``files`` that holds one (None while it is still being written)."""
    for f in files:
        try:
            text = f.read_text().strip()
        except OSError:
            continue
        if text:
            return int(text)
    return None


def _alive(pid: int) -> bool:
    from twinkit.signals import pid_alive

    return pid_alive(pid)


def _stop(p: subprocess.Popen, sig: int) -> tuple[str, str]:
    """Send ``sig`` to the run ``p`` and wait for it to end (its process group is killed if it does not)."""
    try:
        os.kill(p.pid, sig)
        return p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)


def _manifests(project) -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted((project.ws / "runs").glob("*/manifest.json"))]


def test_multirun_with_a_fan_out_recipe(project):
    # jobs run in joblib's loky workers; their fan-out pools used to inherit the 'loky' start method
    project.recipe("fan", FAN)
    r = project.run("-m", "site=t", "recipe=fan", "steps.tiles.n=2,3", "executor.workers=2")
    assert r.rc == 0, r.text
    jobs = sorted((project.ws / "sweeps").glob("*/job*"))
    assert len(jobs) == 2
    merged = sorted(int((j / "04_gather" / "merged.txt").read_text()) for j in jobs)
    assert merged == [2 * 1 + 0 + 1, 3 * 1 + 0 + 1 + 2]
    for j in jobs:
        assert json.loads((j / "manifest.json").read_text())["status"] == "ok"


def test_multirun_with_a_fan_out_recipe_on_dask(project):
    pytest.importorskip("distributed")
    project.recipe("fan", FAN)
    r = project.run("-m", "site=t", "recipe=fan", "steps.tiles.n=2,3", "executor=dask", "executor.n_workers=1",
                    env=project.env(TWINKIT_PLUGINS="builtins,tiles"), timeout=300)
    if "no executor plugin named 'dask'" in r.err:
        pytest.skip("the tiles plugin (dask executor) is not installed")
    assert r.rc == 0, r.text
    jobs = sorted((project.ws / "sweeps").glob("*/job*"))
    assert sorted(int((j / "04_gather" / "merged.txt").read_text()) for j in jobs) == [3, 6]


@pytest.mark.parametrize("how,sig", [("segv", "SIGSEGV"), ("abort", "SIGABRT")])
def test_a_native_crash_is_the_steps_failure_with_a_manifest(project, how, sig):
    project.recipe("crashy", ["{id: make, uses: step/make}", "{id: crash, uses: step/crash}"])
    r = project.run("site=t", "recipe=crashy", f"steps.crash.how={how}")
    assert r.rc == 1, r.text
    assert "step 'crash' (step/crash" in r.err and sig in r.err, r.err
    assert (project.ws / "01_make" / "data.txt").read_text() == "1\n"
    m = _manifests(project)[-1]
    assert m["status"] == "failed" and "step 'crash'" in m["error"] and sig in m["error"]
    assert [s["id"] for s in m["steps"]] == ["make"]
    run_log = sorted((project.ws / "runs").glob("*/run.log"))[-1].read_text()
    if how == "segv":  # faulthandler: the Python stack of the crash, in the run log
        assert "Fatal Python error: Segmentation fault" in run_log and "in crash" in run_log
    assert not list((project.ws / ".cache" / "steps" / ".tmp").iterdir()), "the crashed step's folder must go"
    # and the next run starts at the crashed step
    project.reset_counts()
    r = project.run("site=t", "recipe=crashy", "steps.crash.how=none")
    assert r.rc == 0, r.text
    assert project.counts() == {"crash": 1}


def test_a_native_crash_in_a_one_worker_fan_out_is_the_steps_failure(project):
    project.recipe("fancrash", ["{id: make, uses: step/make}", "{id: tiles, uses: step/tiles}",
                                "{id: crash, uses: step/crash, foreach: tiles.json}"])
    r = project.run("site=t", "recipe=fancrash", "executor.workers=1")
    assert r.rc == 1, r.text
    assert "step 'crash'" in r.err and "SIGSEGV" in r.err, r.err
    assert _manifests(project)[-1]["status"] == "failed"


def test_sigterm_is_handled_like_ctrl_c_and_the_manifest_says_running_first(project):
    p = project.popen("site=t", "recipe=chain", env=project.env(TWINKIT_TEST_SLEEP="60"))
    try:
        store_tmp = project.ws / ".cache" / "steps" / ".tmp"
        _wait_for(lambda: list(store_tmp.glob("*/started")), what="the step to start")
        # a run that is killed outright is recognisable: its manifest says "running" from the start
        m = _manifests(project)
        assert len(m) == 1 and m[0]["status"] == "running", m
        os.kill(p.pid, signal.SIGTERM)
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    assert p.returncode == 143, err
    assert "terminated" in err and "Traceback" not in err
    assert not (project.ws / "01_make").exists()
    assert not list(store_tmp.iterdir())
    m = _manifests(project)[-1]
    assert m["status"] == "interrupted" and "make" in m["error"]


def test_ctrl_c_stops_a_step_stuck_in_a_native_call_within_seconds(project):
    # the stand-in blocks SIGINT and SIGTERM, as a long C call that never returns to Python would
    project.recipe("stuck", ["{id: make, uses: step/make}", "{id: crash, uses: step/crash, params: {how: block}}"])
    p = project.popen("site=t", "recipe=stuck")
    try:
        store_tmp = project.ws / ".cache" / "steps" / ".tmp"
        # the stand-in creates the file, then writes its pid: wait for the pid, not only the file
        step_pid = _wait_for(lambda: _pid_in(store_tmp.glob("*/started")), what="the step to start")
        os.kill(p.pid, signal.SIGINT)
        out, err = p.communicate(timeout=30)  # the step itself would sleep 120 s
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    assert p.returncode == 130, err
    assert "interrupted" in err
    assert not _alive(step_pid)
    assert not list(store_tmp.iterdir())
    assert _manifests(project)[-1]["status"] == "interrupted"


@pytest.mark.parametrize("executor", ["local", "dask"])
def test_killing_the_run_kills_its_fan_out_workers(project, executor):
    project.recipe("fan", FAN)
    if executor == "dask":
        pytest.importorskip("distributed")
        pytest.importorskip("twinkit_tiles")
        args, plugins = ["executor=dask", "executor.n_workers=2"], "builtins,tiles"
    else:
        args, plugins = ["executor.workers=2"], "builtins"
    p = project.popen("site=t", "recipe=fan", "steps.tiles.n=2", *args,
                      env=project.env(TWINKIT_TEST_TILE_SLEEP="120", TWINKIT_PLUGINS=plugins))
    try:
        store_tmp = project.ws / ".cache" / "steps" / ".tmp"
        started = _wait_for(lambda: len(list(store_tmp.glob("*/started"))) == 2 and list(store_tmp.glob("*/started")),
                            what="both workers to start")
        workers = {int(s.read_text()) for s in started}
        assert len(workers) == 2 and p.pid not in workers
        os.kill(p.pid, signal.SIGKILL)  # the run's own process only, not its process group
        p.wait(timeout=30)
        _wait_for(lambda: not any(_alive(w) for w in workers), timeout=30, what="the workers to die with the run")
    finally:
        os.killpg(p.pid, signal.SIGKILL)
        p.communicate()


def test_thread_budget_arithmetic():
    from twinkit.threads import share

    assert share(16, 1) == 16
    assert share(16, 2) == 8
    assert share(16, 3) == 5
    assert share(2, 3) == 1 and share(1, 5) == 1
    assert share(16, 1, cap=8) == 8 and share(16, 4, cap=8) == 4
    assert share(2, 0) == 2


def test_registered_runs_share_the_cores_and_dead_ones_are_ignored(tmp_path, monkeypatch):
    from twinkit import threads

    monkeypatch.setenv("TWINKIT_RUNTIME_DIR", str(tmp_path))
    monkeypatch.setattr(threads, "cores", lambda: 8)
    assert threads.budget() == 8
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    try:
        (tmp_path / "runs").mkdir(parents=True, exist_ok=True)
        (tmp_path / "runs" / str(other.pid)).write_text("another run\n")
        (tmp_path / "runs" / str(dead.pid)).write_text("a run killed outright\n")
        with threads.registered():
            assert threads.active_runs() == 2
            assert threads.budget() == 4
            assert threads.budget(cap=2) == 2
        assert not (tmp_path / "runs" / str(dead.pid)).exists(), "a dead run's file is removed"
        assert not (tmp_path / "runs" / str(os.getpid())).exists()
    finally:
        other.kill()
        other.wait()


def test_a_second_run_halves_the_threads_of_a_run(project, tmp_path):
    # a registered run beside this one (a live process with a file in the runtime folder)
    rt = tmp_path / "rt"
    (rt / "runs").mkdir(parents=True)
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        (rt / "runs" / str(other.pid)).write_text("another run\n")
        project.recipe("thr", ["{id: make, uses: step/make}", "{id: threads, uses: step/threads}"])
        r = project.run("site=t", "recipe=thr", env=project.env(TWINKIT_RUNTIME_DIR=str(rt)))
        assert r.rc == 0, r.text
        n = max(1, (os.cpu_count() or 1) // 2)
        # ctx.threads, and the step's OpenMP/BLAS pools
        assert (project.ws / "02_threads" / "threads.txt").read_text().split() == [str(n), str(n)]
    finally:
        other.kill()
        other.wait()


def test_multirun_jobs_share_the_cores(project, tmp_path):
    project.recipe("thr", ["{id: make, uses: step/make}", "{id: threads, uses: step/threads}"])
    r = project.run("-m", "site=t", "recipe=thr", "steps.make.value=1,2", "hydra.launcher.n_jobs=2",
                    env=project.env(TWINKIT_RUNTIME_DIR=str(tmp_path / "rt")))
    assert r.rc == 0, r.text
    jobs = sorted((project.ws / "sweeps").glob("*/job*"))
    assert len(jobs) == 2
    n = max(1, (os.cpu_count() or 1) // 2)
    for j in jobs:
        assert (j / "02_threads" / "threads.txt").read_text().split() == [str(n), str(n)]


def test_a_failing_job_fails_the_sweep(project):
    r = project.run("-m", "site=t", "recipe=chain", "steps.make.fail=false,true")
    assert r.rc == 1, r.text
    assert "boom on purpose" in r.text


def test_two_sweeps_started_together_do_not_share_a_folder(project):
    procs = [subprocess.Popen(project.cmd("-m", "site=t", "recipe=chain", f"steps.scale.factor={a},{b}",
                                          f"engine.outputs_dir={project.out}"),
                              env=project.env(), cwd=project.tmp, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for a, b in ((2, 3), (4, 5))]
    results = [(p.wait(timeout=180), p.communicate()) for p in procs]
    for rc, (out, err) in results:
        assert rc == 0, err
    sweeps = sorted((project.ws / "sweeps").iterdir())
    assert len(sweeps) == 2, sweeps
    values = sorted(int((j / "03_scale" / "scaled.txt").read_text()) for s in sweeps for j in s.glob("job*"))
    assert values == [4, 6, 8, 10]


@pytest.mark.parametrize("sig,code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_signalled_sweep_stops_its_jobs_like_single_runs(project, sig, code):
    p = project.popen("-m", "site=t", "recipe=chain", "steps.scale.factor=2,3", env=project.env(TWINKIT_TEST_SLEEP="60"))
    try:
        store_tmp = project.ws / ".cache" / "steps" / ".tmp"
        _wait_for(lambda: list(store_tmp.glob("*/started")), what="a job's step to start")
        _wait_for(lambda: len(list((project.ws / "sweeps").glob("*/job*/manifest.json"))) == 2, what="both jobs")
        os.kill(p.pid, sig)  # the sweep's own process only (docker stop, timeout)
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    assert p.returncode == code, err
    statuses = [json.loads(m.read_text())["status"] for m in (project.ws / "sweeps").glob("*/job*/manifest.json")]
    assert statuses == ["interrupted", "interrupted"], statuses
    assert not list(store_tmp.iterdir())


def test_a_run_stopped_while_it_waits_for_the_store_says_interrupted(project):
    # twinkit gc holds the store: the run has taken its workspace and waits; SIGTERM then must still end in
    # an "interrupted" manifest with the workspace given back (a sweep's job once stayed "running" so)
    import fcntl

    from twinkit.engine.locks import store_lock_path

    path = store_lock_path(project.ws)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        p = project.popen("site=t", "recipe=chain")
        owner = project.ws / ".twinkit.owner"
        try:
            _wait_for(lambda: owner.exists() and f"pid {p.pid} " in owner.read_text(), what="the run to take the workspace")
            _wait_for(lambda: [m for m in _manifests(project) if m["status"] == "running"], what="the running manifest")
        finally:
            _, err = _stop(p, signal.SIGTERM)
        assert p.returncode == 143, err
        m = _manifests(project)[-1]
        assert m["status"] == "interrupted" and "Terminated" in m["error"], m
    finally:
        os.close(fd)
    r = project.run("site=t", "recipe=chain")
    assert r.rc == 0, r.text


def test_a_native_crash_in_a_fan_out_worker_is_the_steps_failure(project):
    project.recipe("fancrash", ["{id: make, uses: step/make}", "{id: tiles, uses: step/tiles}",
                                "{id: crash, uses: step/crash, foreach: tiles.json}"])
    r = project.run("site=t", "recipe=fancrash", "executor.workers=2")
    assert r.rc == 1, r.text
    assert "step 'crash'" in r.err and "worker process died" in r.err, r.err
    assert _manifests(project)[-1]["status"] == "failed"


def test_ctrl_c_stops_fan_out_workers_stuck_in_native_calls(project):
    project.recipe("fanstuck", ["{id: make, uses: step/make}", "{id: tiles, uses: step/tiles}",
                                "{id: crash, uses: step/crash, foreach: tiles.json, params: {how: block}}"])
    p = project.popen("site=t", "recipe=fanstuck", "steps.tiles.n=2", "executor.workers=2")
    try:
        store_tmp = project.ws / ".cache" / "steps" / ".tmp"
        started = _wait_for(lambda: len(list(store_tmp.glob("*/started"))) == 2 and list(store_tmp.glob("*/started")),
                            what="both workers to start")
        workers = {int(s.read_text()) for s in started}
        os.kill(p.pid, signal.SIGINT)
        out, err = p.communicate(timeout=30)  # the items would block for 120 s
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    assert p.returncode == 130, err
    _wait_for(lambda: not any(_alive(w) for w in workers), timeout=10, what="the workers to be killed")
    assert _manifests(project)[-1]["status"] == "interrupted"


def test_a_signal_inside_a_logging_lock_is_raised_once_the_lock_is_free():
    """SIGTERM that lands while the thread holds logging's lock must not raise there (the lock would stay held
    and any other thread that logs would block for good: a sweep hung so once under load); it is raised
    a moment later, outside the lock."""
    script = (
        "import logging, os, signal, time\n"
        "from twinkit.signals import _raise_terminated, _logging_lock_held, Terminated\n"
        "signal.signal(signal.SIGTERM, _raise_terminated)\n"
        "logging._acquireLock()\n"
        "try:\n"
        "    os.kill(os.getpid(), signal.SIGTERM)\n"
        "    time.sleep(0.01)\n"
        "    print('inside: not raised', flush=True)\n"
        "finally:\n"
        "    logging._releaseLock()\n"
        "try:\n"
        "    time.sleep(2.0)\n"
        "    print('after: not raised')\n"
        "except Terminated:\n"
        "    print('after: raised')\n"
    )
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert p.stdout.split("\n")[:2] == ["inside: not raised", "after: raised"], p.stdout

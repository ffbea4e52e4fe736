"""Sweeps (``twinkit -m``) meeting faults (issue 47, case 13): the sweep killed, one job's process killed, a
memory budget across the jobs. Real processes and real signals, through the real ``twinkit`` command, with
the small stand-in steps of tests/support/engine_plugins.py."""
from __future__ import annotations

import json
import os
import signal
import time



def _wait_for(pred, timeout=60.0, what="condition"):
    deadline = time.time() + timeout
    while time.time() < deadline:
        v = pred()
        if v:
            return v
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def _session(sid: int) -> list[int]:
    """The live (not zombie) processes of session ``sid``: the sweep and everything it started."""
    out = []
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[3]) == sid and fields[0] != "Z":
            out.append(int(name))
    return out


def _started(project) -> list[int]:
    """Pids of the stand-in steps that sleep now (their ``started`` file)."""
    pids = []
    for f in (project.ws / ".cache" / "steps" / ".tmp").glob("*/started"):
        try:
            pids.append(int(f.read_text()))
        except (OSError, ValueError):
            continue
    return pids


def _parent(pid: int) -> int:
    with open(f"/proc/{pid}/stat") as f:
        return int(f.read().rsplit(")", 1)[1].split()[1])


def _manifests(project) -> list[dict]:
    return [json.loads(m.read_text()) for m in sorted((project.ws / "sweeps").glob("*/job*/manifest.json"))]


def test_killing_a_sweep_kills_its_job_workers(project):
    p = project.popen("-m", "site=t", "recipe=chain", "steps.make.value=1,2", env=project.env(TWINKIT_TEST_SLEEP="60"))
    try:
        _wait_for(lambda: len(_started(project)) == 2, what="both jobs' steps to start")
        assert len(_session(p.pid)) > 3  # the sweep, its pool's workers, the jobs, their steps
        os.kill(p.pid, signal.SIGKILL)  # the sweep's own process only, not its process group
        p.wait(timeout=30)
        _wait_for(lambda: not _session(p.pid), timeout=15, what="the sweep's workers to die with it")
    finally:
        if _session(p.pid):
            os.killpg(p.pid, signal.SIGKILL)
        p.communicate()


def test_a_killed_job_worker_fails_its_job_and_the_others_finish(project):
    p = project.popen("-m", "site=t", "recipe=chain", "steps.make.value=1,2", env=project.env(TWINKIT_TEST_SLEEP="8"))
    try:
        steps = _wait_for(lambda: len(_started(project)) == 2 and _started(project), what="both jobs' steps to start")
        victim = _parent(steps[0])  # the process running that job (the out-of-memory killer's choice)
        os.kill(victim, signal.SIGKILL)
        out, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.communicate()
    assert p.returncode == 1, err
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.startswith("twinkit: error:")]
    assert len(lines) == 1 and "killed (SIGKILL, out of memory?)" in lines[0], err
    statuses = sorted(m["status"] for m in _manifests(project))
    assert statuses == ["failed", "ok"], statuses
    failed = next(m for m in _manifests(project) if m["status"] == "failed")
    assert failed["error"] == "the worker running this job was killed (SIGKILL, out of memory?)"
    assert "sweep summary" in out + err
    summary = next((project.ws / "sweeps").glob("*/report/sweep.html"))
    assert "failed" in summary.read_text()


def _recorded_peak_gb(project) -> float:
    """The largest peak the chain's steps recorded in the run before (tens of MB, for the stand-in steps)."""
    peaks = [json.loads(f.read_text())["peak_rss_mb"] for f in project.ws.glob("0*/step.json")]
    assert len(peaks) == 3 and all(peaks), peaks
    return max(peaks) / 1024


def _times(project) -> list[tuple[str, str]]:
    return sorted((m["started"], m["finished"]) for m in _manifests(project))


def test_the_sweep_memory_budget_runs_fewer_jobs_at_once(project):
    assert project.run("site=t", "recipe=chain").rc == 0  # the steps' peaks are recorded
    budget = 1.5 * _recorded_peak_gb(project)  # one job fits, two do not
    r = project.run("-m", "site=t", "recipe=chain", "steps.make.value=2,3", f"engine.sweep_memory_gb={budget:.4f}",
                    env=project.env(TWINKIT_TEST_SLEEP="2"))
    assert r.rc == 0, r.text
    assert "1 job(s) at a time, not 2" in r.err, r.err
    first, second = _times(project)
    assert second[0] >= first[1], (first, second)  # the second job started after the first had finished


def test_a_sweep_memory_budget_below_one_job_is_refused(project):
    assert project.run("site=t", "recipe=chain").rc == 0
    budget = 0.5 * _recorded_peak_gb(project)
    r = project.run("-m", "site=t", "recipe=chain", "steps.make.value=2,3", f"engine.sweep_memory_gb={budget:.4f}")
    assert r.rc == 2, r.text
    lines = r.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("twinkit: error: engine.sweep_memory_gb: a job of this sweep needs"), r.err
    assert not (project.ws / "sweeps").exists()


def test_without_a_budget_the_jobs_run_together(project):
    assert project.run("site=t", "recipe=chain").rc == 0
    r = project.run("-m", "site=t", "recipe=chain", "steps.make.value=2,3", env=project.env(TWINKIT_TEST_SLEEP="6"))
    assert r.rc == 0, r.text
    assert "at a time" not in r.err
    first, second = _times(project)
    assert second[0] < first[1], (first, second)


def test_memory_plan_counts_a_fan_out_steps_workers_and_knows_nothing_without_records(tmp_path):
    from twinkit.sweeps import memory_plan

    ws = tmp_path / "out" / "s"
    (ws / "01_tiles").mkdir(parents=True)
    items = [{"peak_rss_mb": mb} for mb in (300, 500, 400)]
    (ws / "01_tiles" / "step.json").write_text(json.dumps({"peak_rss_mb": 200, "metrics": {"per_item": items}}))

    def job(workers):
        return {"engine": {"outputs_dir": str(tmp_path / "out"), "sweep_memory_gb": 2.0}, "site": {"name": "s"},
                "executor": {"workers": workers}, "recipe": {"steps": [{"id": "tiles"}]}}

    assert memory_plan([job(1)] * 4, lambda: 4)[0] == 4  # 0.5 GB a job: four fit in 2 GB
    at_once, why = memory_plan([job(2)] * 4, lambda: 4)  # two items at once: 0.88 GB a job
    assert at_once == 2 and "step 'tiles'" in why, why
    other = job(2) | {"site": {"name": "never-ran"}}
    assert memory_plan([other] * 4, lambda: 4) == (0, "")  # no record: the jobs run as asked


def test_a_killed_pool_worker_ends_the_sweep_with_one_line_and_failed_manifests(project):
    p = project.popen("-m", "site=t", "recipe=chain", "steps.make.value=1,2", env=project.env(TWINKIT_TEST_SLEEP="30"))
    try:
        steps = _wait_for(lambda: len(_started(project)) == 2 and _started(project), what="both jobs' steps to start")
        worker = steps[0]
        while _parent(worker) != p.pid:  # up to the pool's worker itself (the sweep's child)
            worker = _parent(worker)
        os.kill(worker, signal.SIGKILL)
        out, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.communicate()
    assert p.returncode == 1, err
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.startswith("twinkit: error:")]
    assert len(lines) == 1 and "pool of workers broke" in lines[0], err
    assert [m["status"] for m in _manifests(project)] == ["failed", "failed"]
    _wait_for(lambda: not _session(p.pid), timeout=15, what="the jobs to die with their pool")

"""scripts/run_tests.py (what `make test` runs): the static checks are sessions that fail the run."""
from __future__ import annotations

import importlib.util
import os
import sys

from tests.conftest import ROOT


def _run_tests_module():
    spec = importlib.util.spec_from_file_location("twinkit_run_tests", ROOT / "scripts" / "run_tests.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look their module up while the class is made
    spec.loader.exec_module(mod)
    return mod


def test_ruff_and_mypy_run_first():
    assert [name for name, _ in _run_tests_module().CHECKS] == ["ruff", "mypy"]


def test_a_failed_check_is_a_failed_session_with_its_output(monkeypatch, capsys):
    mod = _run_tests_module()
    monkeypatch.setattr(mod, "CHECKS", [
        ("good", ["-c", "print('all fine')"]),
        ("bad", ["-c", "import sys; print('x.py:1: error: broken'); sys.exit(1)"]),
    ])
    done = mod.run_sessions(mod.check_sessions(), jobs=2)
    assert [s.name for s in done if s.failed()] == ["bad"]
    out = capsys.readouterr().out
    assert "===== bad (" in out and "x.py:1: error: broken" in out and "all fine" in out
    assert mod.PY == sys.executable


def _fake(mod, name, rc=0, out="", pytest=True, counts=None):
    s = mod.Session(name, ROOT, [], pytest=pytest)
    s.rc, s.out, s.counts = rc, out, counts or {}
    return s


def test_checks_start_first_then_the_tests_longest_first():
    mod = _run_tests_module()
    tests = [mod.Session(n, ROOT, []) for n in
             ("plugins/twinkit-segmentation", "plugins/new-one", mod.CORE, "plugins/twinkit-photo")]
    order = [s.name for s in mod.ordered(mod.check_sessions(), tests)]
    assert order == ["ruff", "mypy", mod.CORE, "plugins/twinkit-photo", "plugins/new-one",
                     "plugins/twinkit-segmentation"]
    assert mod.TYPICAL_S["plugins/twinkit-segmentation"] < mod.UNKNOWN_S < mod.TYPICAL_S["plugins/twinkit-photo"]


def test_every_plugin_with_tests_is_a_session_from_its_own_folder():
    mod = _run_tests_module()
    sessions = mod.pytest_sessions(["-q"])
    assert sessions[0].name == mod.CORE and sessions[0].cwd == ROOT
    assert "examples" in sessions[0].argv and sessions[0].argv[-1] == "-q"
    plugins = {s.name for s in sessions[2:]}
    assert plugins == {p.parent.relative_to(ROOT).as_posix() for p in ROOT.glob("plugins/*/tests")}
    names = plugins | {mod.CORE, mod.CORE_SPLIT_NAME}
    assert set(mod.TYPICAL_S) <= names, "TYPICAL_S names a session that no longer exists"
    assert names <= set(mod.TYPICAL_S), "a session without a typical time in TYPICAL_S"


def test_the_core_is_two_sessions_that_together_run_every_core_test():
    """The split paths run in their own session from the root, and the core session leaves out just those."""
    mod = _run_tests_module()
    core, demo_runs = mod.pytest_sessions([])[:2]
    assert demo_runs.name == mod.CORE_SPLIT_NAME and demo_runs.cwd == ROOT and mod.CORE_SPLIT
    for path in mod.CORE_SPLIT:
        assert (ROOT / path).exists(), path
        assert path in demo_runs.argv and f"--ignore={path}" in core.argv
    assert "tests" not in demo_runs.argv and {"tests", "examples"} <= set(core.argv)
    assert _fake(mod, mod.CORE_SPLIT_NAME, rc=5).failed()  # no tests there is a failure too


def test_jobs_come_from_the_command_line_else_the_environment_else_the_cores(monkeypatch):
    mod = _run_tests_module()
    monkeypatch.delenv(mod.JOBS_ENV, raising=False)
    assert mod.parse_jobs(["-q", "--timeout=5"]) == (os.cpu_count() or 1, ["-q", "--timeout=5"])
    monkeypatch.setenv(mod.JOBS_ENV, "3")
    assert mod.parse_jobs(["-q"]) == (3, ["-q"])
    assert mod.parse_jobs(["--jobs", "1", "-x"]) == (1, ["-x"])
    assert mod.parse_jobs(["-x", "--jobs=4"]) == (4, ["-x"])
    assert mod.parse_jobs(["--jobs=0"]) == (1, [])


def test_a_session_fails_the_run_as_before():
    mod = _run_tests_module()
    assert not _fake(mod, "plugins/p", rc=5).failed()  # a plugin without tests collected
    assert _fake(mod, mod.CORE, rc=5).failed()  # the core without tests
    assert _fake(mod, "plugins/p", rc=1).failed() and _fake(mod, "plugins/p", rc=2).failed()
    assert _fake(mod, "ruff", rc=1, pytest=False).failed() and not _fake(mod, "ruff", pytest=False).failed()


def test_the_totals_add_every_session_and_the_status_says_if_one_failed(capsys):
    mod = _run_tests_module()
    assert mod.summary_counts("x\n== 3 passed, 1 failed, 2 errors, 4 skipped in 1.0s ==\n") == {
        "passed": 3, "failed": 1, "errors": 2, "skipped": 4}
    good = [_fake(mod, "ruff", pytest=False), _fake(mod, mod.CORE, counts={"passed": 5, "skipped": 1}),
            _fake(mod, "plugins/p", rc=5)]
    assert mod.report(good, 1.0) == 0
    out = capsys.readouterr().out
    assert "sessions: 3 in 1.0 min; failed: none" in out and "total: 5 passed, 0 failed, 1 skipped" in out
    bad = good + [_fake(mod, "plugins/q", rc=1, counts={"passed": 1, "failed": 2, "errors": 1})]
    assert mod.report(bad, 2.0) == 1
    out = capsys.readouterr().out
    assert "failed: plugins/q" in out and "total: 6 passed, 3 failed, 1 skipped" in out


def test_sessions_run_side_by_side_and_each_output_is_printed_whole(tmp_path, capsys):
    """Each session waits for the other's flag: both pass only if they run at the same time."""
    mod = _run_tests_module()
    code = ("import sys, time, pathlib; me, other = sys.argv[1:]; d = pathlib.Path(sys.argv[0]).parent\n"
            "print(me + ' start', flush=True); (d / me).touch(); t = time.time()\n"
            "while not (d / other).exists() and time.time() - t < 60: time.sleep(0.05)\n"
            "time.sleep(0.3); print(me + ' end'); sys.exit(0 if (d / other).exists() else 3)\n")
    script = tmp_path / "meet.py"
    script.write_text(code)
    pair = [mod.Session(n, tmp_path, [sys.executable, str(script), n, o], pytest=False)
            for n, o in (("a", "b"), ("b", "a"))]
    done = mod.run_sessions(pair, jobs=2)
    assert [(s.name, s.rc) for s in done] == [("a", 0), ("b", 0)]
    out = capsys.readouterr().out
    for n in "ab":
        block = out[out.index(f"===== {n} ("):]
        assert block.split("\n")[1:3] == [f"{n} start", f"{n} end"], out


def test_the_sessions_share_a_fresh_fixture_folder_removed_at_the_end(monkeypatch):
    from twinkit.testing import CACHE_ENV

    mod = _run_tests_module()
    monkeypatch.delenv(CACHE_ENV, raising=False)
    with mod.shared_cache() as folder:
        assert os.environ[CACHE_ENV] == str(folder) and folder.is_dir() and not any(folder.iterdir())
        (folder / "site").mkdir()
        (folder / "site" / "cloud.ply").write_text("x")
        (folder / "site" / "cloud.ply").chmod(0o444)  # shared results are read-only
    assert CACHE_ENV not in os.environ and not folder.exists()


def test_a_fixture_folder_given_in_the_environment_is_used_and_kept(monkeypatch, tmp_path):
    from twinkit.testing import CACHE_ENV

    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    with _run_tests_module().shared_cache() as folder:
        assert folder == tmp_path
    assert os.environ[CACHE_ENV] == str(tmp_path) and tmp_path.is_dir()

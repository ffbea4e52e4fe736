"""twinkit.testing.shared_plugin_run: an expensive fixture computed once per test run, for every session."""
from __future__ import annotations

import os
import re
import subprocess
import sys

import twinkit.testing as T
from tests.conftest import ROOT
from tests.support import engine_plugins


def _use_make_step(monkeypatch, tmp_path):
    counter = tmp_path / "counter.txt"
    monkeypatch.setenv("TWINKIT_TEST_COUNTER", str(counter))
    monkeypatch.setattr(T, "installed_plugin", lambda kind, name: T.plugin_from_module(engine_plugins, kind, name))
    return counter


def test_the_same_parameters_run_once_and_share_read_only_files(monkeypatch, tmp_path):
    counter = _use_make_step(monkeypatch, tmp_path)
    monkeypatch.setenv(T.CACHE_ENV, str(tmp_path / "cache"))
    a = T.shared_plugin_run("step", "make", tmp_path / "a", value=7)
    b = T.shared_plugin_run("step", "make", tmp_path / "b", value=7)
    assert a == b and a["data.txt"].read_text() == "7\n"
    assert a["data.txt"].is_relative_to(tmp_path / "cache")
    assert not os.access(a["data.txt"], os.W_OK) or os.geteuid() == 0
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
    c = T.shared_plugin_run("step", "make", tmp_path / "c", value=8)  # other parameters: another result
    assert c["data.txt"].read_text() == "8\n" and c != a
    assert counter.read_text().split() == ["make", "make"]


def test_without_the_variable_each_caller_runs_into_its_own_folder(monkeypatch, tmp_path):
    counter = _use_make_step(monkeypatch, tmp_path)
    monkeypatch.delenv(T.CACHE_ENV, raising=False)
    a = T.shared_plugin_run("step", "make", tmp_path / "a", value=7)
    b = T.shared_plugin_run("step", "make", tmp_path / "b", value=7)
    assert a["data.txt"].is_relative_to(tmp_path / "a") and b["data.txt"].is_relative_to(tmp_path / "b")
    assert counter.read_text().split() == ["make", "make"]


def test_two_processes_at_once_compute_it_once(tmp_path):
    """Two sessions asking at the same time: the second waits for the first's result under the lock."""
    code = ("import sys, twinkit.testing as T; from tests.support import engine_plugins as E\n"
            "T.installed_plugin = lambda k, n: T.plugin_from_module(E, k, n)\n"
            "print(T.shared_plugin_run('step', 'make', sys.argv[1], value=5, sleep_s=1.0)['data.txt'])\n")
    env = dict(os.environ, TWINKIT_TEST_COUNTER=str(tmp_path / "counter.txt"), **{T.CACHE_ENV: str(tmp_path / "c")},
               PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    procs = [subprocess.Popen([sys.executable, "-c", code, str(tmp_path / w)], env=env, stdout=subprocess.PIPE,
                              text=True) for w in ("a", "b")]
    outs = [p.communicate(timeout=120)[0].strip() for p in procs]
    assert all(p.returncode == 0 for p in procs) and outs[0] == outs[1]
    assert (tmp_path / "counter.txt").read_text().split() == ["make"]


def _bench_module():
    import importlib.util

    spec = importlib.util.spec_from_file_location("twinkit_bench_slow_tests", ROOT / "bench" / "bench_slow_tests.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_every_test_make_test_skips_for_the_bench_is_run_by_the_bench():
    """A test marked bench_check() is skipped by make test: bench/bench_slow_tests.py must run it."""
    checks = _bench_module().CHECKS
    listed = {(ROOT / cwd / node.split("::")[0]).resolve(): node.split("::")[1].split("[")[0] for cwd, node in checks}
    marked = {f.resolve() for f in [*ROOT.glob("tests/**/test_*.py"), *ROOT.glob("plugins/*/tests/**/test_*.py")]
              if re.search(r"(@|marks=\[?)bench_check\(\)", f.read_text())}
    assert marked == set(listed), (marked, set(listed))
    for path, name in listed.items():
        assert f"def {name}(" in path.read_text(), (path, name)


def test_bench_checks_are_skipped_in_make_test_and_run_in_make_bench(monkeypatch):
    monkeypatch.delenv(T.BENCH_ENV, raising=False)
    mark = T.bench_check()
    assert mark.args[0] is True and "make bench" in mark.kwargs["reason"]
    monkeypatch.setenv(T.BENCH_ENV, "1")
    assert T.bench_check().args[0] is False

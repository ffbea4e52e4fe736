"""Run the static checks, then every test suite, each in its own session, and print one total.

First ``ruff check .`` (the rules in pyproject.toml's [tool.ruff]) and ``mypy`` (the core package, as
[tool.mypy] says), each a session of its own that fails the run like a failed test session, its output shown.
The framework's tests (tests/, examples/) run from the repository root; each plugin's tests run from
the plugin's folder, as a third-party package's would (they may import their own conftest helpers).

Sessions run side by side, ``--jobs N`` at a time (default: the machine's cores; ``--jobs 1`` runs them
one after the other; the ``TWINKIT_TEST_JOBS`` variable sets the default). The checks start first, then
the test sessions longest first (by :data:`TYPICAL_S`), so the long ones do not finish last. Each
session's output is captured and printed whole when it ends, with its time. The other arguments go to
every pytest session. Exit status is non-zero if any session failed: a check that failed, a pytest
session whose status is not 0 or 5 (no tests collected), or a core session with no tests.

Expensive fixtures that several sessions use (the small demo site) are built once per run: the sessions
share a fresh folder named by ``$TWINKIT_TEST_CACHE`` (``twinkit.testing.shared_plugin_run``), removed at
the end (one given in the environment is used and kept). Slow end-to-end checks are not here: they run in
``make bench`` (``bench/bench_slow_tests.py`` lists them).
"""
from __future__ import annotations

import contextlib
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable
COUNT = re.compile(r"(\d+) (passed|failed|skipped|errors?|xfailed|xpassed|deselected)")
CHECKS = [("ruff", ["-m", "ruff", "check", "."]), ("mypy", ["-m", "mypy"])]  # configured in pyproject.toml
CORE = "twinkit"
JOBS_ENV = "TWINKIT_TEST_JOBS"
#: the core's slowest tests (they run the demo site through the engine) in a session of their own, named
#: :data:`CORE_SPLIT_NAME`, so that the core is not one session twice as long as any other
CORE_SPLIT = ("tests/report", "tests/test_real_config.py")
CORE_SPLIT_NAME = "twinkit-demo-runs"
#: seconds each test session takes (2 cores, one session at a time); orders the sessions, longest first. From
#: the last CI's times less the tests moved to make bench and the demo site builds now shared (issue 48's
#: estimate: measure and update). A session not listed counts as :data:`UNKNOWN_S`.
TYPICAL_S = {CORE: 480, CORE_SPLIT_NAME: 180, "plugins/twinkit-export": 200, "plugins/twinkit-roads": 179,
             "plugins/twinkit-photo": 170, "plugins/twinkit-demo-site": 160, "plugins/twinkit-tiles": 110,
             "plugins/twinkit-efficientvit": 38, "plugins/twinkit-pointcloud": 38, "plugins/twinkit-segmentation": 21}
UNKNOWN_S = 60


@dataclass
class Session:
    """One command run from ``cwd``; ``rc``, ``out`` and ``seconds`` are filled when it has run."""

    name: str
    cwd: Path
    argv: list[str]
    pytest: bool = True
    rc: int | None = None
    out: str = ""
    seconds: float = 0.0
    counts: dict[str, int] = field(default_factory=dict)

    def failed(self) -> bool:
        """Whether this session fails the run (see the module docstring)."""
        if not self.pytest:
            return self.rc != 0
        return self.rc not in (0, 5) or (self.rc == 5 and self.name in (CORE, CORE_SPLIT_NAME))


def check_sessions() -> list[Session]:
    """The static checks (:data:`CHECKS`), each a session run from the repository root."""
    return [Session(name, ROOT, [PY, *args], pytest=False) for name, args in CHECKS]


def pytest_sessions(extra: list[str]) -> list[Session]:
    """The pytest sessions: the core's tests and examples (in two: :data:`CORE_SPLIT`'s paths in a session of
    their own), then each plugin's tests from its folder."""
    plugins = [d.parent for d in sorted(ROOT.glob("plugins/*/tests")) if d.is_dir()]
    split = [p for p in CORE_SPLIT if (ROOT / p).exists()]
    core = [(CORE, ["tests", "examples", *(f"--ignore={p}" for p in split)])]
    core += [(CORE_SPLIT_NAME, split)] if split else []
    out = [Session(name, ROOT, [PY, "-m", "pytest", *args, "-p", "no:cacheprovider", *extra]) for name, args in core]
    for cwd in plugins:
        out.append(Session(cwd.relative_to(ROOT).as_posix(), cwd,
                           [PY, "-m", "pytest", "tests", "-p", "no:cacheprovider", *extra]))
    return out


def ordered(checks: list[Session], tests: list[Session]) -> list[Session]:
    """The order sessions start in: the checks as given, then the tests longest first (stable for ties)."""
    return checks + sorted(tests, key=lambda s: -TYPICAL_S.get(s.name, UNKNOWN_S))


def summary_counts(out: str) -> dict[str, int]:
    """The counts on pytest's last summary line (``errors`` for ``error``/``errors``); empty if none."""
    lines = [l for l in out.splitlines() if COUNT.search(l) and (" in " in l or "no tests ran" in l)]
    counts: dict[str, int] = {}
    for n, kind in COUNT.findall(lines[-1] if lines else ""):
        kind = "errors" if kind.startswith("error") else kind
        counts[kind] = counts.get(kind, 0) + int(n)
    return counts


def _run(s: Session, lock: threading.Lock) -> Session:
    """Run one session, capturing its output, then print it whole under ``lock``."""
    t0 = time.perf_counter()
    p = subprocess.run(s.argv, cwd=s.cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    s.rc, s.out, s.seconds = p.returncode, p.stdout, time.perf_counter() - t0
    s.counts = summary_counts(s.out) if s.pytest else {}
    with lock:
        sys.stdout.write(f"\n===== {s.name} ({s.seconds:.0f} s) =====\n{s.out}")
        sys.stdout.flush()
    return s


def run_sessions(sessions: list[Session], jobs: int) -> list[Session]:
    """Run ``sessions`` in their order, ``jobs`` at a time; each is printed when it ends."""
    lock = threading.Lock()
    pool = ThreadPoolExecutor(max_workers=max(1, jobs))
    try:
        return list(pool.map(lambda s: _run(s, lock), sessions))
    finally:  # on Ctrl-C the running sessions stop with it; the waiting ones never start
        pool.shutdown(wait=True, cancel_futures=True)


def parse_jobs(argv: list[str]) -> tuple[int, list[str]]:
    """Take ``--jobs N`` / ``--jobs=N`` out of ``argv``: (jobs, the rest). Default: $TWINKIT_TEST_JOBS, else cores."""
    default = os.environ.get(JOBS_ENV) or str(os.cpu_count() or 1)
    jobs, rest, i = default, [], 0
    while i < len(argv):
        a = argv[i]
        if a == "--jobs" and i + 1 < len(argv):
            jobs, i = argv[i + 1], i + 2
            continue
        if a.startswith("--jobs="):
            jobs = a.split("=", 1)[1]
        else:
            rest.append(a)
        i += 1
    return max(1, int(jobs)), rest


def report(sessions: list[Session], minutes: float) -> int:
    """Print each session's status and time, then the totals; the exit status (1 if any session failed)."""
    print("\nsession                         rc      s")
    for s in sessions:
        print(f"{s.name:<30} {s.rc:>3} {s.seconds:>6.0f}{'  FAILED' if s.failed() else ''}")
    failed = [s.name for s in sessions if s.failed()]
    totals: dict[str, int] = {}
    for s in sessions:
        for kind, n in s.counts.items():
            totals[kind] = totals.get(kind, 0) + n
    print(f"\nsessions: {len(sessions)} in {minutes:.1f} min; failed: {', '.join(failed) or 'none'}")
    print(f"total: {totals.get('passed', 0)} passed, {totals.get('failed', 0) + totals.get('errors', 0)} failed, "
          f"{totals.get('skipped', 0)} skipped")
    return 1 if failed else 0


@contextlib.contextmanager
def shared_cache() -> Iterator[Path]:
    """The sessions' shared fixture folder in ``$TWINKIT_TEST_CACHE``: a fresh one, removed on exit, or the one
    the environment already names (kept)."""
    from twinkit.testing import CACHE_ENV

    given = os.environ.get(CACHE_ENV)
    if given:
        yield Path(given)
        return
    folder = tempfile.mkdtemp(prefix="twinkit-test-cache-")
    os.environ[CACHE_ENV] = folder
    try:
        yield Path(folder)
    finally:
        os.environ.pop(CACHE_ENV, None)
        shutil.rmtree(folder, ignore_errors=True)


def main() -> int:
    jobs, extra = parse_jobs(sys.argv[1:])
    t0 = time.perf_counter()
    print(f"{len(CHECKS)} checks and the test sessions, {jobs} at a time", flush=True)
    with shared_cache():
        sessions = run_sessions(ordered(check_sessions(), pytest_sessions(extra)), jobs)
    return report(sessions, (time.perf_counter() - t0) / 60)


if __name__ == "__main__":
    sys.exit(main())

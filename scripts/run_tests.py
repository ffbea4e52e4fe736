"""Run the static checks, then every test suite, each in its own session, and print one total.

First ``ruff check .`` (the rules in pyproject.toml's [tool.ruff]) and ``mypy`` (the core package, as
[tool.mypy] says), each a session of its own that fails the run like a failed test session, its output shown.
The framework's tests (tests/, examples/) run from the repository root; each plugin's tests run from
the plugin's folder, as a third-party package's would (they may import their own conftest helpers).
Extra arguments go to every pytest session. Exit status is non-zero if any session failed.
"""
from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable
COUNT = re.compile(r"(\d+) (passed|failed|skipped|errors?|xfailed|xpassed|deselected)")
CHECKS = [("ruff", ["-m", "ruff", "check", "."]), ("mypy", ["-m", "mypy"])]  # configured in pyproject.toml


def run_checks() -> list[str]:
    """Run the static checks from the repository root; the names of those that failed."""
    failed = []
    for name, args in CHECKS:
        print(f"\n===== {name} =====", flush=True)
        p = subprocess.run([PY, *args], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        sys.stdout.write(p.stdout)
        sys.stdout.flush()
        if p.returncode != 0:
            failed.append(name)
    return failed


def main() -> int:
    extra = sys.argv[1:]
    sessions = [(ROOT, ["tests", "examples"])]
    sessions += [(d.parent, ["tests"]) for d in sorted(ROOT.glob("plugins/*/tests")) if d.is_dir()]
    totals: dict[str, int] = {}
    t0 = time.perf_counter()
    failed_sessions = run_checks()
    for cwd, args in sessions:
        name = cwd.relative_to(ROOT).as_posix() if cwd != ROOT else "twinkit"
        print(f"\n===== {name} =====", flush=True)
        p = subprocess.run([PY, "-m", "pytest", *args, "-p", "no:cacheprovider", *extra], cwd=cwd,
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        sys.stdout.write(p.stdout)
        sys.stdout.flush()
        summary = [l for l in p.stdout.splitlines() if COUNT.search(l) and (" in " in l or "no tests ran" in l)]
        for n, kind in COUNT.findall(summary[-1] if summary else ""):
            kind = "errors" if kind.startswith("error") else kind
            totals[kind] = totals.get(kind, 0) + int(n)
        if p.returncode not in (0, 5) or (p.returncode == 5 and name == "twinkit"):
            failed_sessions.append(name)
    minutes = (time.perf_counter() - t0) / 60
    print(f"\nsessions: {len(CHECKS) + len(sessions)} in {minutes:.1f} min; failed: {', '.join(failed_sessions) or 'none'}")
    print(f"total: {totals.get('passed', 0)} passed, {totals.get('failed', 0) + totals.get('errors', 0)} failed, "
          f"{totals.get('skipped', 0)} skipped")
    return 1 if failed_sessions else 0


if __name__ == "__main__":
    sys.exit(main())

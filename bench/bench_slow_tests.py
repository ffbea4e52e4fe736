"""The slow end-to-end checks: tests that ``make test`` skips (``twinkit.testing.bench_check``) and ``make bench``
runs, each in its own pytest session from its package's folder, as in ``make test``. A fast test of the same
behaviour stays in the suite; these check it on the whole demo site.

    .venv/bin/python bench/bench_slow_tests.py [name-filter]

Prints a Markdown table (test, seconds, result); the exit status is 1 if one failed.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from twinkit.testing import BENCH_ENV  # noqa: E402

#: (folder the session runs from, relative to the repository root; the test's node id there)
CHECKS = [
    (".", "tests/test_real_config.py::test_demo_site_end_to_end_then_reused[efficientvit_b0]"),
    ("plugins/twinkit-photo", "tests/test_demo_photos.py::test_demo_photos_register_and_georeference_within_5cm"),
    ("plugins/twinkit-tiles", "tests/test_demo_site.py::test_tiled_segment_recipe_on_small_demo_site"),
]


def run(cwd: str, node: str) -> tuple[float, int, str]:
    """(seconds, pytest's exit status, its last lines) of one check."""
    env = dict(os.environ, **{BENCH_ENV: "1"})
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "pytest", node, "-q", "-p", "no:cacheprovider", "-rs"], cwd=ROOT / cwd,
                       env=env, capture_output=True, text=True)
    return time.perf_counter() - t0, p.returncode, (p.stdout + p.stderr)[-3000:]


def main() -> int:
    filt = sys.argv[1] if len(sys.argv) > 1 else ""
    rows, failed = [], []
    for cwd, node in CHECKS:
        if filt not in node:
            continue
        seconds, rc, tail = run(cwd, node)
        last = tail.strip().splitlines()[-1] if tail.strip() else ""
        result = "FAILED" if rc != 0 else "skipped" if "skipped" in last else "passed"  # skipped: data absent
        if rc != 0:
            failed.append(node)
            print(tail, file=sys.stderr)
        rows.append(f"| {cwd}/{node} | {seconds:.0f} | {result} |")
    print("| test | seconds | result |\n|---|---|---|\n" + "\n".join(rows))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

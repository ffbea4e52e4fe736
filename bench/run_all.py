"""Run every benchmark (bench/bench_*.py and plugins/*/bench/bench_*.py), print their tables,
and keep each output in bench/results/<name>.md.

Run: make bench   (or .venv/bin/python bench/run_all.py [name-filter])
"""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    filt = sys.argv[1] if len(sys.argv) > 1 else ""
    scripts = sorted((ROOT / "bench").glob("bench_*.py")) + sorted(ROOT.glob("plugins/*/bench/bench_*.py"))
    results = ROOT / "bench" / "results"
    results.mkdir(parents=True, exist_ok=True)
    failed = []
    for script in scripts:
        if filt and filt not in script.name:
            continue
        print(f"\n# {script.relative_to(ROOT)}\n", flush=True)
        t0 = time.perf_counter()
        p = subprocess.run([sys.executable, str(script)], cwd=ROOT, capture_output=True, text=True)
        print(p.stdout, flush=True)
        if p.returncode != 0:
            print(p.stderr[-4000:], file=sys.stderr)
            failed.append(script.name)
        (results / f"{script.stem}.md").write_text(p.stdout)
        print(f"({script.name}: {time.perf_counter() - t0:.0f} s)")
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())

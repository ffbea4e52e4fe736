"""Engine overhead: a 200-step recipe with about 1 GB of artefacts.

Prints a Markdown table: first run, second run with nothing changed (target < 2 s,
no file re-hashed), and the sha256 throughput of the first-run hashing.
Run: .venv/bin/python bench/bench_engine.py [--steps 200] [--size-mb 5]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--size-mb", type=float, default=5.0)
    ap.add_argument("--keep", action="store_true")
    a = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="twinkit-bench-"))
    conf = tmp / "conf"
    (conf / "site").mkdir(parents=True)
    (conf / "recipe").mkdir()
    shutil.copy(ROOT / "conf" / "config.yaml", conf / "config.yaml")
    (conf / "site" / "bench.yaml").write_text("name: bench\n")
    steps = "\n".join(
        f"    - {{id: s{i:03d}, uses: step/blob, params: {{index: {i}, size_mb: {a.size_mb}}}}}" for i in range(a.steps)
    )
    (conf / "recipe" / "big.yaml").write_text(f"# @package _global_\nrecipe:\n  name: big\n  steps:\n{steps}\n")
    env = dict(os.environ, TWINKIT_CONFIG_DIR=str(conf), TWINKIT_PLUGINS="builtins",
               TWINKIT_PLUGIN_MODULES="engine_bench_plugins",
               PYTHONPATH=f"{ROOT / 'bench'}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    out = tmp / "outputs"
    cmd = [sys.executable, "-m", "twinkit", "site=bench", "recipe=big", f"engine.outputs_dir={out}",
           "engine.report=false"]
    db = out / "bench" / ".cache" / "hashes.sqlite"

    def run() -> tuple[float, float, str]:
        t0 = time.perf_counter()
        p = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=tmp)
        wall = time.perf_counter() - t0
        if p.returncode != 0:
            print(p.stderr[-3000:], file=sys.stderr)
            raise SystemExit("benchmark run failed")
        run_dir = sorted((out / "bench" / "runs").iterdir())[-1]
        return wall, json.loads((run_dir / "manifest.json").read_text())["duration_s"], p.stderr

    def rows() -> int:
        with sqlite3.connect(db) as c:
            return c.execute("SELECT COUNT(*) FROM hashes").fetchone()[0]

    wall1, eng1, _ = run()
    total = sum(f.stat().st_size for f in (out / "bench").glob("[0-9]*/*.bin"))
    rows1 = rows()
    wall2, eng2, log2 = run()
    rows2 = rows()
    reused = log2.count(" reused ")
    # first-run hashing throughput: sha256 over the same artefacts with a cold cache
    from twinkit.hashing import HashCache

    files = sorted((out / "bench" / ".cache" / "steps").glob("*/blob.bin"))
    cold = HashCache(None)
    t0 = time.perf_counter()
    for f in files:
        cold.hash(f)
    hash_s = time.perf_counter() - t0
    mbps = cold.bytes_hashed / 2**20 / hash_s
    print(f"## Engine overhead ({a.steps} steps, {total / 2**30:.2f} GiB of artefacts, {os.cpu_count()} cores)\n")
    print("| run | wall-clock (CLI, s) | engine (s) | files re-hashed | steps reused |")
    print("|---|---:|---:|---:|---:|")
    print(f"| first | {wall1:.2f} | {eng1:.2f} | {rows1} hashed once | 0 |")
    print(f"| second, nothing changed | {wall2:.2f} | {eng2:.2f} | {rows2 - rows1} | {reused}/{a.steps} |")
    print(f"\nsha256 throughput (first-run hashing, cold cache): **{mbps:.0f} MB/s** "
          f"({cold.bytes_hashed / 2**20:.0f} MiB in {hash_s:.2f} s)")
    print(f"\nTarget: second run < 2 s with no file re-hashed -> "
          f"{'PASS' if wall2 < 2 and rows2 == rows1 else 'FAIL'}")
    if not a.keep:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The thread budget: two runs at once on one machine, sharing the cores or each taking all of them.

A two-step recipe multiplies matrices with numpy's BLAS (its pool set to the step's ``ctx.threads``).
Prints a Markdown table of seconds per product in the second step (by then both runs have
registered; a step already running keeps the threads it started with): one run alone; two runs at
once with the budget (each takes cores / 2); two runs at once each taking every core
(``engine.threads=<cores>``, as before the budget).
Run: .venv/bin/python bench/bench_threads.py [--n 600] [--repeats 40]
"""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=600)
    ap.add_argument("--repeats", type=int, default=40)
    a = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="twinkit-bench-threads-"))
    conf = tmp / "conf"
    (conf / "site").mkdir(parents=True)
    (conf / "recipe").mkdir()
    shutil.copy(ROOT / "conf" / "config.yaml", conf / "config.yaml")
    for s in ("a", "b"):
        (conf / "site" / f"{s}.yaml").write_text(f"name: {s}\n")
    (conf / "recipe" / "mm.yaml").write_text("# @package _global_\nrecipe:\n  name: mm\n  steps:\n"
                                             "    - {id: m1, uses: step/matmul}\n"
                                             "    - {id: m2, uses: step/matmul, params: {index: 1}}\n")
    env = dict(os.environ, TWINKIT_CONFIG_DIR=str(conf), TWINKIT_PLUGINS="builtins",
               TWINKIT_PLUGIN_MODULES="engine_bench_plugins", TWINKIT_RUNTIME_DIR=str(tmp / "runtime"),
               PYTHONPATH=f"{ROOT / 'bench'}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    cores = len(os.sched_getaffinity(0))

    def runs(n: int, *extra: str, tag: str) -> list[tuple[float, int]]:
        procs = []
        for i, site in enumerate("ab"[:n]):
            out = tmp / f"out-{tag}"
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "twinkit", f"site={site}", "recipe=mm", f"engine.outputs_dir={out}",
                 "engine.report=false", f"steps.matmul.n={a.n}", f"steps.matmul.repeats={a.repeats}",
                 *extra],
                env=env, cwd=tmp, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
        res = []
        for site, p in zip("ab", procs):
            _, err = p.communicate()
            if p.returncode != 0:
                raise SystemExit(err[-2000:])
            per, threads = (tmp / f"out-{tag}" / site / "02_m2" / "timing.txt").read_text().split()
            res.append((float(per), int(threads)))
        return res

    rows = [("one run alone", runs(1, tag="alone")),
            ("two runs at once, shared budget", runs(2, tag="budget")),
            (f"two runs at once, each engine.threads={cores}", runs(2, f"engine.threads={cores}", tag="all"))]
    print(f"## Two runs on one machine ({cores} cores, {a.n}x{a.n} products)\n")
    print("| case | threads per run | s per product (each run) |")
    print("|---|---:|---:|")
    for name, res in rows:
        print(f"| {name} | {', '.join(str(t) for _, t in res)} | {', '.join(f'{p:.4f}' for p, _ in res)} |")
    shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

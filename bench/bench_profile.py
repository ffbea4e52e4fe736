"""Where the demo spends its time and memory, per step and substep (issue 48: every speed claim starts here).

    .venv/bin/python bench/bench_profile.py [--sizes small,default] [--seed 0] [--run DIR] [--keep DIR]

Runs ``twinkit recipe=pointcloud_site site=demo site.size=<size>`` into a fresh outputs folder (so that every
step computes: nothing comes from the cache), prints the table step / substep / seconds / peak MB / share of the
run (``twinkit.profile``), the run's wall and CPU seconds and the load average, writes
``bench/results/profile_demo_<size>.json`` and prints the change against the previous one (kept as
``profile_demo_<size>.prev.json``). The outputs folder is removed afterwards unless ``--keep`` names one.

``make bench`` runs the small size only (about 7-10 min on a 2-core machine, the size ``make demo`` runs and
issue 48's 180 s target is set on); the default size takes about 15 min more: ``--sizes small,default`` or
``TWINKIT_BENCH_PROFILE_SIZES=small,default``. ``--run DIR`` reads a finished run (a site folder such as
``outputs/demo`` or a run folder under ``runs/``) instead of running one; ``twinkit profile DIR`` prints the
same table without keeping it.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from twinkit.profile import profile_delta, profile_table, read_profile  # noqa: E402

RESULTS = ROOT / "bench" / "results"


def run_demo(size: str, seed: int, outputs: Path) -> tuple[Path, dict]:
    """One fresh demo run of ``size`` into ``outputs``: (the site folder, wall / CPU seconds, load, exit status)."""
    cmd = [sys.executable, "-m", "twinkit", "recipe=pointcloud_site", "site=demo", f"site.size={size}",
           f"site.seed={seed}", f"engine.outputs_dir={outputs}"]
    load0 = os.getloadavg()
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode not in (0, 4):  # 4: finished with a degraded result (the profile is still whole)
        sys.stderr.write(p.stdout[-3000:] + p.stderr[-3000:])
    run = {"wall_s": round(wall, 1), "cpu_s": round(ru1.ru_utime + ru1.ru_stime - ru0.ru_utime - ru0.ru_stime, 1),
           "max_rss_mb": round(ru1.ru_maxrss / 1024, 1), "load_before": [round(x, 2) for x in load0],
           "load_after": [round(x, 2) for x in os.getloadavg()], "exit": p.returncode, "cpus": os.cpu_count()}
    return outputs / "demo", run


def keep(profile: dict, size: str) -> dict | None:
    """Write ``profile_demo_<size>.json`` (the previous one becomes ``.prev.json``); returns the previous one."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"profile_demo_{size}.json"
    prev = None
    if path.is_file():
        try:
            prev = json.loads(path.read_text())
        except ValueError:
            prev = None
        shutil.copyfile(path, path.with_suffix(".prev.json"))
    path.write_text(json.dumps(profile, indent=1) + "\n")
    return prev


def profile_size(size: str, seed: int, run_dir: Path | None, keep_dir: Path | None) -> int:
    """Run (or read) one size, print its table and the change from the last one; the exit status."""
    tmp = None
    info: dict = {}
    if run_dir is None:
        out = keep_dir / size if keep_dir else Path(tempfile.mkdtemp(prefix=f"twinkit-profile-{size}-"))
        tmp = None if keep_dir else out
        if out.exists() and keep_dir:
            shutil.rmtree(out)  # a fresh folder: every step computes
        run_dir, info = run_demo(size, seed, out)
    try:
        profile = read_profile(run_dir)
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    if not profile["steps"]:
        print(f"{run_dir}: no step ran", file=sys.stderr)
        return 1
    profile.update(size=size, seed=seed, run=info, git=_git(), recorded_at=time.strftime("%Y-%m-%dT%H:%M:%S%z"))
    print(f"## demo {size}, seed {seed}\n")
    if info:
        print(f"run: {info['wall_s']:.0f} s wall, {info['cpu_s']:.0f} s CPU on {info['cpus']} CPUs, largest process "
              f"{info['max_rss_mb']:.0f} MB; load average {info['load_before'][0]:.1f} before, "
              f"{info['load_after'][0]:.1f} after (1 min); exit {info['exit']}\n")
    print("```\n" + profile_table(profile) + "\n```\n")
    prev = keep(profile, size)
    if prev is not None:
        print(f"change from the previous profile ({prev.get('recorded_at', '?')}, {prev.get('git', '?')}):\n")
        print("```\n" + profile_delta(prev, profile) + "\n```\n")
    return 0 if info.get("exit", 0) in (0, 4) else 1


def _git() -> str:
    try:
        return subprocess.run(["git", "describe", "--always", "--dirty"], cwd=ROOT, capture_output=True,
                              text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "?"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default=os.environ.get("TWINKIT_BENCH_PROFILE_SIZES", "small"),
                    help="demo sizes, comma-separated (small, default, large)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--run", type=Path, default=None, help="read this finished run instead of running one")
    ap.add_argument("--keep", type=Path, default=None, help="keep the run's outputs under this folder")
    a = ap.parse_args()
    sizes = [s.strip() for s in a.sizes.split(",") if s.strip()]
    if a.run is not None and len(sizes) != 1:
        ap.error("--run reads one run: give its size with --sizes")
    rc = 0
    for size in sizes:
        rc = max(rc, profile_size(size, a.seed, a.run, a.keep))
    return rc


if __name__ == "__main__":
    sys.exit(main())

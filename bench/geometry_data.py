"""The demo-made training captures of the 3D classifier (docs/segmentation.md "3D classifier").

    python bench/geometry_data.py --out DIR

writes ``DIR/demo_mobile/seed<S>.npz`` (the demo's mobile-mapping scan of the ``small`` site of seed S at a
density drawn from the seed, 0.2-2x) and ``DIR/velo/velo_seed<S>_<k>.npz`` (single sweeps of a spinning
multi-beam sensor, 32/64/128 beams, from random places on the scanner van's passes, in the sensor's
frame). Each holds ``xyz`` (n, 3) float32 metres and ``label`` (n,) uint8 trainIds; no intensity (the demo's
is its colour's brightness, not a reflectance). Together with scansim's captures
(``python -m twinkit_demo_site.captures``) they are ``python -m twinkit_segmentation.geometry.train``'s data.
Demo seeds 0, 1, 3 and 7 are left out by default (the demo's benchmark seeds and the fusion's calibration
seed).
"""
from __future__ import annotations

import argparse
import math
import random
from pathlib import Path

import numpy as np


def _seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in filter(None, text.split(",")):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b or a) + 1))
    return out


def _site(seed: int):
    from twinkit_demo_site.layout import build_scene
    from twinkit_demo_site.plugin import PRESETS
    from twinkit_demo_site.raycast import Tracer
    from twinkit_demo_site.textures import build_atlas

    atlas = build_atlas(seed)
    scene = build_scene(PRESETS["small"]["half_m"], seed, atlas)
    return scene, Tracer(scene.mesh, atlas, threads=1, weathering=0.0, seed=seed)


def mobile(seed: int, out: Path) -> None:
    """The demo's own mobile scan of seed ``seed`` at a seeded density in 0.2..2x."""
    from twinkit_demo_site.plugin import PRESETS
    from twinkit_demo_site.scanner import ScanSettings, scan, trajectory

    random.seed(seed)
    dens = round(10 ** random.uniform(-0.7, 0.3), 2)
    pre = PRESETS["small"]
    scene, tracer = _site(seed)
    d = math.sqrt(dens)
    s = ScanSettings(profile_spacing_m=pre["profile_spacing_m"] / d, rays_per_profile=int(round(pre["rays_per_profile"] * d)))
    traj = trajectory(scene, s, np.random.default_rng([seed, 2]))
    chunks = list(scan(scene, tracer, s, traj, np.random.default_rng([seed, 3])))
    xyz = np.concatenate([c.xyz for c in chunks]).astype(np.float32)
    label = np.concatenate([c.label for c in chunks])
    np.savez_compressed(out / f"seed{seed}.npz", xyz=xyz, label=label)


def spinning(seed: int, n_scans: int, out: Path) -> None:
    """``n_scans`` single sweeps of a spinning sensor at random places on the van's passes of seed ``seed``."""
    from twinkit_demo_site.scanner import ScanSettings, trajectory

    rng = np.random.default_rng([seed, 77])
    scene, tracer = _site(seed)
    traj = trajectory(scene, ScanSettings(profile_spacing_m=0.5, rays_per_profile=10), np.random.default_rng([seed, 2]))
    for k in range(n_scans):
        i = rng.integers(len(traj["xyz"]))
        h = rng.uniform(1.6, 2.0)
        org = traj["xyz"][i].copy()
        org[2] += h - 2.0  # the van's scanner is 2 m above the road
        kind = rng.integers(3)
        el = (np.linspace(2.0, -24.8, 64), np.linspace(10.0, -30.0, 32), np.linspace(15.0, -25.0, 128))[kind]
        naz = int(rng.choice([1024, 2048, 4000]))
        az = (np.arange(naz) / naz + rng.random() / naz) * 2 * math.pi
        E, Az = np.meshgrid(np.radians(el + rng.normal(0, 0.05, len(el))), az, indexing="ij")
        dirs = np.stack([np.cos(E) * np.cos(Az), np.cos(E) * np.sin(Az), np.sin(E)], -1).reshape(-1, 3)
        o = np.broadcast_to(org, dirs.shape)
        t, prim, _ = tracer.cast(o.astype(np.float32), dirs.astype(np.float32))
        t = t.astype(np.float64)
        hit = (prim >= 0) & (t < 80) & (t > 2.5)
        hit &= rng.random(len(t)) < 1.0 - 0.5 * np.clip(t / 80, 0, 1) ** 1.5
        sel = np.flatnonzero(hit)
        noise_m = rng.uniform(0.005, 0.03)
        tr = t[sel] + np.clip(rng.standard_normal(len(sel)), -3, 3) * noise_m
        pts = org + dirs[sel] * tr[:, None]
        lab = tracer.face_labels[prim[sel]]
        np.savez_compressed(out / f"velo_seed{seed}_{k}.npz", xyz=(pts - org).astype(np.float32), label=lab.astype(np.uint8))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--mobile-seeds", default="2,4-6,8-12,20-22")
    ap.add_argument("--spinning-seeds", default="2,4-6,8-10")
    ap.add_argument("--spinning-per-seed", type=int, default=4)
    a = ap.parse_args(argv)
    out = Path(a.out)
    (out / "demo_mobile").mkdir(parents=True, exist_ok=True)
    (out / "velo").mkdir(parents=True, exist_ok=True)
    for s in _seeds(a.mobile_seeds):
        mobile(s, out / "demo_mobile")
        print("mobile", s, flush=True)
    for s in _seeds(a.spinning_seeds):
        spinning(s, a.spinning_per_seed, out / "velo")
        print("spinning", s, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

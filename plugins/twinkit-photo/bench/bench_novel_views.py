"""Leave-one-out novel views: how well a photo run's textured mesh explains photos it was not built from.

    .venv/bin/python plugins/twinkit-photo/bench/bench_novel_views.py --run outputs/<site> [--every 5]
        [--photos <folder>] [--out /tmp/novel] [--max-px 640] [--dense-px N]

The real-data check of view synthesis where no ground truth exists. From a finished ``image_site`` run folder
(``outputs/<site>``, with its sfm/georeference/roi step folders) it

1. holds out every ``--every``-th registered photo (1-based: the 5th, 10th, ...) of ``cameras_site.json``;
2. builds the mesh and texture again from the rest only: the dense step with the kept cameras, then Poisson,
   clean_mesh, simplify, bake_texture and photo_texture -- the image_site recipe's chain with the
   parameters the run used (read from each step folder's ``step.json``), through the installed plugins
   (twinkit.testing.run_plugin);
   the poses come from the full run's sfm, so a held-out photo has a pose but gave no pixel to the model;
3. renders that mesh at each held-out photo's pose (Open3D ray casting, ``--supersample`` x ``--supersample``
   rays per pixel, their texels averaged) and compares with the photo at ``--max-px`` (long side):

   * ``covered_below_horizon``: the share of the photo's pixels whose ray points below the horizontal (the
     street and the lower facades; the sky and roofs above the camera do not count) that hit the mesh;
   * ``psnr_db``: PSNR of the rendering against the photo on the covered pixels (8-bit RGB);
   * ``covered_all``: the share of all pixels that hit the mesh.

Targets of issue 24 (Lund, defaults): covered_below_horizon >= 60 %, PSNR >= 18 dB. Prints a markdown table
and writes ``novel_views.json`` (and a side-by-side PNG per held-out photo) into ``--out``. Heavy: it runs
the dense step and the mesh chain once (minutes on 2 cores).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[3]


def _latest(run: Path, name: str) -> Path:
    hits = sorted(run.glob(f"[0-9][0-9]_*/{name}"))
    if not hits:
        sys.exit(f"{run}: no step folder holds {name}; give the outputs/<site> folder of a finished image_site run")
    return hits[-1]


def _photos_dir(run: Path, given: str | None) -> Path:
    if given:
        return Path(given)
    for mf in sorted(run.glob("runs/*/manifest.json"), reverse=True):
        try:
            d = json.loads(mf.read_text())
        except (OSError, ValueError):
            continue
        p = (((d.get("config") or {}).get("site") or {}).get("inputs") or {}).get("photos")
        if isinstance(p, str) and Path(p).is_dir():
            return Path(p)
    for cand in run.glob("[0-9][0-9]_*/photos"):
        if cand.is_dir():
            return cand
    sys.exit(f"{run}: cannot find the photos folder in the run's manifest; give --photos")


def render(mesh, tex: np.ndarray, cam: dict, max_px: int, max_dist: float = 0.0, supersample: int = 1):
    """(rgb (h, w, 3) float, hit mask (h, w), ray directions (h, w, 3) in the site frame) of a textured mesh
    seen from a camera of cameras_site.json (OpenCV pinhole, K at full photo size), at ``max_px`` long side.

    ``supersample`` n: n x n rays per pixel, their texels averaged (a pixel is covered where most of its rays
    hit). A renderer filters a texture it shows smaller than its texels (mipmaps); one nearest texel per pixel
    aliases the far street, while the photo it is compared with is area-filtered down to ``max_px``."""
    import open3d as o3d

    W, H = int(cam["width"]), int(cam["height"])
    s = min(1.0, max_px / float(max(W, H)))
    w, h = int(round(W * s)), int(round(H * s))
    n = max(1, int(supersample))
    K = np.diag([w / W, h / H, 1.0]) @ np.asarray(cam["K"], float)
    R = np.asarray(cam["R_world_from_camera"], float)
    C = np.asarray(cam["center"], float)
    if n > 1:  # the ray of sub-pixel (a, b) of pixel (x, y) goes through (x + (a + 0.5) / n, y + (b + 0.5) / n)
        K = np.diag([float(n), float(n), 1.0]) @ K
        w, h = w * n, h * n
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    d_cam = np.stack([u, v, np.ones_like(u)], -1) @ np.linalg.inv(K).T
    d = d_cam @ R.T
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, np.float32)),
                        o3d.core.Tensor(np.asarray(mesh.faces, np.uint32)))
    rays = np.concatenate([np.broadcast_to(C, d.shape), d], -1).astype(np.float32)
    ans = scene.cast_rays(o3d.core.Tensor(rays))
    t = ans["t_hit"].numpy()
    fid = ans["primitive_ids"].numpy().astype(np.int64)
    bary = ans["primitive_uvs"].numpy()
    hit = np.isfinite(t)
    if max_dist > 0:
        hit &= t <= max_dist
    rgb = np.zeros((h, w, 3), np.float32)
    uv = np.asarray(mesh.face_attrs["texcoord"], np.float64).reshape(-1, 3, 2)
    f = fid[hit]
    b1, b2 = bary[hit, 0], bary[hit, 1]
    tc = (1 - b1 - b2)[:, None] * uv[f, 0] + b1[:, None] * uv[f, 1] + b2[:, None] * uv[f, 2]
    th, tw = tex.shape[:2]
    x = np.clip(tc[:, 0] * tw - 0.5, 0, tw - 1).round().astype(int)
    y = np.clip((1 - tc[:, 1]) * th - 0.5, 0, th - 1).round().astype(int)
    rgb[hit] = tex[y, x, :3]
    if n > 1:
        h, w = h // n, w // n
        cnt = hit.reshape(h, n, w, n).sum((1, 3))
        rgb = (rgb * hit[..., None]).reshape(h, n, w, n, 3).sum((1, 3)) / np.maximum(cnt, 1)[..., None]
        hit = cnt * 2 > n * n
        d = d.reshape(h, n, w, n, 3).mean((1, 3))
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return rgb, hit, d


def compare(photo: np.ndarray, rgb: np.ndarray, hit: np.ndarray, dirs: np.ndarray) -> dict:
    below = dirs[..., 2] < 0
    cov_below = float((hit & below).sum() / max(1, below.sum()))
    if hit.any():
        mse = float(np.mean((photo[hit].astype(np.float64) - rgb[hit]) ** 2))
        psnr = 10 * np.log10(255.0 ** 2 / max(mse, 1e-9))
    else:
        mse, psnr = float("nan"), float("nan")
    return {"covered_below_horizon": round(cov_below, 4), "covered_all": round(float(hit.mean()), 4),
            "psnr_db": round(float(psnr), 2), "covered_px": int(hit.sum()), "mse": mse}


# --param overrides: {plugin: {name: value}}, applied over the run's own parameters
OVERRIDES: dict[str, dict] = {}


def _run_params(run: Path, plugin: str) -> dict:
    """The parameters the run's ``plugin`` step used (its step folder's step.json), so the rebuild measures
    the run's own settings (e.g. ``steps.dense.cpu_method=patchmatch``), not the plugins' defaults; then the
    bench's ``--param`` overrides for that plugin (to measure today's default on an older run)."""
    for step in sorted(run.glob("[0-9][0-9]_*/step.json"), reverse=True):
        try:
            doc = json.loads(step.read_text())
        except (OSError, ValueError):
            continue
        if doc.get("plugin") == plugin:
            return {**dict(doc.get("params") or {}), **OVERRIDES.get(plugin, {})}
    print(f"warning: {run} has no {plugin} step; its defaults are used", flush=True)
    return dict(OVERRIDES.get(plugin, {}))


def _parse_override(text: str) -> tuple[str, str, object]:
    """``step/photo_texture.max_views=6`` -> ("step/photo_texture", "max_views", 6) (the value read as YAML)."""
    import yaml

    key, sep, value = text.partition("=")
    plugin, dot, name = key.rpartition(".")
    if not sep or not dot or not plugin or not name:
        sys.exit(f"--param {text!r}: write it as kind/plugin.name=value, e.g. step/photo_texture.max_views=6")
    return plugin, name, yaml.safe_load(value)


def build_from_rest(run: Path, photos: Path, keep: list[dict], cams_doc: dict, out: Path, dense_px: int) -> Path:
    """dense -> poisson -> clean -> simplify -> bake -> photo_texture from the kept cameras, each with the
    run's parameters; returns the textured mesh (PLY with per-face texcoords beside its PNG)."""
    from twinkit.testing import run_plugin

    cams_rest = out / "cameras_rest.json"
    cams_rest.write_text(json.dumps(dict(cams_doc, cameras=keep)))
    sparse = _latest(run, "sparse_site.ply")
    roi = _latest(run, "roi.json")
    georef = _latest(run, "georef.json")
    sfm = _latest(run, "sfm_report.json").parent / "sfm"
    over = _run_params(run, "step/dense")
    if dense_px:
        over["max_image_px"] = dense_px
    print("dense: " + ", ".join(f"{k}={v}" for k, v in sorted(over.items())), flush=True)
    inputs = {"in_photos_dir": photos, "in_cameras_site_json": cams_rest, "in_sparse_site_ply": sparse,
              "in_roi_json": roi}
    if sfm.is_dir():
        inputs.update({"in_sfm_dir": sfm, "in_georef_json": georef})
    inputs["in_sfm_report_json"] = _latest(run, "sfm_report.json")
    t = time.perf_counter()
    d = run_plugin("step", "dense", out / "dense", inputs, **over)
    print(f"dense from {len(keep)} photos: {time.perf_counter() - t:.0f} s", flush=True)
    m = run_plugin("reconstructor", "poisson", out / "poisson", {"in_points_ply": d["points.ply"]},
                   **_run_params(run, "reconstructor/poisson"))
    c = run_plugin("step", "clean_mesh", out / "clean", {"in_dense_mesh_ply": m["dense_mesh.ply"],
                                                         "in_points_ply": d["points.ply"]},
                   **_run_params(run, "step/clean_mesh"))
    s = run_plugin("step", "simplify", out / "simplify", {"in_clean_mesh_ply": c["clean_mesh.ply"]},
                   **_run_params(run, "step/simplify"))
    b = run_plugin("step", "bake_texture", out / "bake", {"in_mesh_ply": s["mesh.ply"],
                                                          "in_clean_mesh_ply": c["clean_mesh.ply"]},
                   **_run_params(run, "step/bake_texture"))
    p = run_plugin("step", "photo_texture", out / "phototex", {"in_textured_mesh_ply": b["textured_mesh.ply"],
                                                               "in_photos_dir": photos,
                                                               "in_cameras_site_json": cams_rest},
                   **_run_params(run, "step/photo_texture"))
    print(f"mesh chain done: {time.perf_counter() - t:.0f} s", flush=True)
    return p["textured_mesh.ply"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", help="outputs/<site> of a finished image_site run")
    ap.add_argument("--photos", help="the photos folder (default: from the run's manifest)")
    ap.add_argument("--every", type=int, default=5, help="hold out every N-th photo (default 5)")
    ap.add_argument("--out", default="/tmp/twinkit_novel_views")
    ap.add_argument("--max-px", type=int, default=640, help="comparison resolution, long side")
    ap.add_argument("--dense-px", type=int, default=0, help="dense.max_image_px (0: the step's default)")
    ap.add_argument("--mesh", help="skip the rebuild: evaluate this textured mesh PLY (e.g. one built before)")
    ap.add_argument("--supersample", type=int, default=3,
                    help="rays per pixel side, averaged (default 3: the render filtered as the photo is; 1: one "
                         "nearest texel per pixel, as the bench measured until 28 Nov 2026: about 0.3 dB lower on Lund)")
    ap.add_argument("--param", action="append", default=[], metavar="KIND/PLUGIN.NAME=VALUE",
                    help="override a parameter the run used, for the rebuild (repeatable), e.g. "
                         "step/photo_texture.max_views=6: measures a newer default on an older run")
    a = ap.parse_args(argv)
    for text in a.param:
        plugin, name, value = _parse_override(text)
        OVERRIDES.setdefault(plugin, {})[name] = value
    if not a.run:  # make bench runs every script bare: this one needs a finished run to measure
        print("bench_novel_views: no run folder given (--run outputs/<site> of a finished image_site run); "
              "nothing measured")
        return 0
    from PIL import Image
    from twinkit.mesh import read_ply

    run, out = Path(a.run), Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    photos = _photos_dir(run, a.photos)
    cams_doc = json.loads(_latest(run, "cameras_site.json").read_text())
    cams = sorted(cams_doc["cameras"], key=lambda c: c["image"])
    held = [c for k, c in enumerate(cams) if (k + 1) % a.every == 0]
    keep = [c for k, c in enumerate(cams) if (k + 1) % a.every != 0]
    if not held or len(keep) < 3:
        sys.exit(f"{len(cams)} cameras: too few to hold out every {a.every}th")
    print(f"{len(cams)} cameras; held out: {', '.join(c['image'] for c in held)}", flush=True)
    mesh_path = Path(a.mesh) if a.mesh else build_from_rest(run, photos, keep, cams_doc, out, a.dense_px)
    mesh = read_ply(mesh_path)
    png = next((c.split(None, 1)[1] for c in mesh.comments if c.startswith("TextureFile")), mesh_path.stem + ".png")
    tex = np.asarray(Image.open(mesh_path.parent / png).convert("RGB"), np.float32)
    rows = []
    for c in held:
        rgb, hit, dirs = render(mesh, tex, c, a.max_px, supersample=a.supersample)
        h, w = hit.shape
        photo = np.asarray(Image.open(photos / c["image"]).convert("RGB").resize((w, h), Image.BILINEAR), np.float32)
        r = {"photo": c["image"], **compare(photo, rgb, hit, dirs)}
        rows.append(r)
        side = np.concatenate([photo, np.where(hit[..., None], rgb, 0)], 1).clip(0, 255).astype(np.uint8)
        Image.fromarray(side).save(out / f"novel_{Path(c['image']).stem}.png")
        print(r, flush=True)
    mean = {k: round(float(np.nanmean([r[k] for r in rows])), 4) for k in ("covered_below_horizon", "covered_all",
                                                                           "psnr_db")}
    # every covered pixel of every held-out photo weighs the same (the mean above weighs each photo the same,
    # so a photo with 3 % covered counts as much as one with 90 %)
    px = sum(r["covered_px"] for r in rows)
    sse = sum(r["mse"] * r["covered_px"] for r in rows if r["covered_px"])
    mean["psnr_pooled_db"] = round(float(10 * np.log10(255.0 ** 2 / max(sse / px, 1e-9))), 2) if px else float("nan")
    doc = {"run": str(run), "photos": str(photos), "every": a.every, "supersample": a.supersample,
           "param_overrides": OVERRIDES, "held_out": rows, "mean": mean,
           "mesh": str(mesh_path), "units": "metres" if cams_doc.get("scaled", True) else "model units"}
    (out / "novel_views.json").write_text(json.dumps(doc, indent=2))
    print("\n| photo | covered below the horizon | covered (all) | PSNR on covered (dB) |\n|---|---|---|---|")
    for r in rows + [{"photo": "**mean**", **mean}]:
        print(f"| {r['photo']} | {100 * r['covered_below_horizon']:.1f} % | {100 * r['covered_all']:.1f} % | "
              f"{r['psnr_db']:.2f} |")
    print(f"| **all covered pixels pooled** | | | {mean['psnr_pooled_db']:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

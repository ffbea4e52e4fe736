"""Texture from the photos vs. texture baked from the dense cloud, judged from viewpoints no photo was taken from.

    .venv/bin/python plugins/twinkit-demo-site/bench/bench_photo_texture.py [<outputs>/demo] [--views 6] [--png out.png]

Reads a finished ``twinkit recipe=image_site site=demo`` run (by default one in
/tmp/twinkit_photo_texture_bench/outputs/demo; the recipe is run there first, cached steps reused): the site
(``01_site``), the baked texture (``*_texture``) and the projected one (``*_photo_texture``). New viewpoints
halfway between consecutive photos are rendered three ways: the ground truth (this package's own renderer,
the same lighting and weathering as the photos), and the reconstructed mesh with each texture (ray cast,
nearest texel). Prints the mean absolute colour error and PSNR over the pixels where both the truth and the
mesh show a surface, and writes a side-by-side picture.

It lives in the demo-site package because the truth needs the generator's scene and renderer; the photo
branch is reached only through the ``twinkit`` command.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[3]
DEFAULT_RUN = Path("/tmp/twinkit_photo_texture_bench/outputs/demo")


def _mesh_render(scene, o3d, uv_faces, tex, K, R, C, w, h):
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    d = np.c_[(u.ravel() - K[0, 2]) / K[0, 0], (v.ravel() - K[1, 2]) / K[1, 1], np.ones(u.size)] @ R.T
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    rays = np.c_[np.broadcast_to(C, d.shape), d].astype(np.float32)
    ans = scene.cast_rays(o3d.core.Tensor(rays))
    prim = ans["primitive_ids"].numpy().astype(np.int64)
    hit = np.isfinite(ans["t_hit"].numpy())
    b = ans["primitive_uvs"].numpy()
    img = np.zeros((w * h, 3), np.uint8)
    if hit.any():
        t = uv_faces[prim[hit]]
        bb = b[hit]
        st = t[:, 0] * (1 - bb[:, :1] - bb[:, 1:]) + t[:, 1] * bb[:, :1] + t[:, 2] * bb[:, 1:]
        s = tex.shape[0]
        col = np.clip((st[:, 0] * s).astype(int), 0, s - 1)
        row = np.clip(((1 - st[:, 1]) * s).astype(int), 0, s - 1)
        img[hit] = tex[row, col]
    return img.reshape(h, w, 3), hit.reshape(h, w)


def main() -> int:
    import open3d as o3d
    from PIL import Image
    from twinkit_demo_site.layout import build_scene
    from twinkit_demo_site.plugin import PRESETS
    from twinkit_demo_site.raycast import Tracer
    from twinkit_demo_site.textures import build_atlas
    from twinkit.mesh import read_ply

    ap = argparse.ArgumentParser()
    ap.add_argument("run", nargs="?", default=str(DEFAULT_RUN),
                    help="outputs/<site> folder of an image_site run on the demo site")
    ap.add_argument("--views", type=int, default=6)
    ap.add_argument("--png", default="")
    a = ap.parse_args()
    run = Path(a.run)
    if a.run == str(DEFAULT_RUN):
        import subprocess

        subprocess.check_call([str(REPO / ".venv" / "bin" / "twinkit"), "recipe=image_site", "site=demo",
                               f"engine.outputs_dir={run.parent}"], cwd=REPO, stdout=subprocess.DEVNULL)
    site_dir = run / "01_site"
    if not (site_dir / "site.json").exists():
        raise SystemExit(f"{run}: no 01_site/site.json; this bench needs a run on the demo site")
    site = json.loads((site_dir / "site.json").read_text())
    params = site["params"]
    atlas = build_atlas(site["seed"])
    truth = Tracer(build_scene(PRESETS[site["preset"]]["half_m"], site["seed"], atlas).mesh, atlas,
                   weathering=params.get("weathering", 0.0), seed=site["seed"])
    cams = json.loads((site_dir / "cameras.json").read_text())
    intr = cams["intrinsics"]
    K, w, h = np.array(intr["K"]), intr["width"] // 2, intr["height"] // 2
    K = np.diag([0.5, 0.5, 1.0]) @ K
    def step_dir(name):
        found = sorted(d for d in run.glob(f"[0-9][0-9]_{name}") if d.is_dir())
        if not found:
            raise SystemExit(f"{run}: no step folder NN_{name}; run twinkit recipe=image_site site=demo first")
        return found[-1]

    tex_dirs = {"baked from the dense cloud": step_dir("texture"), "projected from the photos": step_dir("photo_texture")}
    mesh = read_ply(tex_dirs["baked from the dense cloud"] / "textured_mesh.ply")
    uvf = np.asarray(mesh.face_attrs["texcoord"], np.float64).reshape(-1, 3, 2)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(mesh.vertices.astype(np.float32)), o3d.core.Tensor(mesh.faces.astype(np.uint32)))
    texs = {k: np.asarray(Image.open(d / "textured_mesh.png").convert("RGB")) for k, d in tex_dirs.items()}
    cl = cams["cameras"]
    picks = np.linspace(0, len(cl) - 2, a.views).astype(int)
    err = {k: [] for k in texs}
    rows = []
    for i in picks:
        c0, c1 = cl[i], cl[i + 1]
        C = (np.array(c0["center"]) + np.array(c1["center"])) / 2
        R0, R1 = np.array(c0["R_world_from_camera"]), np.array(c1["R_world_from_camera"])
        U, _, Vt = np.linalg.svd(R0 + R1)  # the rotation halfway between (chordal mean)
        R = U @ Vt
        gt, _, depth = truth.render(K, R, C, w, h, shadows=params.get("shadows", True))
        row = [gt]
        for k, tex in texs.items():
            img, hit = _mesh_render(scene, o3d, uvf, tex, K, R, C, w, h)
            both = hit & np.isfinite(depth)
            err[k].append(np.abs(img[both].astype(np.float32) - gt[both].astype(np.float32)).reshape(-1))
            row.append(img)
        rows.append(np.concatenate(row, 1))
    print("| texture | mean abs error (0-255) | PSNR dB |\n|---|---:|---:|")
    for k, e in err.items():
        e = np.concatenate(e)
        mse = float((e ** 2).mean())
        print(f"| {k} | {e.mean():.2f} | {10 * np.log10(255 ** 2 / mse):.2f} |")
    if a.png:
        Image.fromarray(np.concatenate(rows, 0)).save(a.png)
        print(f"picture (truth | baked | projected per row): {a.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

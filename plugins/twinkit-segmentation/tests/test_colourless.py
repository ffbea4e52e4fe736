"""A cloud without colours (issue 28): the bake step gives the mesh a shaded grey, the rendered views carry
what the 2D model needs to tell the ground from the walls, and blank views make the run degraded."""
from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image
from twinkit.mesh import Mesh, write_ply
from twinkit.testing import make_context

from twinkit_segmentation import steps as S
from twinkit_segmentation.synthetic import egl_available, street_scene

P = pytest.importorskip("twinkit_pointcloud.plugin")
needs_egl = pytest.mark.skipif(not egl_available(), reason="no headless EGL (Mesa) for moderngl")

GROUND, BUILDING = (0, 1), (2,)


def _views():
    out = []
    for i, x in enumerate(np.arange(-12.0, 12.1, 4.0)):
        for k in range(8):
            out.append({"id": f"v{i:02d}_{k}", "sampler": "test", "position": [float(x), 0.0, 1.6],
                        "heading_deg": 45.0 * k, "pitch_deg": -8.0, "hfov_deg": 75.0, "width": 192, "height": 96})
    return out


def _render(tmp_path, mode: str):
    """Bake the colourless street with ``colourless=mode``, render the views; (ctx, renders dir, vertex labels)."""
    v, f, n, flab = street_scene(step=0.5)
    vlab = np.zeros(len(v), np.uint8)
    vlab[f.reshape(-1)] = np.repeat(flab, 3)
    w = tmp_path / mode
    w.mkdir()
    write_ply(w / "clean_mesh.ply", Mesh(v, f, attrs={"normals": n.astype(np.float32)}))
    write_ply(w / "mesh.ply", Mesh(v, f, attrs={"normals": n.astype(np.float32)}))
    ctx = make_context(w / "bake", site={"name": "synthetic"})
    out = P.bake_texture(P.BakeParams(texture_px=512, colourless=mode), ctx, in_mesh_ply=w / "mesh.ply",
                         in_clean_mesh_ply=w / "clean_mesh.ply", out_textured_mesh_obj=w / "textured_mesh.obj",
                         out_textured_mesh_ply=w / "textured_mesh.ply")
    assert out["colourless"] == mode
    (w / "views.json").write_text(json.dumps({"views": _views()}))
    rctx = make_context(w / "render", site={"name": "synthetic"})
    res = S.render_views(S.RenderParams(), rctx, in_textured_mesh_ply=w / "textured_mesh.ply",
                         in_views_json=w / "views.json", out_renders_dir=w / "renders")
    return rctx, res, w / "renders", vlab


def _readable(renders, vlab) -> float:
    """An image-only oracle: per pixel, the nearest class mean of the rendered colour, fitted on half the
    views and scored on the others, ground (road, sidewalk) against building pixels. Balanced accuracy."""
    idx = json.loads((renders / "index.json").read_text())["kept"]
    feats, labs = [[], []], [[], []]
    for i, v in enumerate(idx):
        rgb = np.asarray(Image.open(renders / f"{v['id']}.png"), np.float64).reshape(-1, 3)
        vert = np.load(renders / f"{v['id']}_vertex.npz")["vertex"].reshape(-1)
        on = vert >= 0
        lab = vlab[vert[on]]
        cls = np.where(np.isin(lab, GROUND), 0, np.where(np.isin(lab, BUILDING), 1, -1))
        keep = cls >= 0
        feats[i % 2].append(rgb[on][keep])
        labs[i % 2].append(cls[keep])
    xtr, ytr = np.concatenate(feats[0]), np.concatenate(labs[0])
    xte, yte = np.concatenate(feats[1]), np.concatenate(labs[1])
    means = np.stack([xtr[ytr == c].mean(axis=0) for c in (0, 1)])
    pred = np.argmin(np.linalg.norm(xte[:, None, :] - means[None], axis=2), axis=1)
    if np.allclose(means[0], means[1]):  # nothing to tell them apart by: a coin
        pred = np.zeros_like(pred)
    return float(np.mean([(pred[yte == c] == c).mean() for c in (0, 1)]))


@needs_egl
def test_colourless_street_views_are_readable(tmp_path):
    ctx, res, renders, vlab = _render(tmp_path, "shaded")
    assert res["kept"] >= 20 and res["blank_share"] < 0.1
    assert not ctx.degraded_reasons
    acc = _readable(renders, vlab)
    assert acc > 0.9, acc


@needs_egl
def test_blank_views_are_degraded(tmp_path):
    ctx, res, renders, vlab = _render(tmp_path, "grey")
    assert res["blank_share"] > 0.9
    (reason,) = ctx.degraded_reasons
    assert "blank" in reason["reason"] and "colourless" in reason["hint"]
    assert _readable(renders, vlab) <= 0.55  # the flat grey silhouettes of before: a coin toss

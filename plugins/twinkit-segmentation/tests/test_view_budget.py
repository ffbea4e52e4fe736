"""The view budget (issue 28): views were uncapped (1,896 on IGN, 2,784 on Autzen, 80 % of the run time)."""
import json

import numpy as np
from twinkit.mesh import Mesh, write_ply
from twinkit.testing import make_context

from twinkit_segmentation import steps as S
from twinkit_segmentation.synthetic import street_scene
from twinkit_segmentation.views import cap_views


def _grid_views(n_side=10, heights=(1.5, 3.0), headings=8):
    views = []
    for x in range(n_side):
        for y in range(n_side):
            for h in heights:
                for k in range(headings):
                    views.append({"id": f"v{len(views)}", "sampler": "s", "position": [4.0 * x, 4.0 * y, h],
                                  "heading_deg": 360.0 * k / headings})
    return views


def test_cap_keeps_whole_positions_spread_over_the_site():
    views = _grid_views()
    kept = cap_views(views, 160)  # 10 of the 100 positions (16 views each)
    assert len(kept) == 160
    pos = {(v["position"][0], v["position"][1]) for v in kept}
    assert len(pos) == 10
    for p in pos:  # every height and heading of a kept position
        assert sum((v["position"][0], v["position"][1]) == p for v in kept) == 16
    xy = np.array(sorted(pos))
    assert np.ptp(xy[:, 0]) >= 28 and np.ptp(xy[:, 1]) >= 28  # spread, not one corner
    d = np.linalg.norm(xy[:, None] - xy[None], axis=2) + np.eye(len(xy)) * 1e9
    assert d.min() >= 8.0  # no two kept positions side by side
    # the old even thinning kept 1 of every 10 list entries: every position, a few headings each
    old = [views[i] for i in np.linspace(0, len(views) - 1, 160).round().astype(int)]
    assert len({(v["position"][0], v["position"][1]) for v in old}) > 50
    few = cap_views(views, 5)  # below one position's 16 views: that position's, evenly thinned
    assert len(few) == 5 and len({tuple(v["position"][:2]) for v in few}) == 1
    assert len({v["heading_deg"] for v in few}) >= 4
    assert cap_views(views, 0) == views and cap_views(views[:3], 10) == views[:3]


def test_sample_views_auto_budget(tmp_path, caplog):
    v, f, n, _ = street_scene(step=1.0)
    write_ply(tmp_path / "m.ply", Mesh(v, f, attrs={"normals": n.astype(np.float32)}))
    cfg = {"view_sampler": {"plugin": "uniform", "spacing_m": 5.0, "heights_m": [2.0], "headings": 8}}
    ctx = make_context(tmp_path / "w", config=cfg)
    out = S.sample_views(S.SampleViewsParams(auto_max_views=40), ctx, in_textured_mesh_ply=tmp_path / "m.ply",
                         out_views_json=tmp_path / "views.json")
    assert out["sampled_views"] > 40 and out["views"] == 40 and out["max_views"] == 40
    assert "kept" in caplog.text
    data = json.loads((tmp_path / "views.json").read_text())
    assert data["sampled"] == out["sampled_views"] and len(data["views"]) == 40
    everything = S.sample_views(S.SampleViewsParams(max_views=0), ctx, in_textured_mesh_ply=tmp_path / "m.ply",
                                out_views_json=tmp_path / "all.json")
    assert everything["views"] == everything["sampled_views"] == out["sampled_views"]


def test_aerial_capture_raises_the_cameras(tmp_path):
    v, f, n, _ = street_scene(step=1.0)
    write_ply(tmp_path / "m.ply", Mesh(v, f, attrs={"normals": n.astype(np.float32)}))
    rng = np.random.default_rng(0)
    ground = np.column_stack([rng.uniform(-20, 20, 6000), rng.uniform(-20, 20, 6000), rng.normal(0, 0.02, 6000)])
    street = np.concatenate([ground, np.column_stack([rng.uniform(-18, 18, 3000), np.full(3000, 10.0),
                                                      rng.uniform(0, 8, 3000)])])
    cfg = {"view_sampler": {"plugin": "auto_street", "spacing_m": 8.0}}
    heights = {}
    for name, pts in (("aerial", ground), ("street", street)):
        write_ply(tmp_path / f"{name}.ply", Mesh(pts))
        ctx = make_context(tmp_path / name, config=cfg)
        out = S.sample_views(S.SampleViewsParams(), ctx, in_textured_mesh_ply=tmp_path / "m.ply",
                             in_points_ply=tmp_path / f"{name}.ply", out_views_json=tmp_path / f"{name}.json")
        views = json.loads((tmp_path / f"{name}.json").read_text())["views"]
        heights[name] = (out["capture"], sorted({round(x["position"][2], 1) for x in views}),
                         {x["pitch_deg"] for x in views})
    assert heights["aerial"] == ("aerial", [3.0, 6.0, 10.0], {-20.0})
    assert heights["street"] == ("mobile", [1.5, 3.0, 4.5], {-8.0})

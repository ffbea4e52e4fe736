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
        out = S.sample_views(S.SampleViewsParams(colourless_views=True), ctx, in_textured_mesh_ply=tmp_path / "m.ply",
                             in_points_ply=tmp_path / f"{name}.ply", out_views_json=tmp_path / f"{name}.json")
        views = json.loads((tmp_path / f"{name}.json").read_text())["views"]
        heights[name] = (out["capture"], sorted({round(x["position"][2], 1) for x in views}),
                         {x["pitch_deg"] for x in views})
    assert heights["aerial"] == ("aerial", [3.0, 6.0, 10.0], {-20.0})
    assert heights["street"] == ("mobile", [1.5, 3.0, 4.5], {-8.0})


def test_a_colourless_capture_gets_no_views_unless_asked_and_the_geometry_labels_it(tmp_path):
    """Beside the 3D classifier the grey views of a colourless capture added nothing (docs/segmentation.md "The
    grey views' worth"): none are sampled, rendered or segmented, and backproject labels from the geometry."""
    import pytest
    from twinkit.cityscapes import BUILDING, ROAD
    from twinkit.errors import InputError

    v, f, n, _ = street_scene(step=1.0)
    write_ply(tmp_path / "m.ply", Mesh(v, f, attrs={"normals": n.astype(np.float32)}))
    rng = np.random.default_rng(0)
    pts = v + rng.normal(0, 0.01, v.shape)
    write_ply(tmp_path / "grey.ply", Mesh(pts))
    write_ply(tmp_path / "coloured.ply", Mesh(pts, attrs={"colors": rng.integers(0, 255, (len(pts), 3)).astype(np.uint8)}))
    cfg = {"view_sampler": {"plugin": "uniform", "spacing_m": 5.0, "heights_m": [2.0], "headings": 8},
           "image_model": {"plugin": "oracle"}}
    ctx = make_context(tmp_path / "w", config=cfg)
    out = {}
    for name in ("grey", "coloured"):
        out[name] = S.sample_views(S.SampleViewsParams(auto_max_views=40), ctx, in_textured_mesh_ply=tmp_path / "m.ply",
                                   in_points_ply=tmp_path / f"{name}.ply", out_views_json=tmp_path / f"{name}.json")
    assert out["coloured"]["views"] == 40 and "skipped" not in out["coloured"]
    assert out["grey"]["views"] == 0 and "no colours" in out["grey"]["skipped"]
    assert "colourless_views=true" in out["grey"]["skipped"]
    asked = S.sample_views(S.SampleViewsParams(auto_max_views=40, colourless_views=True), ctx,
                           in_textured_mesh_ply=tmp_path / "m.ply", in_points_ply=tmp_path / "grey.ply",
                           out_views_json=tmp_path / "asked.json")
    assert asked["views"] == 40
    # render and predict pass the skip on without a model: every vertex gets no vote
    r = S.render_views(S.RenderParams(), ctx, in_textured_mesh_ply=tmp_path / "m.ply", in_views_json=tmp_path / "grey.json",
                       out_renders_dir=tmp_path / "renders")
    assert r["kept"] == 0 and r["skipped"] == out["grey"]["skipped"]
    p = S.predict_views(S.PredictParams(), ctx, in_renders_dir=tmp_path / "renders", out_predictions_dir=tmp_path / "pred",
                        out_vertex_votes_npy=tmp_path / "votes.npy")
    votes = np.load(tmp_path / "votes.npy")
    assert p["views"] == 0 and votes.shape == (len(v), 19) and not votes.any()
    # backproject: the geometry's word alone; without geometry a clear error
    seg = np.arange(len(v))
    np.save(tmp_path / "seg.npy", seg)
    geom = np.zeros((len(v), 19), np.float32)
    geom[:, ROAD] = 1.0
    geom[v[:, 2] > 1.0, ROAD], geom[v[:, 2] > 1.0, BUILDING] = 0.0, 1.0
    np.save(tmp_path / "geom.npy", geom)
    kw = dict(in_textured_mesh_ply=tmp_path / "m.ply", in_segments_npy=tmp_path / "seg.npy",
              in_vertex_votes_npy=tmp_path / "votes.npy", out_labels_npy=tmp_path / "labels.npy",
              out_confidence_npy=tmp_path / "conf.npy", out_labels_ply=tmp_path / "labels.ply",
              out_confidence_png=tmp_path / "conf.png", in_points_ply=tmp_path / "grey.ply")
    S.backproject(S.BackprojectParams(context=False), ctx, in_geometry_votes_npy=tmp_path / "geom.npy", **kw)
    labels = np.load(tmp_path / "labels.npy")
    assert (labels == np.where(v[:, 2] > 1.0, BUILDING, ROAD)).mean() > 0.99
    with pytest.raises(InputError, match="classify_geometry"):
        S.backproject(S.BackprojectParams(context=False), ctx, **kw)

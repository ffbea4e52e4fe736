"""Label agreement across seams: a labelling that breaks at a seam is caught, one that does not is not."""
from __future__ import annotations

import numpy as np
import pytest

from twinkit_tiles.seam_labels import IGNORE, control_planes, seam_label_stats


def _grid(n=61, size=60.0):
    xs = np.linspace(-size / 2, size / 2, n)
    X, Y = np.meshgrid(xs, xs)
    V = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    F = []
    for j in range(n - 1):
        for i in range(n - 1):
            a, b, c, d = j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i
            F += [(a, b, c), (a, c, d)]
    return V, np.asarray(F, np.int64)


PLANES = [(0, -10.0), (0, 10.0), (1, -10.0), (1, 10.0)]


def test_control_planes_lie_inside_tiles():
    c = control_planes(PLANES, np.array([-30.0, -30.0, 0]), np.array([30.0, 30.0, 0]))
    assert sorted(v for a, v in c if a == 0) == [-20.0, 0.0, 20.0]
    assert all(min(abs(v - s) for a2, s in PLANES if a2 == a) >= 2.0 for a, v in c)


def test_labels_that_ignore_the_seams_score_like_the_controls():
    V, F = _grid()
    rng = np.random.default_rng(0)
    gt = np.where(V[:, 1] > 3.3, 1, 0).astype(np.uint8)  # a class border along y = 3.3, across all planes
    pred = gt.copy()
    noise = rng.random(len(V)) < 0.05
    pred[noise] = 2
    r = seam_label_stats(V, F, pred, PLANES, gt)
    assert r["seam_change_pct"] == pytest.approx(r["control_change_pct"], abs=4.0)
    assert r["seam_changes_not_in_gt_pct"] == pytest.approx(r["control_changes_not_in_gt_pct"], abs=4.0)
    assert r["accuracy_near_seams_pct"] == pytest.approx(r["accuracy_elsewhere_pct"], abs=3.0)


def test_labels_that_break_at_a_seam_are_caught():
    V, F = _grid()
    gt = np.zeros(len(V), np.uint8)
    pred = gt.copy()
    pred[V[:, 0] > 10.0] = 1  # the tile beyond x = 10 got another class
    pred[:5] = IGNORE
    r = seam_label_stats(V, F, pred, PLANES, gt)
    x10 = next(s for s in r["seams"] if s["plane"] == ["x", 10.0])
    assert x10["label_changes"] == x10["edges"] > 0
    # (a few diagonal edges crossing a control plane also cross x = 10)
    assert r["control_change_pct"] < 1.0 and r["seam_change_pct"] > 20.0
    assert r["seam_changes_not_in_gt_pct"] > 20.0 and r["control_changes_not_in_gt_pct"] < 1.0
    with pytest.raises(ValueError, match="labels"):
        seam_label_stats(V, F, pred[:-1], PLANES)


def _step_inputs(tmp_path, tiles):
    import json

    from twinkit.mesh import Mesh, write_ply

    V, F = _grid()
    write_ply(tmp_path / "textured_mesh.ply", Mesh(vertices=V, faces=F))
    labels = np.where(V[:, 0] > 10.0, 1, 0).astype(np.uint8)  # breaks at x = 10
    np.save(tmp_path / "labels.npy", labels)
    (tmp_path / "tiles.json").write_text(json.dumps({"items": tiles}))
    return {"in_tiles_json": tmp_path / "tiles.json", "in_textured_mesh_ply": tmp_path / "textured_mesh.ply",
            "in_labels_npy": tmp_path / "labels.npy"}


def test_the_step_checks_the_seams_of_tiles_json_or_the_lines_it_is_given(tmp_path):
    import json

    import twinkit_tiles.plugin as P
    from twinkit import InputError
    from twinkit.testing import check_plugin, plugin_from_module, run_step

    plugin = plugin_from_module(P, "step", "evaluate_seam_labels")
    check_plugin(plugin)
    two = [{"ix": 0, "iy": 0, "core": [None, None, 10.0, None]}, {"ix": 1, "iy": 0, "core": [10.0, None, None, None]}]
    out = run_step(plugin, tmp_path / "a", _step_inputs(tmp_path, two))
    rep = json.loads(out["seam_labels.json"].read_text())
    assert rep["seam_planes"] == 1 and rep["seams"][0]["label_changes"] == rep["seams"][0]["edges"] > 0
    # one tile: no seam, unless lines are given
    one = [{"ix": 0, "iy": 0, "core": [None, None, None, None]}]
    out = run_step(plugin, tmp_path / "b", _step_inputs(tmp_path, one))
    rep = json.loads(out["seam_labels.json"].read_text())
    assert rep["seam_planes"] == 0 and rep["seam_change_pct"] is None
    out = run_step(plugin, tmp_path / "c", _step_inputs(tmp_path, one), P.EvaluateSeamLabelsParams(planes=["x=10", "y = -5"]))
    rep = json.loads(out["seam_labels.json"].read_text())
    assert rep["seam_planes"] == 2 and rep["seam_change_pct"] > 40.0
    with pytest.raises(InputError, match="evaluate_seam_labels.planes.*'z=3'"):
        run_step(plugin, tmp_path / "d", _step_inputs(tmp_path, one), P.EvaluateSeamLabelsParams(planes=["z=3"]))

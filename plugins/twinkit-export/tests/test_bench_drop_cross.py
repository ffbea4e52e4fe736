"""``bench/bench_drop_cross.py``: the drop test with the maps held fixed tells a better mesh from a luckier map."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from twinkit.mesh import Mesh, write_ply

from conftest import straight_xodr
from twinkit_export import synthetic

pytest.importorskip("carla")


def _bench():
    path = Path(__file__).resolve().parents[1] / "bench" / "bench_drop_cross.py"
    spec = importlib.util.spec_from_file_location("bench_drop_cross", path)
    mod = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(mod)
    return mod


def _run(root: Path, hole: bool, road_y: float) -> Path:
    """A site folder with the three files the bench reads: a flat 10 cm ground grid 40 x 26 m (with a 1 x 1 m
    hole at (20, 6.5) when ``hole``) and a straight road at ``road_y``."""
    xs, ys = np.arange(0, 40.0001, 0.1), np.arange(-13.0, 13.0001, 0.1)
    X, Y = np.meshgrid(xs, ys)
    v = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
    i = np.arange(X.size).reshape(X.shape)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel()
    f = np.vstack([np.c_[a, b, d], np.c_[a, d, c]])
    if hole:
        cen = v[f].mean(axis=1)
        f = f[~((np.abs(cen[:, 0] - 20) < 0.5) & (np.abs(cen[:, 1] - 6.5) < 0.5))]
    for sub in ("02_read_cloud", "16_apply_alignment", "21_lift_movables"):
        (root / sub).mkdir(parents=True)
    uv = np.c_[v[:, 0] / 40.0, (v[:, 1] + 13) / 26.0].astype(np.float32)
    synthetic.write_obj(root / "21_lift_movables" / "textured_mesh.obj", v, f, uv, texture_px=64)
    (root / "16_apply_alignment" / "aligned.xodr").write_text(straight_xodr(length_m=40.0, y0=road_y))
    write_ply(root / "02_read_cloud" / "points.ply",
              Mesh(v.copy(), None, attrs={"normals": np.tile(np.array([0, 0, 1], np.float32), (len(v), 1))}))
    return root


def test_a_mesh_change_is_scored_under_each_map(tmp_path):
    """Run A: a hole under its own road's left lane; run B: no hole, its road 10 m south. A's own drop test fails
    and B's passes, which says nothing about the meshes alone: under B's map both meshes pass, under A's map
    only B's."""
    bench = _bench()
    a = _run(tmp_path / "a", hole=True, road_y=5.0)
    b = _run(tmp_path / "b", hole=False, road_y=-5.0)
    rows = {(Path(r["mesh"]).name, Path(r["map"]).name): r for r in bench.cross([a, b])}
    assert set(rows) == {("a", "a"), ("a", "b"), ("b", "a"), ("b", "b")}
    assert rows[("a", "a")]["gate_pct"] < 99.9 and rows[("a", "a")]["failing"] >= 80
    assert rows[("a", "a")]["widest_hole_m"] >= 0.9
    for key in (("a", "b"), ("b", "a"), ("b", "b")):
        assert rows[key]["gate_pct"] == 100.0 and rows[key]["failing"] == 0, (key, rows[key])
    text = bench.table(list(rows.values()))
    assert text.count("\n") == 3 and "hole 1." in text

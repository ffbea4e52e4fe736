"""bench/bench_labelled.py feeds the pipeline a copy of each hand-labelled scan without its labels."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SCAN = ROOT.parent / "shared" / "data" / "labelled" / "semantickitti" / "seq00_000000.ply"


def _bench():
    spec = importlib.util.spec_from_file_location("bench_labelled_under_test", ROOT / "bench" / "bench_labelled.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.skipif(not SCAN.is_file(), reason=f"needs {SCAN} (real labelled lidar, not on this machine)")
def test_the_label_free_copy_keeps_the_points_and_drops_every_label_field(tmp_path):
    from plyfile import PlyData

    bench = _bench()
    src = bench.LABELLED / SCAN.name
    dst = bench.label_free_copy(src, tmp_path / "scan.ply")
    v = PlyData.read(str(dst))["vertex"].data
    assert set(v.dtype.names) == {"x", "y", "z", "intensity"}
    xyz, inten, truth = bench.read_scan(src)
    assert len(v) == len(xyz) and (truth != 255).any()
    assert np.array_equal(np.stack([v["x"], v["y"], v["z"]], 1), xyz.astype(np.float32))
    assert np.array_equal(v["intensity"], inten)
    raw = dst.read_bytes()
    assert b"label" not in raw[:2000] and b"cs_trainid" not in raw[:2000]


def test_the_tables_mean_and_difference():
    bench = _bench()
    now = {"a": {"mIoU": 10.0, "car": float("nan")}, "b": {"mIoU": 30.0, "car": 50.0}}
    rows = {k: dict(v) for k, v in now.items()}
    rows["mean"] = {"mIoU": 20.0, "car": 50.0}
    diff = bench.difference(rows, {"a": {"mIoU": 5.0, "car": 1.0}, "mean": {"mIoU": 25.0, "car": 40.0}})
    assert diff["a"]["mIoU"] == 5.0 and np.isnan(diff["a"]["car"]) and diff["mean"]["car"] == 10.0
    assert "b" not in diff
    assert "| a | 10.0 | - |" in bench.markdown(rows)

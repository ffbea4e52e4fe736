"""bench/bench_geometry.py retrains the 3D classifier on the shipped recipe's captures only."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _bench():
    spec = importlib.util.spec_from_file_location("bench_geometry_under_test", ROOT / "bench" / "bench_geometry.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _manifest(folder: Path, **flags) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    caps = [{"file": "seed0100_tls_v0.npz", "kind": "tls", "meta": {"foliage_m": 0.0}},
            {"file": "seed0100_spinning_v0.npz", "kind": "spinning", "meta": {"foliage_m": 0.3}, **flags}]
    (folder / "manifest.json").write_text(json.dumps({"captures": caps}))


def test_a_capture_folder_of_an_older_recipe_is_refused_before_it_is_trained_on(tmp_path):
    bench = _bench()
    assert ("--surfaces", "--tall-hedges") == next(f for k, _, f in bench.CAPTURES if k == "spinning")
    bench.check_manifest(tmp_path / "empty")  # nothing made yet: the generator makes everything
    _manifest(tmp_path / "new", surfaces=True, tall_hedges=True)
    bench.check_manifest(tmp_path / "new")
    _manifest(tmp_path / "old", surfaces=False, tall_hedges=False)
    with pytest.raises(SystemExit, match="seed0100_spinning_v0.npz.*--surfaces --tall-hedges"):
        bench.check_manifest(tmp_path / "old")

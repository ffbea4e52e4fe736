"""The leave-one-out bench's --param: a newer default measured on an older run (the run's step.json
records the values it used, and the rebuild takes those unless told otherwise)."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench" / "bench_novel_views.py"


def _bench():
    spec = importlib.util.spec_from_file_location("bench_novel_views_under_test", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_param_overrides_replace_the_values_the_run_recorded_and_only_for_their_plugin(tmp_path):
    nv = _bench()
    step = tmp_path / "09_photo_texture"
    step.mkdir()
    (step / "step.json").write_text(json.dumps({"plugin": "step/photo_texture",
                                                "params": {"max_views": 3, "sharpness": 4.0, "min_cos": 0.15}}))
    (tmp_path / "06_clean").mkdir()
    (tmp_path / "06_clean" / "step.json").write_text(json.dumps({"plugin": "step/clean_mesh",
                                                                 "params": {"max_dist_m": 0.08}}))
    assert nv._run_params(tmp_path, "step/photo_texture") == {"max_views": 3, "sharpness": 4.0, "min_cos": 0.15}
    for text in ("step/photo_texture.max_views=6", "step/photo_texture.sharpness=0"):
        plugin, name, value = nv._parse_override(text)
        nv.OVERRIDES.setdefault(plugin, {})[name] = value
    assert nv._run_params(tmp_path, "step/photo_texture") == {"max_views": 6, "sharpness": 0, "min_cos": 0.15}
    assert nv._run_params(tmp_path, "step/clean_mesh") == {"max_dist_m": 0.08}
    # a plugin the run lacks still gets the override (its other parameters: the plugin's defaults)
    nv.OVERRIDES["step/dense"] = {"confirm_max_scale": 4.0}
    assert nv._run_params(tmp_path, "step/dense") == {"confirm_max_scale": 4.0}


def test_a_malformed_param_override_names_the_expected_form():
    nv = _bench()
    assert nv._parse_override("reconstructor/poisson.voxel_m=0.05") == ("reconstructor/poisson", "voxel_m", 0.05)
    with pytest.raises(SystemExit, match="kind/plugin.name=value"):
        nv._parse_override("max_views=6")
    with pytest.raises(SystemExit, match="kind/plugin.name=value"):
        nv._parse_override("step/photo_texture.max_views")

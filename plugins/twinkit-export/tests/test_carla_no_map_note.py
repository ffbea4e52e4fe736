"""A twin without a road network is named beside the run's status (issue 46 item 2): the CARLA package step
notes "no road network", which the manifest lists under ``notes`` and the report's top line shows."""
from __future__ import annotations

import json

import pytest

from twinkit.testing import run_step

from conftest import HAS_BPY, SITE, plugin

pytestmark = pytest.mark.skipif(not HAS_BPY, reason="bpy (Blender as a module) writes the package's FBX files")


def test_a_package_without_a_map_notes_no_road_network(tmp_path, class_dir, fbx_out):
    out = run_step(plugin("exporter", "carla_package"), tmp_path / "run",
                   {"in_twin_fbx": fbx_out, "in_class_meshes_dir": class_dir}, site=SITE)
    metrics = json.loads((out["carla_import"].parent / "step.json").read_text())["metrics"]
    assert metrics["notes"] == ["no road network"]

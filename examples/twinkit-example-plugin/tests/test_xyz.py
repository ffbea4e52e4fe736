"""The example plugin's own tests, written with twinkit's helpers for plugin authors."""
import numpy as np
import pytest

from twinkit import InputError
from twinkit.testing import check_plugin, plugin_from_module, run_step

import twinkit_example.plugin as example

PLY = (
    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
    "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1.5 0 0\n0 2 0.25\n3 0 1 2\n"
)


def _plugin():
    return plugin_from_module(example, "exporter", "xyz")


def test_contract():
    check_plugin(_plugin())


def test_exports_every_vertex(tmp_path):
    mesh = tmp_path / "mesh.ply"
    mesh.write_text(PLY)
    out = run_step(_plugin(), tmp_path / "run", {"in_mesh_ply": mesh}, example.XyzParams(decimals=2, offset_m=1.0))
    pts = np.loadtxt(out["points.xyz"])
    assert pts.shape == (3, 3)
    np.testing.assert_allclose(pts[:, 2], [1.0, 1.0, 1.25])
    assert out["points.xyz"].read_text().splitlines()[1] == "1.50 0.00 1.00"


def test_bad_ply_names_the_file(tmp_path):
    mesh = tmp_path / "mesh.ply"
    mesh.write_text("not a ply")
    with pytest.raises(InputError, match="mesh.ply"):
        run_step(_plugin(), tmp_path / "run", {"in_mesh_ply": mesh})
    assert not (tmp_path / "run" / "result").exists(), "a failed step must leave no outputs"

"""The one PLY path (twinkit.mesh.ply)."""
from __future__ import annotations

import numpy as np

from twinkit.mesh import read_ply, write_ply

from tests.mesh.meshes import grid_mesh


def test_ply_round_trip_attributes(tmp_path):
    m = grid_mesh(10)
    m.attrs["dist_to_cloud_m"] = np.linspace(0, 1, m.n_vertices).astype(np.float32)
    m.attrs["label"] = np.arange(m.n_vertices).astype(np.int32)
    m.face_attrs["texcoord"] = np.random.rand(m.n_faces, 6).astype(np.float32)
    write_ply(tmp_path / "m.ply", m)
    r = read_ply(tmp_path / "m.ply")
    assert np.array_equal(r.faces, m.faces) and np.allclose(r.vertices, m.vertices)
    assert np.allclose(r.attrs["dist_to_cloud_m"], m.attrs["dist_to_cloud_m"])
    assert np.array_equal(r.attrs["label"], m.attrs["label"])
    assert np.allclose(r.face_attrs["texcoord"], m.face_attrs["texcoord"])
    # plyfile reads what we write
    from plyfile import PlyData

    p = PlyData.read(str(tmp_path / "m.ply"))
    assert p["face"].count == m.n_faces

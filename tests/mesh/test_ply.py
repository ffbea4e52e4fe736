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


def test_big_endian_binary_read_fast(tmp_path):
    """A big-endian binary PLY reads like the little-endian one (fast path, native byte order)."""
    from plyfile import PlyData, PlyElement

    m = grid_mesh(6)
    vert = np.empty(m.n_vertices, dtype=[("x", ">f4"), ("y", ">f4"), ("z", ">f4"), ("red", "u1"), ("green", "u1"),
                                          ("blue", "u1"), ("label", ">i4")])
    vert["x"], vert["y"], vert["z"] = m.vertices.T
    vert["red"], vert["green"], vert["blue"] = m.colors.T
    vert["label"] = np.arange(m.n_vertices)
    face = np.empty(m.n_faces, dtype=[("vertex_indices", ">i4", (3,))])
    face["vertex_indices"] = m.faces
    PlyData([PlyElement.describe(vert, "vertex"), PlyElement.describe(face, "face")], byte_order=">").write(
        str(tmp_path / "be.ply"))
    r = read_ply(tmp_path / "be.ply")
    assert np.array_equal(r.faces, m.faces) and np.allclose(r.vertices, m.vertices)
    assert np.array_equal(r.colors, m.colors) and r.attrs["label"].dtype.isnative
    assert np.array_equal(r.attrs["label"], np.arange(m.n_vertices))


def test_polygons_fan_triangulated_through_plyfile(tmp_path):
    (tmp_path / "q.ply").write_text("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                                    "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                                    "end_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n")
    r = read_ply(tmp_path / "q.ply")
    assert r.faces.tolist() == [[0, 1, 2], [0, 2, 3]]


def test_write_colored_ply_layout(tmp_path):
    """Vertex colours, uchar label and extra scalars in the layout the segmentation files always had."""
    from twinkit.mesh import write_colored_ply

    m = grid_mesh(5)
    lab = np.arange(m.n_vertices, dtype=np.uint8) % 19
    write_colored_ply(tmp_path / "c.ply", m.vertices, m.faces, m.colors, labels=lab,
                      extra={"segment": np.arange(m.n_vertices, dtype=np.int32)}, comment="hello")
    data = (tmp_path / "c.ply").read_bytes()
    head = data[:data.index(b"end_header\n")].decode().splitlines()
    assert head == ["ply", "format binary_little_endian 1.0", "comment hello", f"element vertex {m.n_vertices}",
                    "property float x", "property float y", "property float z", "property uchar red",
                    "property uchar green", "property uchar blue", "property uchar label", "property int segment",
                    f"element face {m.n_faces}", "property list uchar int vertex_indices"]
    r = read_ply(tmp_path / "c.ply")
    assert np.array_equal(r.attrs["label"], lab) and np.array_equal(r.attrs["segment"], np.arange(m.n_vertices))


def test_read_mesh_checks_and_texture(tmp_path):
    import pytest

    from twinkit import InputError
    from twinkit.mesh import read_mesh

    m = grid_mesh(4)
    m.face_attrs["texcoord"] = np.zeros((m.n_faces, 6), np.float32)
    write_ply(tmp_path / "t.ply", m)
    (tmp_path / "t.png").write_bytes(b"")
    r = read_mesh(tmp_path / "t.ply")
    assert r.texture == tmp_path / "t.png" and r.corner_uv.shape == (m.n_faces, 3, 2)
    m.comments = ["TextureFile atlas.jpg"]
    (tmp_path / "atlas.jpg").write_bytes(b"")
    write_ply(tmp_path / "t.ply", m)
    assert read_mesh(tmp_path / "t.ply").texture == tmp_path / "atlas.jpg"
    with pytest.raises(InputError):
        read_mesh(tmp_path / "t.obj")
    (tmp_path / "bad.ply").write_bytes(b"not a ply")
    with pytest.raises(InputError):
        read_mesh(tmp_path / "bad.ply")
    m.faces = m.faces.copy()
    m.faces[0, 0] = 10_000
    write_ply(tmp_path / "range.ply", m)
    with pytest.raises(InputError):
        read_mesh(tmp_path / "range.ply")


def test_import_is_light():
    import subprocess
    import sys

    code = ("import sys, twinkit, twinkit.mesh, twinkit.surface, twinkit.surface.cleanup, twinkit.surface.poisson, "
            "twinkit.surface.simplify, twinkit.surface.texture, twinkit.mesh.glb; "
            "print(sorted(m for m in ('open3d', 'scipy', 'plyfile', 'trimesh', 'PIL', 'fast_simplification') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "[]"
    out = subprocess.run([sys.executable, "-c", "import sys, twinkit; print('twinkit.mesh' in sys.modules)"],
                         capture_output=True, text=True, check=True).stdout.strip()
    assert out == "False"

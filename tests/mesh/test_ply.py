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


def test_polygons_fan_triangulated_by_the_general_reader(tmp_path):
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


def _plyfile_cases(tmp_path):
    """PLY files written by plyfile (an independent writer): ASCII and binary of both byte orders, with
    polygons of varying length, an extra element, a cloud, and an empty face list."""
    from plyfile import PlyData, PlyElement

    vert = np.array([(0, 0, 0, 9), (1, 0, 0, 8), (1, 1, 0, 7), (0, 1, 0, 6), (2, 2, 2, 5)],
                    dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("label", "u1")])
    poly = np.empty(3, dtype=[("vertex_indices", object), ("q", "u1")])
    poly["vertex_indices"] = [np.array(v, "i4") for v in ([0, 1, 2, 3], [1, 2, 4], [0, 1, 2, 3, 4])]
    poly["q"] = [1, 2, 3]
    tri = np.empty(2, dtype=[("vertex_indices", "i4", (3,))])
    tri["vertex_indices"] = [[0, 1, 2], [2, 3, 0]]
    edge = np.array([(0, 1), (1, 2)], dtype=[("vertex1", "i4"), ("vertex2", "i4")])
    empty = PlyElement.describe(np.empty(0, dtype=[("vertex_indices", object)]), "face",
                                len_types={"vertex_indices": "u1"}, val_types={"vertex_indices": "i4"})
    out = []
    for text in (True, False):
        for order in ("<", ">"):
            for name, els in (("poly", [PlyElement.describe(poly, "face"), PlyElement.describe(edge, "edge")]),
                              ("tri_edge", [PlyElement.describe(edge, "edge"), PlyElement.describe(tri, "face")]),
                              ("cloud", []), ("no_faces", [empty])):
                f = tmp_path / f"{name}_{text}_{'le' if order == '<' else 'be'}.ply"
                PlyData([PlyElement.describe(vert, "vertex"), *els], text=text, byte_order=order,
                        comments=["made by plyfile"]).write(str(f))
                out.append((f, vert, {"poly": [[0, 1, 2], [0, 2, 3], [1, 2, 4], [0, 1, 2], [0, 2, 3], [0, 3, 4]],
                                      "tri_edge": tri["vertex_indices"].tolist(), "cloud": None, "no_faces": []}[name]))
    return out


def test_the_general_reader_reads_what_plyfile_writes(tmp_path):
    """ASCII, polygons, lists of varying length and other elements, read without any PLY library."""
    for f, vert, faces in _plyfile_cases(tmp_path):
        r = read_ply(f)
        assert np.array_equal(r.vertices, np.stack([vert["x"], vert["y"], vert["z"]], 1).astype(np.float64)), f
        assert np.array_equal(r.attrs["label"], vert["label"]) and r.comments == ["made by plyfile"], f
        assert (r.faces is None) if faces is None else (r.faces.tolist() == faces), (f, r.faces)
    bad = tmp_path / "poly_False_le.ply"
    (tmp_path / "cut.ply").write_bytes(bad.read_bytes()[:-5])
    import pytest

    with pytest.raises(ValueError, match="truncated"):
        read_ply(tmp_path / "cut.ply")


def test_ascii_writer_matches_plyfile_byte_for_byte(tmp_path):
    """The ASCII writer gives the bytes plyfile gave for the same mesh (when it wrote twinkit's ASCII)."""
    from plyfile import PlyData, PlyElement

    m = grid_mesh(4)
    m.attrs["d"] = np.linspace(0, 1, m.n_vertices).astype(np.float32)
    m.face_attrs["texcoord"] = np.random.default_rng(0).random((m.n_faces, 6)).astype(np.float32)
    m.comments = ["hello"]
    write_ply(tmp_path / "ours.ply", m, text=True)
    vert = np.empty(m.n_vertices, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "u1"), ("green", "u1"),
                                          ("blue", "u1"), ("d", "f4")])
    vert["x"], vert["y"], vert["z"] = m.vertices.T
    vert["red"], vert["green"], vert["blue"] = m.colors.T
    vert["d"] = m.attrs["d"]
    face = np.empty(m.n_faces, dtype=[("vertex_indices", "i4", (3,)), ("texcoord", "f4", (6,))])
    face["vertex_indices"], face["texcoord"] = m.faces, m.face_attrs["texcoord"]
    PlyData([PlyElement.describe(vert, "vertex"),
             PlyElement.describe(face, "face", len_types={"vertex_indices": "u1", "texcoord": "u1"},
                                 val_types={"vertex_indices": "i4"})], text=True, comments=["hello"]).write(
        str(tmp_path / "theirs.ply"))
    assert (tmp_path / "ours.ply").read_bytes() == (tmp_path / "theirs.ply").read_bytes()
    r = read_ply(tmp_path / "ours.ply")
    assert np.array_equal(r.faces, m.faces) and np.allclose(r.vertices, m.vertices)
    assert np.array_equal(r.face_attrs["texcoord"], m.face_attrs["texcoord"])


def test_reading_and_writing_any_ply_needs_no_ply_library(tmp_path):
    """plyfile (GPL-3.0) is a test tool only: the core reads and writes every PLY without it."""
    import subprocess
    import sys

    f = tmp_path / "q.ply"
    f.write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                 "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n3 0 1 2\n")
    code = (f"import sys; sys.modules['plyfile'] = None; from twinkit.mesh import read_ply, write_ply; "
            f"m = read_ply({str(f)!r}); write_ply({str(tmp_path / 'a.ply')!r}, m, text=True); "
            f"write_ply({str(tmp_path / 'b.ply')!r}, m); print(read_ply({str(tmp_path / 'a.ply')!r}).faces.tolist())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.strip() == "[[0, 1, 2]]", out.stderr

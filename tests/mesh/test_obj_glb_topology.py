"""Textured OBJ, the one GLB writer and the topology helpers of twinkit.mesh."""
from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from twinkit.mesh import Mesh, boundary_loops, components, edges, read_obj, write_obj
from twinkit.street.holes import fan_fill
from twinkit.mesh.glb import GlbPart, srgb_to_linear, write_colored_glb, write_textured_glb

from tests.mesh.meshes import grid_mesh


def _glb(path):
    data = path.read_bytes()
    magic, version, total = struct.unpack("<4sII", data[:12])
    assert magic == b"glTF" and version == 2 and total == len(data)
    jlen, jtype = struct.unpack("<I4s", data[12:20])
    assert jtype == b"JSON" and jlen % 4 == 0
    doc = json.loads(data[20:20 + jlen])
    blen, btype = struct.unpack("<I4s", data[20 + jlen:28 + jlen])
    assert btype == b"BIN\0" and blen == doc["buffers"][0]["byteLength"] and blen % 4 == 0
    return doc, data[28 + jlen:28 + jlen + blen]


def test_obj_round_trip(tmp_path):
    m = grid_mesh(8)
    uv = np.random.default_rng(0).random((m.n_faces, 3, 2))
    nrm = np.tile(np.float32([0, 0, 1]), (m.n_vertices, 1))
    write_obj(tmp_path / "m.obj", m.vertices, m.faces, uv, "m.png", normals=nrm)
    (tmp_path / "m.png").write_bytes(b"")
    r = read_obj(tmp_path / "m.obj")
    assert np.array_equal(r.faces, m.faces) and np.allclose(r.vertices, m.vertices, atol=1e-6)
    assert np.allclose(r.corner_uv, uv, atol=1e-6) and np.allclose(r.normals, nrm)
    assert r.texture == tmp_path / "m.png"
    # polygons and negative indices
    (tmp_path / "q.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf -4 -3 -2 -1\n")
    q = read_obj(tmp_path / "q.obj")
    assert q.faces.tolist() == [[0, 1, 2], [0, 2, 3]] and q.corner_uv is None


def test_unique_uv_rows_as_numpy():
    from twinkit.mesh.obj import _unique_rows

    rng = np.random.default_rng(1)
    a = np.round(rng.integers(0, 6, (500, 2)) / 5 + rng.choice([0, 1e-7], (500, 2)), 7)
    ref, inv = np.unique(a, axis=0, return_inverse=True)
    got, ginv = _unique_rows(a)
    assert np.array_equal(got, ref) and np.array_equal(ginv, inv.ravel()) and np.array_equal(got[ginv], a)


def test_colored_glb_layout(tmp_path):
    m = grid_mesh(5)
    seg = np.zeros((m.n_vertices, 3), np.uint8)
    write_colored_glb(tmp_path / "v.glb", m.vertices, m.faces, m.colors, seg)
    doc, binary = _glb(tmp_path / "v.glb")
    attrs = doc["meshes"][0]["primitives"][0]["attributes"]
    # COLOR_0 = the texture colours (what any viewer draws), segmentation in _CLASS_COLOR (darkens nothing)
    assert list(attrs) == ["POSITION", "COLOR_0", "_CLASS_COLOR"]
    acc = doc["accessors"][attrs["COLOR_0"]]
    view = doc["bufferViews"][acc["bufferView"]]
    got = np.frombuffer(binary, "<u2", acc["count"] * 4, view["byteOffset"]).reshape(-1, 4)
    want = np.round(srgb_to_linear(m.colors).astype(np.float64) * 65535)
    assert np.abs(got[:, :3] - want).max() <= 1 and (got[:, 3] == 65535).all()
    assert doc["nodes"][0]["extras"]["site_origin_m"] == [0.5, 0.5, 0.0]


def test_textured_glb_splits_uv_seams(tmp_path):
    m = grid_mesh(4)
    uv = np.zeros((m.n_faces, 3, 2), np.float32)
    uv[: m.n_faces // 2] = 0.25  # two charts: vertices on the border get two glTF vertices
    part = GlbPart("ground", m.vertices, m.faces, np.tile(np.float32([0, 0, 1]), (m.n_vertices, 1)), uv, m.colors,
                   ubyte_attrs={"_CLASS_ID": np.ones(m.n_vertices, np.uint8)}, extras={"class_id": 1})
    empty = GlbPart("none", m.vertices[:0], m.faces[:0], m.vertices[:0], uv[:0], m.colors[:0])
    stats = write_textured_glb(tmp_path / "t.glb", [part, empty], None, generator="test", asset_extras={"a": 1})
    doc, _ = _glb(tmp_path / "t.glb")
    assert list(stats) == ["ground"] and stats["ground"]["vertices"] > m.n_vertices
    assert doc["asset"] == {"version": "2.0", "generator": "test", "extras": {"a": 1}}
    assert doc["nodes"] == [{"name": "ground", "mesh": 0, "extras": {"class_id": 1}}]
    assert "COLOR_0" in doc["meshes"][0]["primitives"][0]["attributes"]  # given colours are appearance
    assert "extensions" not in doc and len(doc["materials"]) == 1  # no variants unless asked
    cls = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["_CLASS_ID"]]
    assert doc["bufferViews"][cls["bufferView"]]["byteStride"] == 4
    trimesh = pytest.importorskip("trimesh")
    scene = trimesh.load(str(tmp_path / "t.glb"))
    assert sum(len(g.faces) for g in scene.geometry.values()) == m.n_faces


def test_topology_components_loops_fan():
    a, b = grid_mesh(5), grid_mesh(3)
    b.vertices = b.vertices + [5, 0, 0]
    m = Mesh(np.vstack([a.vertices, b.vertices]), np.vstack([a.faces, b.faces + a.n_vertices]),
             attrs={"colors": np.vstack([a.colors, b.colors])})
    n, lab = components(m.n_vertices, m.faces)
    assert n == 2 and np.bincount(lab).tolist() == [a.n_faces, b.n_faces]
    loops = boundary_loops(m.faces)
    assert sorted(len(lp) for lp in loops) == [8, 16]
    closed = fan_fill(m, loops)
    assert boundary_loops(closed.faces) == [] and closed.n_vertices == m.n_vertices + 2
    e = edges(m.faces, m.n_vertices)
    assert (e[:, 0] < e[:, 1]).all() and len(np.unique(e, axis=0)) == len(e)


def test_bad_faces_duplicates_any_winding_and_degenerates():
    from twinkit.mesh import bad_faces, drop_bad_faces

    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [2, 0, 0]], float)
    f = np.array([[0, 1, 2],   # kept
                  [2, 1, 0],   # back-to-back twin of 0: dropped
                  [1, 3, 2],   # up-facing: kept over its twin below although it comes later
                  [1, 2, 3],   # down-facing twin of 2: dropped
                  [0, 1, 4],   # collinear corners, zero area: degenerate
                  [0, 0, 2],   # repeated vertex: degenerate
                  [1, 2, 0]])  # same winding as 0, rotated: a plain duplicate
    up = np.tile(np.float32([0, 0, 1]), (5, 1))
    drop, n = bad_faces(v, f, up)
    assert drop.tolist() == [False, True, False, True, True, True, True]
    assert n == {"degenerate_faces": 2, "duplicate_faces": 3, "back_to_back_faces": 2}
    # the vertex normals decide which twin stays: with down normals the down-facing one does
    drop_dn, _ = bad_faces(v, f[[2, 3]], -up)
    assert drop_dn.tolist() == [True, False]
    m, counts = drop_bad_faces(Mesh(v, f, attrs={"normals": up}, face_attrs={"texcoord": np.arange(42.).reshape(7, 6)}))
    assert m.faces.tolist() == [[0, 1, 2], [1, 3, 2]] and m.n_vertices == 5 and counts == n
    assert m.face_attrs["texcoord"][:, 0].tolist() == [0, 12]
    clean, none = drop_bad_faces(m)
    assert clean is m and none == {"degenerate_faces": 0, "duplicate_faces": 0, "back_to_back_faces": 0}


def test_write_obj_per_vertex_uvs_groups_and_the_mtl(tmp_path):
    """The one OBJ writer in the forms its callers write: per-vertex UVs (demo site, synthetic street),
    ``g`` runs, the producer's comments and precision; the texture step's per-corner form is above."""

    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0.123456789], [0, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1.0]])
    write_obj(tmp_path / "a.obj", v, f, uv, "a.png", material="atlas", comment="one\ntwo", mtl_comment=None,
              mtl_dissolve=False, decimals=5, uv_decimals=6, groups=[("road_0", 1), ("car_13", 1)])
    assert (tmp_path / "a.obj").read_text() == (
        "# one\n# two\nmtllib a.mtl\n"
        "v 0.00000 0.00000 0.00000\nv 1.00000 0.00000 0.00000\nv 1.00000 1.00000 0.12346\nv 0.00000 1.00000 0.00000\n"
        "vt 0.000000 0.000000\nvt 1.000000 0.000000\nvt 1.000000 1.000000\nvt 0.000000 1.000000\n"
        "usemtl atlas\ng road_0\nf 1/1 2/2 3/3\ng car_13\nf 1/1 3/3 4/4\n")
    assert (tmp_path / "a.mtl").read_text() == "newmtl atlas\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1\nmap_Kd a.png\n"
    back = read_obj(tmp_path / "a.obj")
    assert np.array_equal(back.faces, f) and np.abs(back.vertices - v).max() < 1e-5


def test_edge_face_incidence_compiled_equals_numpy(monkeypatch):
    """The compiled bucket count gives numpy's unique edges, ids and counts exactly, on a mesh with open borders,
    a non-manifold edge (three faces), shuffled faces and unused vertex ids."""
    import twinkit.surface.compiled as C
    from twinkit.mesh import edge_face_incidence

    m = grid_mesh(n=12)
    f = np.asarray(m.faces, np.int64)
    rng = np.random.default_rng(0)
    f = np.vstack([f[rng.permutation(len(f))], [[0, 13, 200]]]) + 3  # a third face on edge (3, 16); ids 0-2 unused
    got = edge_face_incidence(f)
    monkeypatch.setattr(C, "ENABLED", False)
    ref = edge_face_incidence(f)
    assert C.compiled(lambda x: x) is None  # the reference really is numpy's
    for a, b in zip(got, ref):
        assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b)
    assert got[2].max() == 3 and (got[0][:, 0] < got[0][:, 1]).all()


def test_vertex_faces_lists_the_faces_around_each_vertex():
    from twinkit.mesh.topology import vertex_faces

    faces = np.array([[0, 1, 2], [0, 2, 3], [3, 4, 5]])
    vf = vertex_faces(faces, 7)
    assert vf.shape == (7, 3)
    assert sorted(vf[0].indices) == [0, 1] and sorted(vf[3].indices) == [1, 2] and len(vf[6].indices) == 0
    assert sorted(np.unique(vf[[1, 4]].indices)) == [0, 2]

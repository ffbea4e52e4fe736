"""Splitting per class: counts, names, attributes, UVs, and the class PLY round trip."""
from __future__ import annotations

import json

import numpy as np
import pytest

from twinkit import InputError
from twinkit.testing import check_plugin, run_step

from twinkit_export.classes import BY_ID, CLASSES, carla_auto_folder, palette_lut
from twinkit.mesh import Mesh, bad_faces, read_obj
from twinkit_export.classmesh import read_class_ply, write_class_ply
from twinkit_export import synthetic
from twinkit_export.split import face_classes, load_class_set, split_mesh

from conftest import SITE, plugin


@pytest.mark.parametrize("kind,name", [("step", "split_classes"), ("exporter", "fbx"),
                                       ("exporter", "usd"), ("exporter", "gltf"), ("exporter", "carla_package")])
def test_contract(kind, name):
    check_plugin(plugin(kind, name))


def test_names_follow_carla_0916_import():
    # the mesh names CARLA's MoveAssets commandlet recognises, and where everything else goes
    assert BY_ID[0].carla_name == "Road_Road" and carla_auto_folder("Road_Road") == "Road"
    assert BY_ID[1].carla_name == "Road_Sidewalk" and carla_auto_folder("Road_Sidewalk") == "SideWalk"
    assert BY_ID[9].carla_name == "Terrain" and carla_auto_folder("Terrain") == "Terrain"
    assert carla_auto_folder("Road_Marking") == "RoadLine"
    for c in CLASSES:
        assert carla_auto_folder(c.carla_name) == {"Roads": "Road", "Sidewalks": "SideWalk"}.get(c.auto_tag, "Terrain")
    assert len({c.carla_name for c in CLASSES}) == len(CLASSES)


def test_carla_tag_ids_match_installed_carla():
    carla = pytest.importorskip("carla")
    names = {k: int(v) for k, v in carla.CityObjectLabel.names.items()}
    for c in CLASSES:
        if c.train_id != 255:
            assert names[c.carla_tag] == c.carla_tag_id, c


def test_face_classes_majority_and_lone_vertices():
    faces = np.array([[0, 1, 2], [1, 3, 2], [2, 3, 4]])
    labels = np.array([0, 0, 1, 0, 2], np.uint8)
    fc, st = face_classes(faces, labels)
    # majority gives every face to class 0; vertex 2 (label 1) then takes face 1, which strands
    # nobody; vertex 4 (label 2) has only face 2, which vertex 3 now needs: it stays lone
    assert fc.tolist() == [0, 1, 0]
    assert st == {"mixed_faces": 3, "faces_given_to_lone_vertices": 1, "lone_vertices_left": 1}
    mesh = Mesh(np.eye(5, 3) + np.arange(5)[:, None], faces, face_attrs={"texcoord": np.zeros((3, 6), np.float32)})
    res = split_mesh(mesh, labels)
    assert [(m.name, m.n_faces, m.own_vertices) for m in res.meshes] == [("Road_Road", 2, 3), ("Road_Sidewalk", 1, 1)]
    # a class with no face at all cannot be drawn: its vertex is reported, not hidden
    assert res.stats["vertices_dropped"] == 1 and res.stats["loose_vertices"] == 1


def test_loose_vertices_travel_with_their_class():
    # a triangle with three labels next to a class-0 quad: the unplaced corner becomes a loose point
    faces = np.array([[0, 1, 2], [1, 3, 2], [3, 4, 2]])
    labels = np.array([0, 0, 0, 0, 1], np.uint8)
    labels2 = np.array([0, 0, 1, 0, 0], np.uint8)
    mesh = Mesh(np.random.default_rng(0).random((5, 3)), faces, face_attrs={"texcoord": np.zeros((3, 6), np.float32)})
    for lab in (labels, labels2):
        res = split_mesh(mesh, lab)
        assert sum(m.own_vertices for m in res.meshes) + res.stats["vertices_dropped"] == 5
        for m in res.meshes:
            assert m.own_vertices == int((lab == m.class_id).sum())


def test_split_invariants(street):
    _, obj, _, (v, f, uv, lab) = street
    mesh = read_obj(obj)
    res = split_mesh(mesh, lab)
    # the reconstruction's bad faces are dropped first, and counted
    n_bad = sum(synthetic.BAD_FACES.values())
    assert res.stats["input_faces"] == len(f) and res.stats["source_faces"] == len(f) - n_bad
    assert res.stats["degenerate_faces_dropped"] == synthetic.BAD_FACES["degenerate"]
    assert res.stats["duplicate_faces_dropped"] == 4 and res.stats["back_to_back_faces_dropped"] == 3
    # every other face in exactly one sub-mesh
    assert sum(m.n_faces for m in res.meshes) == len(f) - n_bad
    for m in res.meshes:
        assert not bad_faces(m.vertices, m.faces)[0].any(), m.name
    # own-vertex counts equal the label histogram and add up to the source mesh
    for m in res.meshes:
        assert m.own_vertices == int((lab == m.class_id).sum()), m.name
        assert m.name == BY_ID[m.class_id].carla_name
    assert sum(m.own_vertices for m in res.meshes) == len(v)
    assert res.stats["vertices_dropped"] == 0 and res.stats["lone_vertices_left"] == 0
    assert set(np.unique(lab).tolist()) == {m.class_id for m in res.meshes}
    # attributes: positions, palette colours and labels of the source vertices
    lut = palette_lut()
    for m in res.meshes:
        np.testing.assert_array_equal(m.vertices, mesh.vertices[m.source_index])
        np.testing.assert_array_equal(m.vertex_class, lab[m.source_index])
        np.testing.assert_array_equal(m.colors, lut[lab[m.source_index]])
        # faces map back to source faces with their UVs unchanged
        src_faces = m.source_index[m.faces]
        key = {tuple(r): i for i, r in reversed(list(enumerate(f.tolist())))}  # the first of twins is kept
        idx = np.array([key[tuple(r)] for r in src_faces.tolist()])
        np.testing.assert_allclose(m.corner_uv, mesh.corner_uv[idx], atol=0)
    # border copies sit exactly on the source vertices (no cracks)
    allsrc = np.concatenate([m.source_index for m in res.meshes])
    assert len(np.unique(allsrc)) == len(v)


def test_class_ply_round_trip(street, tmp_path):
    _, obj, _, (v, f, uv, lab) = street
    res = split_mesh(read_obj(obj), lab)
    m = res.meshes[0]
    write_class_ply(tmp_path / "c.ply", m, "texture.png")
    r = read_class_ply(tmp_path / "c.ply")
    assert (r.class_id, r.name) == (m.class_id, m.name)
    for a in ("vertices", "normals", "colors", "vertex_class", "source_index", "faces", "corner_uv"):
        np.testing.assert_array_equal(getattr(r, a), getattr(m, a))
    # and an ordinary PLY reader sees the palette and class_id
    from plyfile import PlyData

    ply = PlyData.read(str(tmp_path / "c.ply"))
    assert ply["vertex"].count == m.n_vertices
    np.testing.assert_array_equal(ply["vertex"]["class_id"], m.vertex_class)


def test_split_step_writes_manifest(class_dir, street):
    _, _, _, (v, f, uv, lab) = street
    cs = load_class_set(class_dir)
    man = json.loads((class_dir / "classes.json").read_text())
    assert (class_dir / man["texture"]).exists()
    assert sum(c["own_vertices"] for c in man["classes"]) == len(v)
    assert {c["name"] for c in man["classes"]} == {BY_ID[int(k)].carla_name for k in np.unique(lab)}
    assert len(cs.meshes) == len(man["classes"])


def test_split_rejects_wrong_label_count(street, tmp_path):
    _, obj, _, (v, *_rest) = street
    bad = tmp_path / "labels.npy"
    np.save(bad, np.zeros(len(v) - 1, np.uint8))
    with pytest.raises(InputError, match="labels.npy"):
        run_step(plugin("step", "split_classes"), tmp_path / "run", {"in_labels_npy": bad, "in_textured_mesh_obj": obj})
    assert not (tmp_path / "run" / "result").exists()


def test_split_downscales_large_texture(street, tmp_path):
    from twinkit_export.plugin import SplitParams
    from PIL import Image

    _, obj, labels, _ = street
    out = run_step(plugin("step", "split_classes"), tmp_path / "run", {"in_labels_npy": labels, "in_textured_mesh_obj": obj},
                   SplitParams(max_texture_px=128), site=SITE)
    man = json.loads((out["class_meshes"] / "classes.json").read_text())
    assert man["texture_downscaled_to"] == [128, 128]
    assert Image.open(out["class_meshes"] / man["texture"]).size == (128, 128)

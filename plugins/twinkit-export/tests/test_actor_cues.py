"""Scanned actors are what they claim (issue 45): a part of a tree labelled person, a ghost hanging in the
air, stay static; a pedestrian on the pavement is lifted. And the package checker's ``actors_geometry``
rule: an actor inside static geometry or over nothing is reported."""
from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import HAS_BPY

ROAD, VEG, PERSON = 0, 8, 11
TREE_XY, PED_XY, GHOST_XY = np.array([3.0, 0.0]), np.array([-3.0, 0.0]), np.array([0.0, 3.5])


def box_surface(lo, hi, step: float = 0.1):
    """The six faces of the box ``lo``..``hi`` (3,), each a grid of ``step``: (vertices (n, 3), faces (m, 3))."""
    vs, fs, n0 = [], [], 0
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    for ax in range(3):
        a, b = [k for k in range(3) if k != ax]
        ua = np.linspace(lo[a], hi[a], max(2, int(round((hi[a] - lo[a]) / step)) + 1))
        ub = np.linspace(lo[b], hi[b], max(2, int(round((hi[b] - lo[b]) / step)) + 1))
        ga, gb = np.meshgrid(ua, ub, indexing="ij")
        for side in (lo[ax], hi[ax]):
            p = np.zeros((ga.size, 3))
            p[:, a], p[:, b], p[:, ax] = ga.ravel(), gb.ravel(), side
            i = np.arange(ga.size).reshape(ga.shape) + n0
            q = np.c_[i[:-1, :-1].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel(), i[:-1, 1:].ravel()]
            fs.append(np.r_[q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
            vs.append(p)
            n0 += len(p)
    return np.vstack(vs), np.vstack(fs)


def street_with_a_tree():
    """A 12 x 12 m road; a tree (trunk 0.3 m to 1.2 m, crown 1.2 x 1.2 m from 1.2 to 3.4 m) whose crown's lower
    band (to 2.3 m) the labels call person; a pedestrian (0.45 x 0.3 x 1.75 m) on the road; a ghost (a person-
    labelled body 0.45 x 0.3 m from 0.45 to 1.9 m, nothing under it). Returns (vertices, faces, labels, votes
    (n, 19): the 3D classifier's, vegetation on the tree, person on the pedestrian and the ghost, road)."""
    g = np.linspace(-6, 6, 61)
    gx, gy = np.meshgrid(g, g)
    v = [np.c_[gx.ravel(), gy.ravel(), np.zeros(gx.size)]]
    i = np.arange(gx.size).reshape(gx.shape)
    q = np.c_[i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()]
    f = [np.r_[q[:, [0, 1, 2]], q[:, [0, 2, 3]]]]
    lab, vote = [np.full(gx.size, ROAD)], [np.full(gx.size, ROAD)]
    parts = [((*TREE_XY - 0.15, 0.0), (*TREE_XY + 0.15, 1.2), VEG, VEG),
             ((*TREE_XY - 0.6, 1.2), (*TREE_XY + 0.6, 3.4), VEG, VEG),
             ((*PED_XY - [0.225, 0.15], 0.0), (*PED_XY + [0.225, 0.15], 1.75), PERSON, PERSON),
             ((*GHOST_XY - [0.225, 0.15], 0.45), (*GHOST_XY + [0.225, 0.15], 1.9), PERSON, PERSON)]
    n = len(v[0])
    for lo, hi, lb, vt in parts:
        pv, pf = box_surface(lo, hi)
        v.append(pv)
        f.append(pf + n)
        n += len(pv)
        lab.append(np.full(len(pv), lb))
        vote.append(np.full(len(pv), vt))
    v, f, lab, vote = np.vstack(v), np.vstack(f), np.concatenate(lab).astype(np.uint8), np.concatenate(vote)
    crown_band = (np.linalg.norm(v[:, :2] - TREE_XY, axis=1) < 1.0) & (v[:, 2] >= 1.2) & (v[:, 2] <= 2.3)
    lab[crown_band] = PERSON
    votes = np.zeros((len(v), 19), np.float32)
    votes[np.arange(len(v)), vote] = 0.9
    return v, f, lab, votes


def _lift(votes_too: bool = True):
    from twinkit.mesh import Mesh
    from twinkit_export.movables import lift_movables

    v, f, lab, votes = street_with_a_tree()
    return lift_movables(Mesh(v, f), lab, None, None, votes if votes_too else None), v


def test_a_tree_part_labelled_person_stays_static_the_pedestrian_is_lifted():
    """The crown's band has a person's size, walls, and (through the trunk) ground contact: labels and shape
    alone lifted it (before issue 45). The 3D classifier calls it vegetation: it stays, with the tree's label."""
    res, v = _lift()
    got = [(i.name, np.round(i.center[:2], 1).tolist()) for i in res.instances]
    assert len(res.instances) == 1 and np.allclose(res.instances[0].center[:2], PED_XY, atol=0.1), got
    assert res.instances[0].cues["geometry_movable_share"] > 0.9 and res.instances[0].cues["ground_gap_m"] <= 0.25
    assert res.report["clusters_rejected"].get("static_to_geometry", 0) == 1, res.report["clusters_rejected"]
    out = res.mesh
    band = (np.linalg.norm(out.vertices[:, :2] - TREE_XY, axis=1) < 1.0) & (out.vertices[:, 2] > 1.3) & \
        (out.vertices[:, 2] < 2.2)
    assert band.sum() > 100  # the tree keeps its crown
    assert set(np.unique(res.labels[band]).tolist()) == {VEG}  # and its label, not person


def test_a_ghost_in_the_air_is_not_lifted_without_votes_either():
    """Without the 3D classifier only the ground contact is left to tell: the ghost's lowest point is 0.45 m
    above the road (more than ground_contact_m), so it stays; the pedestrian still goes."""
    res, v = _lift(votes_too=False)
    centres = [i.center[:2] for i in res.instances]
    assert not any(np.linalg.norm(c - GHOST_XY) < 1.0 for c in centres), centres
    assert any(np.linalg.norm(c - PED_XY) < 0.2 for c in centres)
    assert res.report["clusters_rejected"].get("floating", 0) == 1, res.report["clusters_rejected"]
    assert res.report["geometry_votes"] is False


def test_actor_geometry_rule_on_boxes():
    """The checker's geometry: a "pedestrian" box around the tree's crown band holds the trunk (inside static
    geometry); the ghost's mesh hangs 0.45 m over the road (floating); the pedestrian on the road is fine."""
    from twinkit_export.contract_actors import actor_boxes, actor_geometry_problems

    v, f, lab, _ = street_with_a_tree()
    band = (np.linalg.norm(v[:, :2] - TREE_XY, axis=1) < 1.0) & (v[:, 2] >= 1.2) & (v[:, 2] <= 2.3)
    ghost = (np.linalg.norm(v[:, :2] - GHOST_XY, axis=1) < 0.5) & (v[:, 2] > 0.05)
    ped = np.linalg.norm(v[:, :2] - PED_XY, axis=1) < 0.5
    ped &= v[:, 2] > 0.05
    actors = [{"name": n, "size_m": size, "scanned_prop_name": n,
               "site": {"center": [*c, size[2] / 2], "yaw_deg": 0.0, "ground_z": 0.0}}
              for n, c, size in (("TreePart", TREE_XY, [1.2, 1.2, 2.3]), ("Ghost", GHOST_XY, [0.45, 0.3, 1.9]),
                                 ("Walker", PED_XY, [0.45, 0.3, 1.75]))]
    static_f = f[~(band | ghost | ped)[f].any(axis=1)]
    probs = actor_geometry_problems(actor_boxes(actors, None), [("Static", v, static_f)],
                                    {"TreePart": v[band], "Ghost": v[ghost], "Walker": v[ped]})
    assert any(p.startswith("TreePart:") and "inside its box" in p for p in probs), probs
    assert any(p.startswith("Ghost:") and "floating" in p for p in probs), probs
    assert not any(p.startswith("Walker:") for p in probs), probs


@pytest.mark.skipif(not HAS_BPY, reason="bpy (Blender as a module) is not installed")
def test_check_package_reports_a_tree_part_lifted_as_a_pedestrian(tmp_path):
    """The package with a tree's crown band as a walker: the CARLA contract reports it under actors_geometry
    (the rule reads actors.json and the package's FBX files); without that actor the package has no such
    finding."""
    from twinkit_export.classes import palette_lut
    from twinkit_export.classmesh import class_part, write_class_ply
    from twinkit_export.carla_contract import ContractReport
    from twinkit_export.contract_actors import check_actor_geometry
    from twinkit_export.fbx import write_fbx_set

    v, f, lab, _ = street_with_a_tree()
    band = (np.linalg.norm(v[:, :2] - TREE_XY, axis=1) < 1.0) & (v[:, 2] >= 1.2) & (v[:, 2] <= 2.3)
    pkg = tmp_path / "Import" / "Pkg"
    pkg.mkdir(parents=True)

    def ply(name, cid, faces):
        vid = np.unique(faces)
        remap = np.full(len(v), -1)
        remap[vid] = np.arange(len(vid))
        cls = np.full(len(vid), cid, np.uint8)
        p = tmp_path / f"{name}.ply"
        write_class_ply(p, class_part(cid, name, v[vid], remap[faces], np.tile([0, 0, 1.0], (len(vid), 1)),
                                      palette_lut()[cls], cls, vid, np.zeros((len(faces), 3, 2))), None)
        return p

    in_band = band[f].all(axis=1)
    write_fbx_set([(pkg / "Pkg_Static.fbx", [ply("Static", VEG, f[~in_band])], {}),
                   (pkg / "Pkg_ScannedPerson_000.fbx", [ply("Person_000", PERSON, f[in_band])], {})], None)
    actor = {"name": "Person_000", "size_m": [1.2, 1.2, 2.3], "scanned_prop_name": "Pkg_ScannedPerson_000",
             "site": {"center": [*TREE_XY, 1.15], "yaw_deg": 0.0, "ground_z": 0.0}}
    (tmp_path / "actors.json").write_text(json.dumps({"actors": [actor]}))
    rep = ContractReport("Pkg")
    check_actor_geometry(rep, tmp_path)
    assert [v.rule for v in rep.violations] == ["actors_geometry"], [str(v) for v in rep.violations]
    assert "inside its box" in str(rep.violations[0])
    (tmp_path / "actors.json").write_text(json.dumps({"actors": []}))
    rep = ContractReport("Pkg")
    check_actor_geometry(rep, tmp_path)
    assert rep.ok

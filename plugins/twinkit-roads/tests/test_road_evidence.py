"""road_evidence: the aligned lanes vote for road / sidewalk where the scan's geometry agrees.

Synthetic scene: a straight road along +x (x 0..50) at y = 0, one driving lane each way (3.25 m) and a
2 m sidewalk lane beyond each (netconvert's layout). The mesh is a height field:
- south (y < 0): carriageway to y = -3.25, then a raised pavement (+0.15 m) to the mesh edge (y = -7),
  wider than the sidewalk lane;
- north (y > 0): the carriageway goes on to y = 5.25 (a parking strip the OpenDRIVE does not know:
  its sidewalk lane lies on the carriageway level), raised pavement 5.25..9, a 6 m building from y = 9.
The "scan" votes road on all the ground (the commonest error: pavement voted road), building on the
building, and car on a small flat patch of the south pavement.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

LANES = """<lanes><laneSection s="0">
  <left><lane id="2" type="sidewalk" level="false"><width sOffset="0" a="2.0" b="0" c="0" d="0"/></lane>
        <lane id="1" type="driving" level="false"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane></left>
  <center><lane id="0" type="none" level="false"/></center>
  <right><lane id="-1" type="driving" level="false"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane>
         <lane id="-2" type="sidewalk" level="false"><width sOffset="0" a="2.0" b="0" c="0" d="0"/></lane></right>
</laneSection></lanes>"""


def xodr(dy: float = 0.0) -> str:
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<OpenDRIVE><header revMajor="1" revMinor="4" name="" version="1.00"/>
<road name="A" length="50.0" id="1" junction="-1">
  <link/>
  <planView><geometry s="0" x="0" y="{dy}" hdg="0" length="50.0"><line/></geometry></planView>
  <elevationProfile><elevation s="0" a="0" b="0" c="0" d="0"/></elevationProfile>
  {LANES}
</road>
</OpenDRIVE>
"""


def scene():
    xs = np.arange(0.0, 50.0 + 1e-9, 0.25)
    ys = np.arange(-7.0, 22.0 + 1e-9, 0.25)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    Z = np.zeros_like(X)
    Z[Y < -3.25] = 0.15  # south pavement
    Z[(Y > 5.25) & (Y < 9.0)] = 0.15  # north pavement beyond the parking strip
    Z[Y >= 9.0] = 6.0  # building roof
    V = np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1)
    nx, ny = len(xs), len(ys)
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])  # counter-clockwise from above
    L = np.where(V[:, 2] > 1.0, 2, 0).astype(np.uint8)
    car = (V[:, 0] >= 20) & (V[:, 0] <= 22) & (V[:, 1] >= -5.0) & (V[:, 1] <= -4.0)
    L[car] = 13
    return V, F, L, car


def write_inputs(tmp_path, dy: float = 0.0, labels=None):
    from twinkit.mesh import write_colored_ply

    V, F, L, _ = scene()
    write_colored_ply(tmp_path / "textured_mesh.ply", V, F, np.full((len(V), 3), 128, np.uint8))
    np.save(tmp_path / "labels.npy", L if labels is None else labels)
    (tmp_path / "aligned.xodr").write_text(xodr(dy))
    return {"in_aligned_xodr": tmp_path / "aligned.xodr", "in_textured_mesh_ply": tmp_path / "textured_mesh.ply",
            "in_labels_npy": tmp_path / "labels.npy"}


def run(tmp_path, inputs, **params):
    from twinkit.testing import plugin_from_module, run_step

    import twinkit_roads.plugin as roads

    p = roads.RoadEvidenceParams(**params)
    out = run_step(plugin_from_module(roads, "step", "road_evidence"), tmp_path / "run", inputs, p)
    return np.load(out["labels.npy"]), json.loads(out["road_evidence.json"].read_text()), out


def band(V, y0, y1, x0=3.0, x1=47.0):
    return (V[:, 0] > x0) & (V[:, 0] < x1) & (V[:, 1] > y0) & (V[:, 1] < y1)


def test_sidewalk_lane_relabels_the_raised_band_voted_road(tmp_path):
    V, F, L, car = scene()
    new, doc, out = run(tmp_path, write_inputs(tmp_path))
    assert set(out) == {"labels.npy", "road_evidence.json", "road_evidence.png"}
    lane = band(V, -5.0, -3.6) & ~car
    assert (new[lane] == 1).mean() > 0.95  # under the south sidewalk lane: raised, voted road -> sidewalk
    beyond = band(V, -6.5, -5.5) & ~car
    assert (new[beyond] == 1).mean() > 0.95  # the rest of the pavement it lies on (the plateau) too
    assert (new[band(V, -3.0, 3.0)] == 0).all()  # carriageway stays road
    assert (new[car] == 13).all()  # a clear non-ground class under a lane is not relabelled...
    assert doc["per_vote"]["sidewalk"]["disagree_label_m2"] > 1.0  # ...but reported
    assert doc["transitions"].keys() == {"road -> sidewalk"}
    # north: the sidewalk lane lies on the carriageway level (a parking strip): a disagreement, no relabel
    assert (new[band(V, 3.5, 5.0)] == 0).all()
    assert doc["per_vote"]["sidewalk"]["disagree_geometry_m2"] > 0.5 * 2.0 * 50 * 0.8
    assert (new[band(V, 5.6, 8.6)] == 0).all()  # its raised pavement has no agreeing lane: left alone
    assert (new[V[:, 2] > 1] == 2).all()


def test_without_the_plateau_only_the_lane_itself_votes(tmp_path):
    V, F, L, car = scene()
    new, doc, _ = run(tmp_path, write_inputs(tmp_path), plateau=False)
    assert (new[band(V, -5.0, -3.6) & ~car] == 1).mean() > 0.95
    assert (new[band(V, -6.5, -5.5)] == 0).all()


def test_network_shifted_10_m_over_the_building_is_reported_and_relabels_nothing(tmp_path):
    V, F, L, _ = scene()
    new, doc, _ = run(tmp_path, write_inputs(tmp_path, dy=10.0))
    assert (new == L).all()
    assert doc["changed_vertices"] == 0
    assert doc["disagreement_geometry_m2"] > 200  # the lanes over the roof and the pavements
    assert doc["disagreement_fraction"] > 0.5
    assert doc["vetoed_lanes"]
    # the same network in place does relabel: the veto is what stops it
    new0, doc0, _ = run(tmp_path / "inplace", write_inputs(tmp_path, dy=0.0))
    assert doc0["changed_vertices"] > 1000 and doc0["disagreement_fraction"] < 0.5


def test_network_whose_driving_lanes_often_disagree_votes_nowhere(tmp_path):
    """Shifted 1.5 m south, the south driving lane lies partly on the raised pavement: each lane still
    agrees over more than half its surface, but the driving lanes of the network disagree over about
    a fifth of theirs, above max_network_disagreement (0.10), so no lane votes. A lax threshold lets
    the same network relabel."""
    V, F, L, _ = scene()
    new, doc, _ = run(tmp_path, write_inputs(tmp_path, dy=-1.5))
    assert doc["network_vetoed"] and doc["network_disagreement"] > 0.10
    assert doc["changed_vertices"] == 0 and (new == L).all()
    new_lax, doc_lax, _ = run(tmp_path / "lax", write_inputs(tmp_path, dy=-1.5), max_network_disagreement=0.5)
    assert not doc_lax["network_vetoed"] and doc_lax["changed_vertices"] > 0


def test_switched_off_labels_pass_through(tmp_path):
    V, F, L, _ = scene()
    new, doc, out = run(tmp_path, write_inputs(tmp_path), enabled=False)
    assert (new == L).all() and new.dtype == L.dtype
    assert doc["enabled"] is False
    assert out["road_evidence.png"].is_file()


def test_report_only_changes_nothing_but_reports(tmp_path):
    V, F, L, _ = scene()
    new, doc, _ = run(tmp_path, write_inputs(tmp_path), relabel=False)
    assert (new == L).all()
    assert doc["per_vote"]["sidewalk"]["relabelled_m2"] > 50


def test_evaluates_against_ground_truth_when_given(tmp_path):
    V, F, L, car = scene()
    inputs = write_inputs(tmp_path)
    gt = L.copy()
    gt[(V[:, 2] > 0.1) & (V[:, 2] < 1)] = 1
    np.save(tmp_path / "gt_labels.npy", gt)
    _, doc, _ = run(tmp_path, {**inputs, "in_gt_labels_npy": tmp_path / "gt_labels.npy"})
    ev = doc["evaluation"]
    assert ev["iou_after"]["sidewalk"] > ev["iou_before"]["sidewalk"] + 20


@pytest.mark.parametrize("bad", ["labels", "xodr", "mesh"])
def test_bad_input_names_the_file(tmp_path, bad):
    from twinkit import InputError

    inputs = write_inputs(tmp_path)
    if bad == "labels":
        np.save(tmp_path / "labels.npy", np.zeros(10, np.uint8))
        match = "labels.npy"
    elif bad == "xodr":
        (tmp_path / "aligned.xodr").write_text("not an OpenDRIVE")
        match = "aligned.xodr"
    else:
        (tmp_path / "textured_mesh.ply").write_text("ply\nbroken")
        match = "textured_mesh.ply"
    with pytest.raises(InputError, match=match):
        run(tmp_path, inputs)


def test_a_capture_sampled_in_rings_passes_its_labels_through_and_says_why(tmp_path):
    """A single spinning sweep samples its ground in rings: no kerb step can be measured across them, so the level
    that decides which lanes may vote cannot be told (on the real sweeps every network, the scan's own too, came out
    'disagreeing with the scan's ground over 96 %', blaming the labels). Its labels pass through with that reason;
    the same scene read as a street scan (two-way share 0.99) still votes."""
    from twinkit import artefacts as A

    _, _, L, _ = scene()
    relabelled = {}
    for name, share in (("sweep", 0.3), ("street", 0.99)):
        (tmp_path / name).mkdir()
        inputs = write_inputs(tmp_path / name)
        meta = tmp_path / name / "points_meta.json"
        A.write_points_meta(meta, {"source": {"reader": "test"}, "counts": {}, "fields": {}, "frame": {},
                                   "bounds_m": [], "density": {"points": 0, "spacing_m": 0.03, "capture": "mobile",
                                                               "ground_two_way_share": share}})
        new, doc, out = run(tmp_path / name, {**inputs, "in_points_meta_json": meta})
        relabelled[name] = int((new != L).sum())
        if name == "sweep":
            assert doc["rings"] is True and doc["ground_two_way_share"] == 0.3 and "rings" in doc["note"]
            assert out["road_evidence.png"].is_file()
    assert relabelled["sweep"] == 0 and relabelled["street"] > 100

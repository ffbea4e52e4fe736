"""One connected sidewalk surface per block (twinkit_export.sidewalks), and the package rules that check it
and the parked cars (twinkit_export.contract_sidewalks)."""
from __future__ import annotations

import numpy as np
import pytest

from twinkit.cityscapes import POLE, ROAD, SIDEWALK, TERRAIN
from twinkit_export import contract_sidewalks as cs
from twinkit_export.sidewalks import connect_sidewalks, sidewalk_components
from twinkit_export.split import face_classes, split_mesh

from conftest import straight_xodr


def grid(nx: int = 201, ny: int = 101, step: float = 0.1):
    """A flat grid 20 x 10 m (x -10..10, y -10..0): vertices, faces, (ny, nx) index array."""
    xs = np.arange(nx) * step - 10.0
    ys = np.arange(ny) * step - 10.0
    gx, gy = np.meshgrid(xs, ys)
    i = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel()
    faces = np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    return np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)]), faces, gx, gy


def pavement():
    """A pavement (y < -4, 0.12 m above the road) along a road (y > -4), as the scan labels it: the pavement
    cut in two by a 0.3 m band of it labelled road at x = 0, a pole's foot (x = -3), a sidewalk speck on the
    road (a lone vertex) and a sidewalk patch on the road at road level, 1 m from the kerb."""
    v, f, gx, gy = grid()
    raised = gy < -4.0
    v[:, 2] = np.where(raised.ravel(), 0.12, 0.0)
    lab = np.where(raised, SIDEWALK, ROAD).astype(np.uint8)
    lab[raised & (np.abs(gx) < 0.15)] = ROAD  # mislabelled pavement: the pavement in two, x < 0 and x > 0
    lab[raised & (np.abs(gx + 3) < 0.2) & (np.abs(gy + 7) < 0.2)] = POLE  # a pole's foot: walked around
    lab[(np.abs(gx - 3) < 0.05) & (np.abs(gy + 1) < 0.05)] = SIDEWALK  # a lone sidewalk vertex on the road
    lab[(np.abs(gx + 5) < 0.5) & (np.abs(gy + 2.5) < 0.5)] = SIDEWALK  # a sidewalk patch on the road, 1.5 m away
    return v, f, lab.ravel()


def _count(v, f, lab) -> int:
    fc, _ = face_classes(f, lab)
    return len(sidewalk_components(v, f, fc)[2])


def test_fragments_joined_or_dissolved():
    v, f, lab = pavement()
    assert _count(v, f, lab) >= 3  # today: two halves of the pavement, the speck, the patch on the road
    res = connect_sidewalks(v, f, lab, keep_m2=5.0)
    assert res.components_before == _count(v, f, lab)
    assert res.components_after == 1 and _count(v, f, res.labels) == 1
    new = res.labels.reshape(101, 201)
    assert (new[:60, 100] == SIDEWALK).any()  # across the mislabelled band, on the pavement's level: joined
    assert new[30, 70] == POLE
    assert (new[70:, :] != SIDEWALK).all()  # the pieces on the road: dissolved into the road ...
    assert new[75, 50] == ROAD  # ... not joined over the kerb
    # the split then exports one walkable surface
    from twinkit.mesh import Mesh

    parts = {p.name: p for p in split_mesh(Mesh(vertices=v, faces=f), res.labels).meshes}
    assert cs.components(parts["Road_Sidewalk"].mesh.vertices, parts["Road_Sidewalk"].mesh.faces)[1] == 1


def test_large_separate_surfaces_stay():
    v, f, gx, gy = grid()
    lab = np.full(len(v), TERRAIN, np.uint8)
    lab[(gy.ravel() < -8)] = SIDEWALK
    lab[(gy.ravel() > -2)] = SIDEWALK  # 6 m of grass between two pavements: not a gap to close
    res = connect_sidewalks(v, f, lab, keep_m2=10.0)
    assert res.components_after == 2 and res.dissolved == 0 and res.joined == 0


# ----------------------------------------------------------------------------- the package rules

def test_block_rule_counts_pieces_per_block():
    """A straight road (conftest.straight_xodr: centre y = 5, one lane each way of 3.5 m): south of it one
    block, north another. A pavement cut in two in the south block is two surfaces there."""
    v, f, gx, gy = grid()
    v = v + [0.0, 0.0, 0.0]
    lab = np.where(gy.ravel() < -3, SIDEWALK, TERRAIN)
    sel = (lab[f] == SIDEWALK).all(1)
    whole = cs.sidewalk_blocks(v, f[sel], straight_xodr(length_m=40.0, y0=5.0))
    assert whole.components == 1 and not whole.split_blocks and not whole.stray
    cut = sel & (np.abs(v[f, 0].mean(1)) > 0.3)
    two = cs.sidewalk_blocks(v, f[cut], straight_xodr(length_m=40.0, y0=5.0))
    assert list(two.split_blocks.values())[0] == pytest.approx([66.9, 66.9], abs=0.5)


def test_parked_rule_reads_carla_waypoints():
    xodr = straight_xodr(length_m=40.0, y0=5.0)  # right lane y 1.5..5, sidewalk 1.5..-0.5
    car = {"name": "Car_000", "class": "car", "transform": {"x": 10.0, "y": -0.5, "z": 0.2, "yaw": 0.0}}
    off = {"name": "Car_001", "class": "car", "transform": {"x": 10.0, "y": -3.0, "z": 0.2, "yaw": 0.0}}
    bike = {"name": "Bicycle_002", "class": "bicycle", "transform": {"x": 12.0, "y": -0.5, "z": 0.2, "yaw": 0.0}}
    hits = cs.parked_on_sidewalk([car, off, bike], xodr)  # CARLA frame: y = -north, so y -0.5 is 0.5 m north
    assert [h["name"] for h in hits] == ["Car_000"] and hits[0]["lane"] == -2


def test_unwelded_parts_are_one_surface():
    """A modelled mesh whose parts keep their own vertices (the demo's ground-truth mesh: each part a shell of its
    own) is one surface where the parts meet: nothing is dissolved into the road."""
    verts, faces, n = [], [], 0
    for t in range(10):  # a pavement of ten 2 x 2 m tiles side by side, none sharing a vertex with the next
        v, f, _, _ = grid(5, 5, 0.5)
        v[:, 0] += 10.0 + 2.0 * t
        verts.append(v)
        faces.append(f + n)
        n += len(v)
    road, rf, _, _ = grid(41, 5, 0.5)  # the road beside it, its own shell too
    road[:, 1] += 2.0
    V, F = np.vstack(verts + [road]), np.vstack(faces + [rf + n])
    L = np.r_[np.full(n, SIDEWALK), np.full(len(road), ROAD)].astype(np.uint8)
    fc, _ = face_classes(F, L)
    assert len(sidewalk_components(V, F, fc)[2]) == 10  # by shared vertices alone: ten pieces of 4 m^2
    res = connect_sidewalks(V, F, L, keep_m2=5.0)
    assert res.components_before == 1 and res.components_after == 1 and res.dissolved == 0
    assert (res.labels == L).all()


def test_a_sag_across_the_pavement_is_crossed_the_road_level_is_not():
    """The mislabelled band across the pavement sags 6.5 cm (Poisson's sag over a scan shadow: on the full-density
    `large` site a 0.4 m band 5-6 cm deep, labelled road, cut a block's sidewalk in two and CARLA's walkers on the
    smaller piece could never leave it): a dip less than half the kerb (the pavement's height over the road beside
    it) is the pavement's, and the halves are joined. The same band down at the road's level stays a cut."""
    v, f, lab = pavement()
    pave = v[:, 2] > 0.1
    v[pave, 2] = 0.15  # a 15 cm kerb
    for depth, joined in ((0.065, True), (0.15, False)):
        w = v.copy()  # a V 1.2 m wide (no edge steeper than the walkable slope), deepest on the band
        w[pave, 2] = 0.15 - depth * np.clip(1 - np.abs(v[pave, 0]) / 0.6, 0, 1)
        res = connect_sidewalks(w, f, lab, keep_m2=5.0)
        new = res.labels.reshape(101, 201)
        assert (new[:60, 100] == SIDEWALK).any() == joined, depth
        assert (res.components_after == 1) == joined, depth

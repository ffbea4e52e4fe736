"""The simulated captures (captures.py): ring structure, labels, density, determinism, the CLI."""
from __future__ import annotations

import json

import numpy as np
import pytest

from twinkit import cityscapes as cs

SEED = 101


@pytest.fixture(scope="module")
def world():
    from twinkit_demo_site.captures import build_world

    return build_world(SEED, "small")


def _cap(world, kind, rng_seed=1, density=1.0):
    from twinkit_demo_site.captures import simulate_capture

    return simulate_capture(SEED, kind, rng_seed, density=density, world=world)


@pytest.fixture(scope="module")
def sweep(world):
    return _cap(world, "spinning")


def test_spinning_has_rings_and_falls_off_with_range(sweep):
    ring, xyz, o = sweep["ring"], sweep["xyz"].astype(np.float64), sweep["origin"][0]
    per_ring = np.bincount(ring, minlength=64)
    assert sweep["meta"]["beams"] == 64 and (per_ring[32:] > 500).all()  # every lower beam returns a ring
    r = np.linalg.norm(xyz - o, axis=1)
    # each lower beam's ground returns lie at one range (a ring), increasing from the lowest beam upwards
    ground = np.isin(sweep["label"], cs.GROUND)
    med = np.array([np.median(r[ground & (ring == b)]) for b in (63, 55, 47)])
    assert np.all(np.diff(med) > 0.3), med
    # areal density near the car is far higher than far away
    rh = np.linalg.norm(xyz[:, :2] - o[:2], axis=1)
    near = (rh > 4) & (rh < 8)
    far = (rh > 20) & (rh < 24)
    dn = near.sum() / (np.pi * (8 ** 2 - 4 ** 2))
    df = far.sum() / (np.pi * (24 ** 2 - 20 ** 2))
    assert dn > 8 * df, (dn, df)
    assert 0 <= sweep["intensity"].min() and sweep["intensity"].max() <= 1


def test_labels_match_the_surfaces_hit(world, sweep):
    from twinkit_demo_site.captures import _ground_at

    xyz = sweep["xyz"].astype(np.float64)
    # low flat returns under open sky are ground classes, and the ground label under them agrees
    zg, lab = _ground_at(world, xyz[:, :2], z0=40.0)
    on_ground = np.abs(xyz[:, 2] - zg) < 0.06
    share = np.isin(sweep["label"][on_ground], cs.GROUND).mean()
    assert share > 0.95, share
    agree = (sweep["label"][on_ground] == lab[on_ground]).mean()
    assert agree > 0.95, agree
    # points labelled building or car stand above the road (z = 0) and curb
    for c, zmin in ((cs.BUILDING, 0.8), (cs.CAR, 0.4)):
        m = sweep["label"] == c
        assert m.sum() > 50 and np.median(xyz[m, 2]) > zmin


def test_aerial_has_almost_no_facade_points(world, sweep):
    def facade_share(c):
        b = c["label"] == cs.BUILDING
        nz = np.abs(world.tracer.face_normals[world.tracer.closest_faces(c["xyz"][b])][:, 2])
        return b.sum(), (nz < 0.3).mean()

    c = _cap(world, "aerial")
    n_b, share = facade_share(c)
    assert n_b > 500 and share < 0.12, (n_b, share)
    assert facade_share(sweep)[1] > 0.9  # a street-level sweep sees facades
    assert np.isin(c["label"], cs.GROUND).mean() > 0.4


@pytest.mark.parametrize("kind", ["spinning", "tls", "aerial"])
def test_density_factor_scales_counts(world, kind):
    lo = _cap(world, kind, rng_seed=3, density=0.25)["raw_points"]
    hi = _cap(world, kind, rng_seed=3, density=1.0)["raw_points"]
    assert 2.5 < hi / lo < 6, (lo, hi)


def test_same_seed_same_capture_other_seed_other_pose(world):
    a = _cap(world, "tls", rng_seed=5, density=0.3)
    b = _cap(world, "tls", rng_seed=5, density=0.3)
    c = _cap(world, "tls", rng_seed=6, density=0.3)
    assert np.array_equal(a["xyz"], b["xyz"]) and np.array_equal(a["label"], b["label"])
    assert np.array_equal(a["intensity"], b["intensity"])
    assert not np.array_equal(a["origin"], c["origin"])


def test_mobile_reuses_the_van_and_cli_writes_npz_and_manifest(tmp_path):
    from twinkit_demo_site.captures import main

    main(["--out", str(tmp_path), "--seeds", str(SEED), "--kinds", "mobile", "--size", "small",
          "--density-min", "0.2", "--density-max", "0.2", "--max-points", "20000"])
    man = json.loads((tmp_path / "manifest.json").read_text())
    (rec,) = man["captures"]
    z = np.load(tmp_path / rec["file"])
    assert z["xyz"].shape == (rec["points"], 3) and z["xyz"].dtype == np.float32 and rec["points"] <= 20000
    assert len(z["origin"]) > 50  # one origin per van position
    assert z["sensor"].max() < len(z["origin"])
    assert sum(rec["counts"].values()) == rec["points"] and rec["counts"].get("road", 0) > 0.2 * rec["points"]


def test_layout_variety_changes_the_site_and_its_default_is_the_demo():
    from twinkit_demo_site.layout import Variety, build_scene, random_variety
    from twinkit_demo_site.textures import build_atlas

    atlas = build_atlas(0)
    plain = build_scene(30.0, 0, atlas)
    same = build_scene(30.0, 0, atlas, Variety())
    assert np.array_equal(plain.mesh.vertices, same.mesh.vertices) and plain.counts == same.counts
    v = random_variety(np.random.default_rng(1))
    v.street_trees, v.floors = 1.0, (8, 9)
    varied = build_scene(30.0, 0, atlas, v)
    assert varied.counts["trees"] > plain.counts["trees"]
    assert max(b["max"][2] for b in varied.buildings) > max(b["max"][2] for b in plain.buildings)


def test_streets_go_on_beyond_the_site_edge(world):
    """The apron: ground to the sensor's range and, along the road arms, buildings and trees beyond the edge."""
    tr = world.tracer
    H = world.scene.dims.half_m
    c = tr.mesh.vertices[tr.mesh.faces].mean(1)
    out = (np.abs(c[:, 0]) > H + 1) | (np.abs(c[:, 1]) > H + 1)
    labs = set(np.unique(tr.face_labels[out]).tolist())
    assert {cs.ROAD, cs.SIDEWALK, cs.TERRAIN, cs.BUILDING, cs.VEGETATION} <= labs
    assert np.abs(tr.mesh.vertices[:, :2]).max() > H + 100


def test_surface_depth_puts_returns_inside_foliage_and_behind_window_panes():
    from twinkit_demo_site.sensor import Sensor, surface_depth

    s = Sensor(noise_m=0.0, dropout=0.0, cos_min=0.0, snr_thr=1e-3, gain=1.0, range_half_m=100.0,
               refl=np.full(256, 0.3, np.float32), max_range_m=100.0, foliage_m=0.3, glass=0.5, relief_m=0.01,
               window_period_m=3.0)
    rng = np.random.default_rng(0)
    # a facade in the plane x = 5 (normal -x), 30 m long and 9 m high, hit head-on
    u, z = np.meshgrid(np.arange(0, 30, 0.05), np.arange(0.2, 9, 0.05))
    hit = np.column_stack([np.full(u.size, 5.0), u.ravel(), z.ravel()])
    nrm = np.tile([-1.0, 0.0, 0.0], (len(hit), 1))
    d = surface_depth(s, hit, nrm, np.full(len(hit), cs.BUILDING, np.uint8), np.ones(len(hit)), rng)
    deep = d > 0.079  # the relief stays within 3 cm; a window's frame is 8-25 cm deep, a room 0.2-2.5 m
    assert 0.15 < deep.mean() < 0.3  # windows cover about a fifth of a facade
    assert 0.3 < (d > 0.26).mean() / deep.mean() < 0.7  # half from the rooms behind the panes (glass 0.5)
    assert np.abs(d[d < 0.079]).max() <= 0.031  # the wall between windows: relief only (3 sigma)
    # windows repeat along the facade with the bay's period (the row of points through a window band)
    zs = np.unique(hit[:, 2])
    row = hit[:, 2] == zs[np.argmax([deep[hit[:, 2] == v].mean() for v in zs])]
    on = np.convolve(deep[row].astype(float), np.ones(5) / 5, mode="same") > 0.5
    starts = np.flatnonzero(np.diff(on.astype(int)) == 1)
    assert len(starts) >= 8 and np.allclose(np.diff(hit[row][starts, 1]), 3.0, atol=0.2)
    # foliage: into the crown, never out of it; the road and a roof stay where they are
    veg = surface_depth(s, hit[:5000], nrm[:5000], np.full(5000, cs.VEGETATION, np.uint8), np.ones(5000), rng)
    assert veg.min() >= 0 and 0.2 < veg.mean() < 0.35 and veg.max() <= 1.2
    up = np.tile([0.0, 0.0, 1.0], (100, 1))
    for c in (cs.ROAD, cs.BUILDING):
        assert not surface_depth(s, hit[:100], up, np.full(100, c, np.uint8), np.ones(100), rng).any()


def test_surfaces_are_opt_in_and_keep_the_pose(world):
    from twinkit_demo_site.captures import simulate_capture

    a = simulate_capture(SEED, "spinning", 2, density=0.3, world=world)
    b = simulate_capture(SEED, "spinning", 2, density=0.3, world=world, surfaces=True)
    assert a["meta"]["foliage_m"] == 0 and a["meta"]["glass"] == 0  # off by default: clean skins
    assert b["meta"]["foliage_m"] >= 0.1 and np.array_equal(a["origin"], b["origin"])
    assert len(a["xyz"]) != len(b["xyz"]) or not np.array_equal(a["xyz"], b["xyz"])


def test_a_variety_with_tall_hedges_grows_its_front_garden_hedges_and_the_demo_keeps_its_bushes():
    # real trimmed hedges stand 1-3 m, above a single sweep's top beam near them; the demo's bushes 0.6-1.1 m
    from twinkit_demo_site.layout import Variety, build_scene
    from twinkit_demo_site.textures import build_atlas

    atlas = build_atlas(0)

    def hedge_band(hedge_m):
        v = Variety(setback_m=5.0, hedges=1.0, hedge_m=hedge_m)
        m = build_scene(30.0, 0, atlas, v).mesh
        veg = m.attrs["label"] == cs.VEGETATION
        z = m.vertices[:, 2] - np.median(m.vertices[m.attrs["label"] == cs.ROAD, 2])
        return int((veg & (z > 1.4) & (z < 2.6)).sum())

    short, tall = hedge_band(0.0), hedge_band(2.5)
    assert tall > 5 * short + 1000, (short, tall)
    from twinkit_demo_site.layout import random_variety

    plain, tall_v = (random_variety(np.random.default_rng([104, 10]), t) for t in (False, True))
    assert plain.hedge_m == 0.0 and 0.6 <= tall_v.hedge_m <= 3.0  # opt-in: a seed's other knobs stay as they were
    assert (plain.setback_m, plain.floors, plain.sidewalk_m) == (tall_v.setback_m, tall_v.floors, tall_v.sidewalk_m)


def test_materials_order_the_intensities_and_change_nothing_else(world):
    """With ``materials`` the road's asphalt comes back darker than the grass in every capture and darker than
    the pavement's paving in most (a quarter of the sites pave with asphalt); the pose and the other draws are
    those of the capture without it (its draws come from a child stream)."""
    from twinkit_demo_site.captures import simulate_capture

    darker_than_paving = 0
    for rs in range(1, 9):
        plain = simulate_capture(SEED, "tls", rs, density=0.3, world=world)
        mat = simulate_capture(SEED, "tls", rs, density=0.3, world=world, materials=True)
        assert np.array_equal(plain["origin"], mat["origin"]) and plain["meta"]["noise_m"] == mat["meta"]["noise_m"]
        med = {c: np.median(mat["intensity"][mat["label"] == c]) for c in (cs.ROAD, cs.SIDEWALK, cs.TERRAIN)}
        assert med[cs.ROAD] < med[cs.TERRAIN], (rs, med)
        darker_than_paving += med[cs.ROAD] < 0.85 * med[cs.SIDEWALK]
    assert darker_than_paving >= 5, darker_than_paving

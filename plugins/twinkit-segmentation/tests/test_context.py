"""3D context in the vote: each geometric cue changes the fused label where the physics says so, and
only there (each test fails with its cue switched off)."""
import numpy as np
import pytest

from twinkit.cityscapes import (BICYCLE, BUILDING, CAR, FENCE, MOTORCYCLE, N_CLASSES, POLE, ROAD, SIDEWALK, TERRAIN,
                                TRAFFIC_LIGHT, TRAFFIC_SIGN, VEGETATION, WALL)
from twinkit.mesh import edges as mesh_edges
from twinkit.mesh.core import vertex_normals
from twinkit.street.ground import LocalGround
from twinkit_segmentation.context import CUES, DEFAULT_CUES, ContextOptions, fuse_with_context, geometric_context


def heightfield(z_of, size=(24.0, 16.0), step=0.25):
    """A grid mesh z = z_of(x, y) over [-w/2, w/2] x [-h/2, h/2]: (vertices, faces, normals, edges)."""
    xs = np.arange(-size[0] / 2, size[0] / 2 + 1e-9, step)
    ys = np.arange(-size[1] / 2, size[1] / 2 + 1e-9, step)
    X, Y = np.meshgrid(xs, ys)
    v = np.column_stack([X.ravel(), Y.ravel(), z_of(X.ravel(), Y.ravel())])
    nx = len(xs)
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(len(ys) - 1))
    a = (j * nx + i).ravel()
    f = np.vstack([np.column_stack([a, a + 1, a + nx + 1]), np.column_stack([a, a + nx + 1, a + nx])])
    return v, f, vertex_normals(v, f), mesh_edges(f, len(v))


def votes(n, **shares):
    p = np.zeros((n, N_CLASSES))
    for name, s in shares.items():
        p[:, globals()[name.upper()]] = s
    return p


def in_box(v, x0, x1, y0, y1):
    return (v[:, 0] >= x0) & (v[:, 0] <= x1) & (v[:, 1] >= y0) & (v[:, 1] <= y1)


def test_local_ground_ignores_a_car_and_follows_a_slope():
    car = lambda x, y: np.where((np.abs(x) <= 2.25) & (np.abs(y) <= 0.9), 1.5, 0.0)  # noqa: E731
    v, f, n, _ = heightfield(lambda x, y: 0.08 * x + car(x, y))  # an 8 % street with a car on it
    h = LocalGround(v, n[:, 2] >= 0.85, window="opening", window_m=3.0).height(v)
    roof = in_box(v, -2.0, 2.0, -0.7, 0.7)
    assert np.abs(h[roof] - 1.5).max() < 0.1  # the roof is 1.5 m above the ground, not ground
    inner = in_box(v, -10.5, 10.5, -6.5, 6.5) & ~in_box(v, -2.5, 2.5, -1.2, 1.2)  # (at the scan's edge the
    assert np.abs(h[inner]).max() < 0.03  # opening sinks by up to slope x window / 2); a window minimum would here
    assert np.abs(v[inner, 2] - (v[inner, 0] - 1.5) * 0.08 - h[inner]).max() > 0.1  # sink by 12 cm everywhere


def test_ground_cue_flat_patch_beside_a_car_keeps_its_ground_class():
    car = (lambda x, y: (np.abs(x) <= 2.25) & (np.abs(y) <= 0.9))  # noqa: E731
    v, f, n, e = heightfield(lambda x, y: np.where(car(x, y), 1.5, 0.0))
    p = votes(len(v), road=1.0)
    on_car = in_box(v, -2.2, 2.2, -0.85, 0.85)
    # the ground beside the car (past its wall's foot): every view votes car there
    spill = in_box(v, -3.0, 3.0, 1.4, 2.5)
    p[in_box(v, -3.0, 3.0, 0.9, 1.4)] = votes(1, car=1.0)
    p[on_car | spill] = votes(1, car=1.0)
    lab, _, met = fuse_with_context(p, v, n, e)
    assert (lab[spill] == ROAD).mean() > 0.95
    assert (lab[on_car] == CAR).all()  # the roof stays car (raised, not ground)
    assert met["ground_changed"] > 0 and met["explained_away"] > 0
    off, _, _ = fuse_with_context(p, v, n, e, cues=[c for c in CUES if c != "ground"])
    assert (off[spill] == CAR).mean() > 0.95


def curb_street(curb_m=0.15):
    # carriageway x < 0 at z = 0 with a 2 % camber, a sidewalk band 0 <= x <= 3 raised by a curb, grass beyond
    return heightfield(lambda x, y: np.where((x >= 0) & (x <= 3.0), curb_m, 0.02 * np.minimum(0, x + 12) * 0 +
                                             np.where(x < 0, 0.02 * (6 - np.abs(x + 6)), 0.0)))


def test_curb_cue_raised_band_beside_the_road_becomes_sidewalk_when_votes_are_split():
    v, f, n, e = curb_street()
    p = votes(len(v), road=0.6, sidewalk=0.4)  # split everywhere, road ahead
    lab, _, met = fuse_with_context(p, v, n, e)
    band = in_box(v, 0.3, 2.7, -8, 8)
    road = in_box(v, -11.5, -0.5, -8, 8)
    assert (lab[band] == SIDEWALK).mean() > 0.95
    assert (lab[road] == ROAD).all()  # the carriageway (and its cambered crown, 12 cm over 6 m) stays road
    assert met["curb_changed"] > 0
    off, _, _ = fuse_with_context(p, v, n, e, cues=[c for c in CUES if c != "curb"])
    assert (off[band] == ROAD).all()


def test_curb_cue_needs_a_step_not_a_slope():
    v, f, n, e = heightfield(lambda x, y: 0.06 * x)  # a 6 % ramp rises 15 cm over 2.5 m but has no step
    ctx = geometric_context(v, n)
    assert not ctx["curb"].any()
    v2, _, n2, _ = curb_street(curb_m=0.5)  # a 50 cm wall foot is no curb
    assert not geometric_context(v2, n2)["curb"].any()


def test_raised_cue_blob_above_the_ground_is_not_terrain():
    blob = (lambda x, y: (np.abs(x) <= 1.0) & (np.abs(y) <= 1.0))  # noqa: E731  a 1 m high shrub block
    v, f, n, e = heightfield(lambda x, y: np.where(blob(x, y), 1.0, 0.0))
    p = votes(len(v), terrain=1.0)
    top = in_box(v, -0.9, 0.9, -0.9, 0.9)
    p[top] = votes(1, terrain=0.6, vegetation=0.4)
    lab, _, _ = fuse_with_context(p, v, n, e)
    assert (lab[top] == VEGETATION).all()
    assert (lab[~in_box(v, -1.5, 1.5, -1.5, 1.5)] == TERRAIN).all()
    off, _, _ = fuse_with_context(p, v, n, e, cues=[c for c in CUES if c != "raised"])
    assert (off[top] == TERRAIN).all()


def test_high_cue_nothing_six_metres_up_is_a_car():
    tower = (lambda x, y: (np.abs(x) <= 1.0) & (np.abs(y) <= 1.0))  # noqa: E731  a 6 m advertising column
    v, f, n, e = heightfield(lambda x, y: np.where(tower(x, y), 6.0, 0.0))
    p = votes(len(v), road=1.0)
    top = in_box(v, -0.9, 0.9, -0.9, 0.9)
    p[top] = votes(1, car=0.6, building=0.4)
    lab, _, _ = fuse_with_context(p, v, n, e)
    assert (lab[top] == BUILDING).all()
    off, _, _ = fuse_with_context(p, v, n, e, cues=[c for c in CUES if c != "high"])
    assert (off[top] == CAR).all()


def test_strong_evidence_still_wins_and_no_cue_changes_nothing():
    v, f, n, e = curb_street()
    p = votes(len(v), road=0.9, sidewalk=0.1)  # 9:1 for road: the curb prior (0.2) does not overturn it
    lab, _, _ = fuse_with_context(p, v, n, e)
    assert (lab == ROAD).all()
    p2 = votes(len(v), road=0.6, sidewalk=0.4)
    none, _, met = fuse_with_context(p2, v, n, e, cues=())
    assert (none == ROAD).all() and met["changed"] == 0
    opt = ContextOptions(min_curb_m=0.2)  # a 15 cm step is below this site's curbs: no band
    assert (fuse_with_context(p2, v, n, e, opt)[0] == ROAD).all()


def test_potts_smoothing_flips_a_weak_outlier_not_a_confident_one():
    from twinkit_segmentation.context import potts_smooth

    v, f, n, e = heightfield(lambda x, y: 0.0 * x, size=(4.0, 4.0))
    p = votes(len(v), road=1.0)
    centre = int(np.argmin(np.linalg.norm(v[:, :2], axis=1)))
    corner = int(np.argmin(np.linalg.norm(v[:, :2] - 1.0, axis=1)))
    p[centre] = votes(1, car=0.55, road=0.45)[0]  # a weak outlier amid road
    p[corner] = votes(1, car=0.95, road=0.05)[0]  # a confident one
    lab = p.argmax(axis=1).astype(np.uint8)
    out, changed = potts_smooth(lab, p, e, beta=1.0)
    assert out[centre] == ROAD and out[corner] == CAR and changed == 1
    same, none = potts_smooth(lab, p, e, beta=0.0)
    assert same[centre] == CAR and none == 0
    lab255 = lab.copy()
    lab255[:5] = 255
    assert (potts_smooth(lab255, p, e, beta=1.0)[0][:5] == 255).all()  # unlabelled stays for the fill


def test_curb_face_the_curbs_own_edge_is_sidewalk_too():
    # a finer mesh: the curb's top edge has a tilted normal (not up-facing), so only the face rule reaches it
    v, f, n, e = heightfield(lambda x, y: np.where((x >= 0) & (x <= 3.0), 0.15, 0.0), size=(10.0, 4.0), step=0.05)
    edge = (np.abs(v[:, 0]) < 0.08) & (v[:, 2] > 0.1)  # the first row on top of the step
    assert edge.sum() > 10 and (n[edge, 2] < 0.85).all()
    p = votes(len(v), road=0.6, sidewalk=0.4)
    lab, _, _ = fuse_with_context(p, v, n, e)
    assert (lab[edge] == SIDEWALK).all()
    assert (lab[v[:, 0] < -0.02] == ROAD).all()  # the gutter below it stays road
    off, _, _ = fuse_with_context(p, v, n, e, ContextOptions(curb_face=False))
    assert (off[edge] == ROAD).all()


def test_band_default_pavement_hidden_behind_parked_cars_is_sidewalk_not_the_verge_beside_it():
    v, f, n, e = heightfield(lambda x, y: np.where((x >= 0) & (x <= 3.0), 0.15, 0.0))
    p = votes(len(v), road=1.0)
    band = in_box(v, 0.0, 3.0, -8, 8)
    p[band] = votes(1, car=1.0)  # every view sees the parked cars' sides in front of the pavement
    verge = v[:, 0] > 3.0
    p[verge] = votes(1, terrain=1.0)  # the grass behind it
    lab, _, _ = fuse_with_context(p, v, n, e)
    inner = in_box(v, 0.3, 2.7, -7.5, 7.5)
    assert (lab[inner] == SIDEWALK).all()
    off, _, _ = fuse_with_context(p, v, n, e, ContextOptions(band_default=False))
    assert (off[inner] == TERRAIN).mean() > 0.9  # the verge grows over the band


def test_backproject_step_context_metrics_and_bad_cue_name(tmp_path, scene_files):
    from twinkit import InputError
    from twinkit.testing import plugin_from_module, run_step

    import twinkit_segmentation.plugin as P
    from twinkit_segmentation.steps import BackprojectParams

    mesh_ply, _, vlab = scene_files
    rng = np.random.default_rng(1)
    vv = np.zeros((len(vlab), N_CLASSES), np.float32)
    vv[np.arange(len(vlab)), vlab] = 1.0
    vv[rng.random(len(vlab)) < 0.2, CAR] += 2.0  # noisy car votes all over
    np.save(tmp_path / "votes.npy", vv)
    np.save(tmp_path / "segments.npy", np.arange(len(vlab), dtype=np.int32))
    ins = {"in_textured_mesh_ply": mesh_ply, "in_segments_npy": tmp_path / "segments.npy",
           "in_vertex_votes_npy": tmp_path / "votes.npy"}
    step = plugin_from_module(P, "step", "backproject")
    out = run_step(step, tmp_path / "on", ins)
    on = np.load(out["labels.npy"])
    off = np.load(run_step(step, tmp_path / "off", ins, BackprojectParams(context=False, smooth_beta=0))["labels.npy"])
    gt_car = vlab == CAR
    # the ground voted car is ground again with the context; the plain vote keeps it car
    assert ((on == CAR) & ~gt_car).sum() < ((off == CAR) & ~gt_car).sum()
    assert BackprojectParams().context_cues == list(DEFAULT_CUES)  # the step and the library agree
    with pytest.raises(InputError, match="context_cues"):
        run_step(step, tmp_path / "bad", ins, BackprojectParams(context_cues=["ground", "kerb"]))


# ------------------------------------------------------------------ objects above the ground and their shape
SHAPE_OFF = {c: [x for x in CUES if x != c] for c in ("column", "mounted", "low", "narrow", "slender")}


def solid_box(lo, hi, step=0.1, top=True):
    """A box's closed surface (welded, outward faces) subdivided to about ``step``: (vertices, faces);
    ``top=False`` leaves the roof out (what a street scanner sees of a building)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    verts, faces = [], []
    sides = [(0, 1, 2, lo[2], -1), (0, 1, 2, hi[2], 1), (0, 2, 1, lo[1], 1), (0, 2, 1, hi[1], -1),
             (1, 2, 0, lo[0], -1), (1, 2, 0, hi[0], 1)]
    for a, b, c, val, sign in sides:
        if c == 2 and val == hi[2] and not top:
            continue
        ua = np.linspace(lo[a], hi[a], max(2, int(np.ceil((hi[a] - lo[a]) / step)) + 1))
        ub = np.linspace(lo[b], hi[b], max(2, int(np.ceil((hi[b] - lo[b]) / step)) + 1))
        A, B = np.meshgrid(ua, ub)
        p = np.zeros((A.size, 3))
        p[:, a], p[:, b], p[:, c] = A.ravel(), B.ravel(), val
        na = len(ua)
        i, j = np.meshgrid(np.arange(na - 1), np.arange(len(ub) - 1))
        q = (j * na + i).ravel()
        t = np.vstack([np.column_stack([q, q + 1, q + na + 1]), np.column_stack([q, q + na + 1, q + na])])
        # outward: the cross product of the grid axes a x b points along +c for (a, b, c) cyclic
        cyclic = (a, b, c) in ((0, 1, 2), (1, 2, 0), (2, 0, 1))
        if (sign > 0) != cyclic:
            t = t[:, ::-1]
        faces.append(t + sum(len(x) for x in verts))
        verts.append(p)
    v = np.vstack(verts)
    _, first, inv = np.unique(np.round(v, 6), axis=0, return_index=True, return_inverse=True)
    return v[first], inv.ravel()[np.vstack(faces)]


def scene(*parts, ground=(20.0, 20.0)):
    """A flat ground grid plus solids: (vertices, normals, edges, [vertex mask of each solid])."""
    gv, gf, _, _ = heightfield(lambda x, y: 0.0 * x, size=ground)
    vs, fs, masks, off = [gv], [gf], [], len(gv)
    for v, f in parts:
        vs.append(v)
        fs.append(f + off)
        off += len(v)
    v, f = np.vstack(vs), np.vstack(fs)
    start = len(gv)
    for pv, _ in parts:
        m = np.zeros(len(v), bool)
        m[start:start + len(pv)] = True
        masks.append(m)
        start += len(pv)
    return v, vertex_normals(v, f), mesh_edges(f, len(v)), masks


def test_objects_above_the_ground_split_and_measure_a_post_and_a_wall():
    from twinkit_segmentation.objects import objects_above_ground

    post = solid_box([0, 0, 0], [0.2, 0.2, 4.0], top=False)
    wall = solid_box([3, -4, 0], [3.25, 4, 1.9])
    v, n, e, (mp, mw) = scene(post, wall)
    h = LocalGround(v, n[:, 2] >= 0.85).height(v)
    ob = objects_above_ground(v, h, h > 0.3, e)
    assert ob["n_objects"] == 2
    op, ow = ob["object"][mp & (h > 0.3)][0], ob["object"][mw & (h > 0.3)][0]
    assert abs(ob["top"][op] - 4.0) < 0.05 and abs(ob["top"][ow] - 1.9) < 0.05
    assert ob["footprint_minor"][ow] < 0.3 and ob["footprint_major"][ow] > 7.9  # thin and long
    assert ob["thin_span"][op] > 3.5 and ob["thin_span"][ow] == 0
    assert (ob["slice_major"][mp & (h > 0.3)] < 0.3).all()


def test_column_cue_a_thin_post_is_pole_a_tree_trunk_under_its_crown_is_not():
    post = solid_box([0, 0, 0], [0.2, 0.2, 4.0], top=False)
    trunk = solid_box([6, 0, 0], [6.25, 0.25, 2.8], top=False)
    crown = solid_box([4.6, -1.4, 2.8], [7.6, 1.6, 5.5])
    v, n, e, (mp, mt, mc) = scene(post, trunk, crown)
    p = votes(len(v), road=1.0)
    p[mp] = votes(1, building=0.6, pole=0.4)  # the facade behind the post takes most of its pixels
    p[mt] = votes(1, vegetation=0.6, pole=0.4)
    p[mc] = votes(1, vegetation=1.0)
    shaft = mp & (v[:, 2] > 0.5)
    lab, _, met = fuse_with_context(p, v, n, e)
    assert (lab[shaft] == POLE).all() and met["column_changed"] > 0
    assert (lab[mt & (v[:, 2] > 0.5)] == VEGETATION).all()  # a trunk (CityScapes: vegetation) stays
    off, _, _ = fuse_with_context(p, v, n, e, cues=SHAPE_OFF["column"])
    assert (off[shaft] == BUILDING).all()


def test_mounted_cue_a_free_plate_is_a_sign_a_box_on_a_post_is_a_light():
    plate = solid_box([0, 0, 2.1], [0.65, 0.03, 2.75], step=0.05)  # on a post too thin for the scan
    post = solid_box([5, 0, 0], [5.15, 0.15, 3.6], top=False)
    head = solid_box([5.15, -0.05, 2.45], [5.45, 0.25, 3.4], step=0.05)
    facade = solid_box([-6, 6, 0], [6, 14, 10], top=False)
    chip = solid_box([0, 5.7, 3.0], [0.5, 5.9, 3.5], step=0.05)  # a bit of facade the mesh split off
    v, n, e, (mpl, mpo, mh, mf, mch) = scene(plate, post, head, facade, chip)
    p = votes(len(v), road=1.0)
    p[mpl] = votes(1, building=0.5, vegetation=0.14, traffic_light=0.2, traffic_sign=0.16)  # light ahead: a plate is a sign
    p[mpo | mh] = votes(1, building=0.5, traffic_sign=0.2, traffic_light=0.16, pole=0.14)  # sign ahead: a box is a light
    p[mf | mch] = votes(1, building=0.6, traffic_sign=0.4)
    lab, _, met = fuse_with_context(p, v, n, e)
    assert (lab[mpl] == TRAFFIC_SIGN).mean() > 0.95 and met["mounted_changed"] > 0
    assert (lab[mh] == TRAFFIC_LIGHT).mean() > 0.9
    assert (lab[mch] == BUILDING).all() and (lab[mf] == BUILDING).all()  # a facade fragment is no sign
    off, _, _ = fuse_with_context(p, v, n, e, cues=SHAPE_OFF["mounted"])
    assert (off[mpl] == BUILDING).all() and (off[mh] == BUILDING).all()
    # gated off (a capture that cannot show the post), the item keeps no sign-or-signal-head reading either
    q = p.copy()
    q[mpl] = votes(1, traffic_light=0.4, traffic_sign=0.35, building=0.25)
    ref, _, _ = fuse_with_context(q, v, n, e, cues=SHAPE_OFF["mounted"])
    gated, _, _ = fuse_with_context(q, v, n, e, gates={"mounted": np.zeros(len(v), bool)})
    assert (ref[mpl] == TRAFFIC_LIGHT).mean() > 0.9 and np.array_equal(gated[mpl], ref[mpl])


def test_low_cue_a_two_metre_wall_is_no_building_a_facade_is():
    wall = solid_box([-5, 0, 0], [5, 0.25, 1.9])
    facade = solid_box([-5, 5, 0], [5, 12, 9], top=False)
    v, n, e, (mw, mf) = scene(wall, facade, ground=(24.0, 30.0))
    p = votes(len(v), road=1.0)
    p[mw | mf] = votes(1, building=0.6, wall=0.4)
    lab, _, met = fuse_with_context(p, v, n, e)
    face = mw & (v[:, 2] > 0.5)
    assert (lab[face] == WALL).all() and met["low_changed"] > 0
    assert (lab[mf & (v[:, 2] > 0.5)] == BUILDING).all()
    off, _, _ = fuse_with_context(p, v, n, e, cues=SHAPE_OFF["low"])
    assert (off[face] == BUILDING).all()


def test_narrow_cue_a_motorcycle_is_no_car_a_car_is():
    moto = solid_box([0, 0, 0.3], [2.0, 0.6, 1.1], step=0.05)
    car = solid_box([4, -1, 0.3], [8.4, 0.8, 1.5])
    v, n, e, (mm, mc) = scene(moto, car)
    p = votes(len(v), road=1.0)
    p[mm | mc] = votes(1, car=0.6, motorcycle=0.4)
    lab, _, met = fuse_with_context(p, v, n, e)
    body = mm & (v[:, 2] > 0.35)  # above the highest curb: part of an object
    assert (lab[body] == MOTORCYCLE).all() and met["narrow_changed"] > 0
    assert (lab[mc] == CAR).all()
    off, _, _ = fuse_with_context(p, v, n, e, cues=SHAPE_OFF["narrow"])
    assert (off[body] == CAR).all()


def test_floor_unanimous_votes_survive_the_cues():
    from twinkit_segmentation.context import near_unanimous

    v, f, n, e = heightfield(lambda x, y: 0.0 * x, size=(8.0, 8.0))
    raw = np.zeros((len(v), N_CLASSES))
    raw[:, ROAD] = 10.0
    bike = in_box(v, -0.3, 0.3, -0.3, 0.3)  # a wheel's contact patch, flat on the ground
    raw[bike] = 0.0
    raw[bike, BICYCLE] = 12.0  # every view: bicycle
    weak = in_box(v, 2.0, 2.4, 2.0, 2.4)
    raw[weak, ROAD], raw[weak, BICYCLE] = 2.0, 8.0  # 80 %: the ground cue wins there
    p = raw / raw.sum(axis=1, keepdims=True)
    sure = near_unanimous(raw, None, 0.9)
    assert sure[bike].all() and not sure[weak].any()
    lab, _, met = fuse_with_context(p, v, n, e, keep=sure)
    assert (lab[bike] == BICYCLE).all() and (lab[weak] == ROAD).all() and met["kept_unanimous"] == bike.sum()
    off, _, _ = fuse_with_context(p, v, n, e)
    assert (off[bike] == ROAD).all()
    seg = np.zeros(len(v), np.int64)  # one segment, road by far: its share reaches the floor for all
    assert near_unanimous(raw, seg, 0.9).all() and not near_unanimous(raw, None, 0).any()


def test_slender_cue_a_fence_panel_is_no_vegetation_a_hedge_is():
    fence = solid_box([-4, 0, 0], [4, 0.08, 1.4], step=0.07)
    hedge = solid_box([-4, 4, 0], [4, 4.8, 1.4])
    v, n, e, (mf, mh) = scene(fence, hedge)
    p = votes(len(v), road=1.0)
    p[mf | mh] = votes(1, vegetation=0.6, fence=0.4)  # the park behind the fence shows through it
    lab, _, met = fuse_with_context(p, v, n, e, cues=CUES)  # slender is not on by default
    panel = mf & (v[:, 2] > 0.35)
    assert (lab[panel] == FENCE).all() and met["slender_changed"] > 0
    assert (lab[mh] == VEGETATION).all()
    off, _, _ = fuse_with_context(p, v, n, e, cues=[c for c in CUES if c != "slender"])
    assert (off[panel] == VEGETATION).all()
    assert (fuse_with_context(p, v, n, e)[0][panel] == VEGETATION).all() and "slender" not in DEFAULT_CUES


def test_low_cue_no_signal_head_on_a_low_object():
    box = solid_box([0, 0, 0], [0.4, 0.4, 1.2], step=0.05)  # a control cabinet at the kerb
    v, n, e, (mb,) = scene(box)
    p = votes(len(v), road=1.0)
    p[mb] = votes(1, traffic_light=0.6, pole=0.4)
    body = mb & (v[:, 2] > 0.35)
    assert (fuse_with_context(p, v, n, e)[0][body] == POLE).all()
    assert (fuse_with_context(p, v, n, e, cues=SHAPE_OFF["low"])[0][body] == TRAFFIC_LIGHT).all()


def test_objects_join_parts_that_share_positions_a_car_built_of_separate_sides_stays_one_car():
    from twinkit_segmentation.synthetic import box

    bv, bf, _ = box((4, -1, 0.3), (8.4, 0.8, 1.5), 0.2)  # each side its own vertex set (a texture seam)
    v, n, e, (mc,) = scene((bv, bf))
    p = votes(len(v), road=1.0)
    p[mc] = votes(1, car=0.6, motorcycle=0.4)
    lab, _, met = fuse_with_context(p, v, n, e)
    assert met["objects"] == 1 and (lab[mc] == CAR).all()  # one 1.8 m wide object, not five narrow panels

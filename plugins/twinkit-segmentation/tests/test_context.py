"""3D context in the vote: each geometric cue changes the fused label where the physics says so, and
only there (each test fails with its cue switched off)."""
import numpy as np
import pytest

from twinkit.cityscapes import N_CLASSES
from twinkit.mesh import edges as mesh_edges
from twinkit.mesh.core import vertex_normals
from twinkit.surface.localground import LocalGround
from twinkit_segmentation.context import CUES, ContextOptions, fuse_with_context, geometric_context

ROAD, SIDEWALK, BUILDING, VEGETATION, TERRAIN, CAR = 0, 1, 2, 8, 9, 13


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
    h = LocalGround(v, n, window_m=3.0).height(v)
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
    with pytest.raises(InputError, match="context_cues"):
        run_step(step, tmp_path / "bad", ins, BackprojectParams(context_cues=["ground", "kerb"]))

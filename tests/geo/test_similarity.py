"""The photo branch's robust similarity (twinkit.geo.similarity): camera centres -> GPS fixes."""
import math

import numpy as np
import pytest

from twinkit import InputError
from twinkit.geo import fit_similarity


def test_consumer_gps_in_the_same_frame_gives_about_the_identity():
    # 40 photos along a walk around a 60 m junction, GPS with 2.5 m horizontal / 4 m vertical noise
    # (what the demo site writes into its photos' EXIF)
    rng = np.random.default_rng(0)
    s = np.linspace(0, 1, 40)
    centres = np.c_[-25 + 50 * s, 8 * np.sin(6 * s), np.full(40, 1.6)]
    gps = centres + rng.normal(0, 1, (40, 3)) * [2.5, 2.5, 4.0]
    real = fit_similarity(centres, gps, threshold_m=8.0)
    assert abs(math.degrees(real.yaw_rad)) < 10.0 and abs(real.scale - 1.0) < 0.15
    assert real.to_json()["n"] == 40


def test_rotated_scaled_reconstruction_with_wild_fixes():
    # a reconstruction in its own frame: rotated 30 deg, scaled 0.5, shifted; GPS with 0.5 m noise and
    # two wild fixes
    rng = np.random.default_rng(1)
    yaw, s, t = math.radians(30.0), 0.5, np.array([100.0, -40.0, 3.0])
    R = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]])
    recon = rng.uniform(-60, 60, (40, 3)) * [1, 1, 0.05]
    fixes = s * recon @ R.T + t + rng.normal(0, 0.5, (40, 3))
    fixes[:2, :2] += 60.0
    sim = fit_similarity(recon, fixes, threshold_m=3.0)
    assert abs(math.degrees(sim.yaw_rad) - 30.0) < 1.0
    assert abs(sim.scale - 0.5) < 0.01
    assert not sim.inliers[:2].any() and sim.inliers[2:].all()
    assert np.abs(sim.apply(recon[2:]) - fixes[2:]).max() < 3.0
    with pytest.raises(InputError):
        fit_similarity(recon[:1], fixes[:1])
    with pytest.raises(InputError, match="GPS positions"):
        fit_similarity(recon[:3], fixes[:2])


# ------------------------------------------------------------------ the closed form (one fit for every caller)
def test_closed_form_keeps_the_recorded_numbers():
    """The numbers the road source's 2D fit and the photo branch's 3D Umeyama gave before they became one."""
    from twinkit.geo.similarity import closed_form_similarity

    rng = np.random.default_rng(5)
    p = rng.uniform(-200, 200, (30, 2))
    R2 = np.array([[math.cos(0.01), -math.sin(0.01)], [math.sin(0.01), math.cos(0.01)]])
    q = 1.0004 * p @ R2.T + [3500.0, -1200.0] + 1e-3 * (p / 200) ** 2
    f = closed_form_similarity(p, q)
    np.testing.assert_allclose([f.scale, f.angle_rad], [1.0003998942100978, 0.009999718275609713], rtol=1e-12)
    np.testing.assert_allclose(f.t, [3500.000281946548, -1199.9995566546818], rtol=1e-12)
    a = rng.uniform(-20, 20, (12, 3))
    b = 0.8 * a @ np.linalg.qr(rng.normal(size=(3, 3)))[0].T + [1.0, 2.0, 3.0] + rng.normal(0, 0.05, (12, 3))
    T = closed_form_similarity(a, b)
    assert T.angle_rad is None and abs(T.scale - 0.7998852158760827) < 1e-12
    np.testing.assert_allclose(T.R, [[-0.5723094775760224, 0.5545775286749518, 0.6040741896203179],
                                     [-0.7778452206301116, -0.6003742429962224, -0.18576216269629975],
                                     [0.25965106319742715, -0.5761896675882832, 0.7749753495079373]], atol=1e-12)
    np.testing.assert_allclose(T.t, [1.042727355129236, 1.9933210972879356, 2.98530853173254], atol=1e-12)
    assert abs(np.linalg.det(T.R) - 1) < 1e-12


def test_closed_form_modes_recover_a_planted_similarity():
    from twinkit.geo.similarity import closed_form_similarity

    rng = np.random.default_rng(2)
    src = rng.uniform(-30, 30, (25, 3))
    yaw = math.radians(-40.0)
    Rz = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]])
    dst = 2.5 * src @ Rz.T + [10.0, 20.0, -3.0]
    for T in (closed_form_similarity(src, dst), closed_form_similarity(src, dst, about_z=True),
              closed_form_similarity(src, dst, about_z=True, scale_dims=3)):
        assert abs(T.scale - 2.5) < 1e-12 and np.abs(T.R - Rz).max() < 1e-12
        assert np.abs(T.apply(src) - dst).max() < 1e-9
    assert abs(closed_form_similarity(src, dst, about_z=True).angle_rad - yaw) < 1e-12
    rigid = closed_form_similarity(src[:, :2], src[:, :2] @ Rz[:2, :2].T + 7.0, with_scale=False)
    assert rigid.scale == 1.0 and abs(rigid.angle_rad - yaw) < 1e-12 and np.allclose(rigid.t, 7.0)
    with pytest.raises(InputError, match="one point"):
        closed_form_similarity(np.zeros((3, 2)), np.ones((3, 2)))

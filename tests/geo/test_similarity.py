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

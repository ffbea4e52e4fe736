"""A single spinning sweep's sensor and top beam from its points (twinkit.surface.rings), on sweeps ray-cast
by code: flat ground, a tall facade the top beam cuts, a low wall it passes over."""
from __future__ import annotations

import numpy as np

from twinkit.surface.rings import ring_sensor, under_ceiling

SENSOR = np.array([3.0, -2.0, 1.8])
TOP_DEG = 2.0
FACADE_X, FACADE_TOP = 18.0, 12.0  # a building front, taller than the beam reaches
WALL_Y, WALL_TOP, WALL_X = -8.0, 1.2, (4.0, 12.0)  # a low wall along the street


def sweep(sensor=SENSOR, top_deg=TOP_DEG, beams=64, az_step_deg=0.12, seed=0):
    """(points, part) of one sweep of a spinning sensor over the scene; part: 0 ground, 1 facade, 2 wall."""
    rng = np.random.default_rng(seed)
    el = np.radians(np.linspace(-24.8, top_deg, beams))
    az = np.radians(np.arange(0.0, 360.0, az_step_deg))
    e, a = np.meshgrid(el, az, indexing="ij")
    d = np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], axis=-1).reshape(-1, 3)
    t = np.full(len(d), np.inf)
    part = np.full(len(d), -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        hits = [(-sensor[2] / d[:, 2], 0, lambda p: np.ones(len(p), bool)),
                ((FACADE_X - sensor[0]) / d[:, 0], 1, lambda p: (p[:, 2] <= FACADE_TOP) & (np.abs(p[:, 1]) < 40)),
                ((WALL_Y - sensor[1]) / d[:, 1], 2,
                 lambda p: (p[:, 2] <= WALL_TOP) & (p[:, 0] > WALL_X[0]) & (p[:, 0] < WALL_X[1]))]
        for tt, k, inside in hits:
            p = sensor + tt[:, None] * d
            ok = np.isfinite(tt) & (tt > 0.5) & (tt < 80.0) & (tt < t) & inside(p) & (p[:, 2] >= -1e-6)
            t[ok], part[ok] = tt[ok], k
    keep = np.isfinite(t)
    pts = sensor + (t[keep] + rng.normal(0, 0.01, keep.sum()))[:, None] * d[keep]
    return pts, part[keep]


def on_top_beam(pts, part, top_deg=TOP_DEG):
    """The facade's returns of the top beam (the truth)."""
    r = np.hypot(pts[:, 0] - SENSOR[0], pts[:, 1] - SENSOR[1])
    return (part == 1) & (np.abs(SENSOR[2] + r * np.tan(np.radians(top_deg)) - pts[:, 2]) < 0.05)


def test_the_sensor_and_its_top_beam_come_from_the_rings_and_the_cut_facade():
    pts, part = sweep()
    s = ring_sensor(pts + [500.0, 200.0, 30.0])  # a site frame far from the sensor's own
    assert s is not None
    assert np.hypot(s["xy"][0] - 503.0, s["xy"][1] - 198.0) < 0.6, s
    assert abs(s["top_deg"] - TOP_DEG) < 0.4, s
    gap = under_ceiling(pts + [500.0, 200.0, 30.0], s)
    assert np.abs(gap[on_top_beam(pts, part)]).max() < 0.3  # the top beam's returns on the facade lie on the cone
    assert gap[part == 2].min() > 0.5  # the wall stands well under it: its top was seen


def test_a_steeper_top_beam_is_found_too():
    pts, part = sweep(top_deg=15.0, beams=32)
    s = ring_sensor(pts)
    assert s is not None and abs(s["top_deg"] - 15.0) < 1.0, s
    gap = under_ceiling(pts, s)
    assert np.abs(gap[on_top_beam(pts, part, top_deg=15.0)]).max() < 0.3


def test_a_capture_whose_ground_is_sampled_both_ways_has_no_ring_sensor():
    rng = np.random.default_rng(1)
    g = np.column_stack([rng.uniform(-30, 30, 60_000), rng.uniform(-30, 30, 60_000), rng.normal(0, 0.01, 60_000)])
    facade = np.column_stack([np.full(20_000, 18.0), rng.uniform(-30, 30, 20_000), rng.uniform(0, 12, 20_000)])
    assert ring_sensor(np.vstack([g, facade])) is None
    assert ring_sensor(np.zeros((5, 3))) is None

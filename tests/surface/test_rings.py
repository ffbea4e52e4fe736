"""A single spinning sweep's sensor and top beam from its points (twinkit.surface.rings), on sweeps ray-cast
by code: flat ground, a tall facade the top beam cuts, a low wall it passes over."""
from __future__ import annotations

import numpy as np

from twinkit.surface.rings import ring_sensor, under_ceiling
from twinkit.testing import SWEEP_SENSOR as SENSOR
from twinkit.testing import SWEEP_TOP_DEG as TOP_DEG
from twinkit.testing import spinning_sweep as sweep


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


def test_the_vehicle_carrying_the_sensor_is_found_inside_the_blind_circle():
    from twinkit.surface.rings import blind_circle, platform_returns

    pts, part = sweep(platform=True)
    truth = part == 3
    s = ring_sensor(pts)
    circle = blind_circle(pts, s)
    # the lowest beam (-24.8 degrees from 1.8 m) meets the ground 3.9 m from the sensor
    assert circle is not None and abs(circle["radius_m"] - 1.8 / np.tan(np.radians(24.8))) < 0.4, circle
    assert np.hypot(*(np.array(circle["xy"]) - SENSOR[:2])) < 0.3, circle
    gone, _ = platform_returns(pts, s)
    assert (gone == truth).all(), (gone & ~truth).sum()


def test_what_stands_near_the_sensor_is_the_streets_when_it_reaches_the_ring_or_is_large():
    from twinkit.surface.rings import platform_returns

    pts, part = sweep(platform=True)
    truth = part == 3
    rng = np.random.default_rng(3)
    # a car parked alongside (its side 2.2 m from the sensor, reaching past the ring at 3.9 m) and a pole 3 m
    # away, inside the ring, from the ground up to 1.5 m (hundreds of returns: more than a car's bonnet gives)
    beside = SENSOR + np.column_stack([rng.uniform(-2.0, 2.0, 800), rng.uniform(-4.4, -2.2, 800),
                                       rng.uniform(-1.5, -0.3, 800)])
    pole = np.column_stack([np.full(300, SENSOR[0] - 3.0), np.full(300, SENSOR[1]), np.linspace(0.0, 1.5, 300)])
    pts = np.vstack([pts, beside, pole])
    gone, circle = platform_returns(pts, ring_sensor(pts))
    assert circle is not None
    assert gone[:len(truth)].sum() == truth.sum() and not gone[len(truth):].any()


def test_a_capture_without_a_blind_circle_loses_nothing():
    from twinkit.surface.rings import platform_returns

    pts, _ = sweep()
    s = ring_sensor(pts)
    gone, circle = platform_returns(pts, s)
    assert circle is not None and not gone.any()  # a sweep whose sensor stood on nothing: the circle is empty

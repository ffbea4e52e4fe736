"""twinkit.surface.density: the capture measures the steps choose their settings from."""
import numpy as np

from twinkit.surface import density


def _rings(r0=3.0, r1=25.0, ring_gap_deg=0.4, along_m=0.02, h=1.8, seed=0):
    """The ground of one spinning sweep: rings where beams at 0.4 deg steps meet a flat ground from 1.8 m up,
    a point every ``along_m`` along each ring, 1 cm of range noise (along the beam) and 4 mm of height noise."""
    rng = np.random.default_rng(seed)
    pts = []
    ang = np.deg2rad(np.arange(np.rad2deg(np.arctan(h / r1)), np.rad2deg(np.arctan(h / r0)), ring_gap_deg))
    for a in ang:
        r = h / np.tan(a)
        phi = np.arange(0, 2 * np.pi, along_m / r)
        rr = r + rng.normal(0, 0.01, len(phi))
        pts.append(np.column_stack([rr * np.cos(phi), rr * np.sin(phi), rng.normal(0, 0.004, len(phi))]))
    return np.concatenate(pts)


def test_the_ground_of_a_single_sweep_is_told_from_a_patch_sampled_both_ways():
    rng = np.random.default_rng(1)
    sweep = _rings()
    patch = np.column_stack([rng.uniform(-20, 20, 60000), rng.uniform(-20, 20, 60000), rng.normal(0, 0.004, 60000)])
    s, p = density.measure(sweep), density.measure(patch)
    # the rings are sampled far finer along than across (beyond a few metres): most neighbourhoods are one line
    assert s["ground_two_way_share"] < 0.5 < 0.95 < p["ground_two_way_share"]
    # the median spacing alone would call the sweep the denser of the two
    assert s["spacing_m"] < p["spacing_m"]
    wall = np.column_stack([rng.uniform(-20, 20, 5000), np.zeros(5000), rng.uniform(0, 10, 5000)])
    assert density.measure(wall)["ground_two_way_share"] is None  # no ground: not measured

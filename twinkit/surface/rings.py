"""A capture sampled in rings (a single sweep of a spinning multi-beam lidar): where its sensor stood, and
how high its top beam reaches.

A real sweep file gives neither (SemanticKITTI's points are in the sensor's frame, but a cropped, merged
or georeferenced sweep is not), and both follow from the points:

* **The sensor's position** (x, y): on the ground each beam draws a circle round the sensor, so a patch of
  one ring line runs square to the direction of the sensor. Every such patch (a near-horizontal
  neighbourhood whose points spread one way only, :func:`twinkit.surface.density.neighbourhoods`) gives
  a line through the patch, square to its main direction; the sensor is the point nearest all of them
  (least squares, re-weighted so that patches of kerbs and scan edges, which run other ways, count less).
  Within about 1 m of the truth on the SemanticKITTI sweeps, 10-40 m from the sensor where it matters.
* **The top beam's cone**: nothing is sampled above the highest beam, so every point lies under
  ``z = z0 + r tan(top)`` (r: horizontal distance to the sensor), and the top beam's returns line up just
  under it wherever something stood tall enough. The elevation (searched in 0.1 degree steps) is the one
  whose band under that line reaches the most distances from the sensor (a ground ring, dense but at one
  distance, would otherwise win), and of those the one whose band holds the most points. 1.9-2.1 degrees on the SemanticKITTI sweeps (a
  Velodyne HDL-64E: +2 degrees).

What it is for: a facade or a hedge that reaches the cone was cut by the scan, so its height is not
known. On an HDL-64E sweep that is everything higher than about 2.1 m at 10 m and 2.8 m at 30 m, and the
3D classifier, which tells a free-standing wall from a building by its height, calls most cut facades
walls (docs/segmentation.md, "Cut by the top beam").
"""
from __future__ import annotations

import numpy as np

from twinkit.surface.density import RING_CAPTURE_SHARE, SAMPLE, neighbourhoods

#: the top beam's elevation is searched for between these angles (degrees)
TOP_BEAM_DEG = (-5.0, 30.0)
#: a point counts on the top beam when it lies this close under the cone (m)
TOP_BAND_M = 0.25
#: the top beam is the cone whose band reaches the most distances from the sensor, in steps of this (m):
#: one ground ring, dense but at one distance, must not win over a beam that grazes tall things everywhere
TOP_SPREAD_M = 0.5
#: fewer ring-line patches than this and no sensor is estimated
MIN_RING_LINES = 200


def ring_sensor(points: np.ndarray, *, sample: int = SAMPLE, seed: int = 0) -> dict | None:
    """The sensor of a capture whose ground is sampled in rings (see the module's docstring), or None for
    any other capture (ground sampled both ways in over ``RING_CAPTURE_SHARE`` of its patches: a
    mobile, terrestrial or aerial scan) or when too few ring lines are found.

    ``points`` (n, 3) metres, z up. Returns ``{"xy": [x, y], "z0_m": height of the cone's apex, "top_deg":
    the top beam's elevation, "ring_lines": patches used, "residual_m": their median distance from the
    sensor's radial lines}``."""
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) < 20 or not np.isfinite(pts).all():
        return None
    mean = pts.mean(axis=0)
    pts = pts - mean
    nbh = neighbourhoods(pts, sample=sample, seed=seed)
    flat = nbh.flat
    if not flat.any() or nbh.two_way[flat].mean() >= RING_CAPTURE_SHARE:
        return None
    lines = flat & ~nbh.two_way
    if int(lines.sum()) < MIN_RING_LINES:
        return None
    xy, residual = _ring_centre(pts[nbh.idx[lines], :2], nbh.major[lines, :2])
    if xy is None:
        return None
    z0, top = _top_beam(pts, xy)
    return {"xy": [round(float(xy[0] + mean[0]), 3), round(float(xy[1] + mean[1]), 3)],
            "z0_m": round(float(z0 + mean[2]), 3), "top_deg": round(float(top), 2),
            "ring_lines": int(lines.sum()), "residual_m": round(float(residual), 3)}


def _ring_centre(p: np.ndarray, tangent: np.ndarray, iterations: int = 10) -> tuple[np.ndarray | None, float]:
    """The point nearest the lines through ``p`` (m, 2) square to ``tangent`` (m, 2), and the lines' median
    distance from it; (None, nan) when the lines are near parallel (a straight scan, not rings)."""
    t = tangent / np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    w = np.ones(len(p))
    c = np.zeros(2)
    res = np.zeros(len(p))
    for _ in range(iterations):
        a = np.einsum("n,ni,nj->ij", w, t, t)
        if np.linalg.cond(a) > 1e6:
            return None, float("nan")
        c = np.linalg.solve(a, np.einsum("n,ni,nj,nj->i", w, t, t, p))
        res = np.abs(np.einsum("ni,ni->n", c - p, t))
        scale = max(1.5 * float(np.median(res)), 0.05)
        w = 1.0 / np.maximum(res / scale, 1.0)
    return c, float(np.median(res))


def _top_beam(pts: np.ndarray, xy: np.ndarray, sample: int = 200_000) -> tuple[float, float]:
    """(z0, elevation in degrees) of the cone ``z = z0 + r tan(elevation)`` under which the points lie."""
    r = np.hypot(pts[:, 0] - xy[0], pts[:, 1] - xy[1])
    z = pts[:, 2]
    keep = r > 3.0  # the car carrying the sensor, and returns of the first metres, say nothing of the beam
    r, z = r[keep], z[keep]
    if len(r) > sample:
        pick = np.random.default_rng(0).choice(len(r), sample, replace=False)
        r, z = r[pick], z[pick]
    if len(r) == 0:
        return float(pts[:, 2].max()), 0.0
    best = (-1, -1, 0.0, 0.0)
    r_bin = np.floor(r / TOP_SPREAD_M).astype(np.int64)
    for deg in np.arange(TOP_BEAM_DEG[0], TOP_BEAM_DEG[1], 0.1):
        u = z - np.tan(np.radians(deg)) * r
        z0 = float(np.quantile(u, 0.999))
        band = u > z0 - TOP_BAND_M
        score = (len(np.unique(r_bin[band])), int(band.sum()))  # distances reached, then points (ties)
        if score > best[:2]:
            best = (*score, z0, float(deg))
    return best[2], best[3]


def under_ceiling(points: np.ndarray, sensor: dict) -> np.ndarray:
    """(n,) how far each point lies under the top beam's cone of :func:`ring_sensor`'s ``sensor`` (m;
    negative above it)."""
    pts = np.asarray(points, dtype=np.float64)
    r = np.hypot(pts[:, 0] - sensor["xy"][0], pts[:, 1] - sensor["xy"][1])
    return sensor["z0_m"] + np.tan(np.radians(sensor["top_deg"])) * r - pts[:, 2]

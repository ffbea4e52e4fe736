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

* **The blind circle** round the sensor: the lowest beam meets the ground at a few metres, and nothing of
  the street is sampled nearer. What returns come from inside it are the vehicle carrying the sensor (its
  bonnet, its mirrors: a few dozen points a metre above the road, "unlabeled" and "outlier" in
  SemanticKITTI's hand labels), and a mesh over them is a lump in the middle of the road
  (:func:`platform_returns`).

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
#: the blind circle's edge is looked for in this many sectors round the sensor, out to BLIND_MAX_R_M
BLIND_SECTORS = 36
BLIND_MAX_R_M = 10.0
#: a sector's edge of the blind circle is its this-many-th nearest point: a ring's sector holds dozens, the
#: platform's few returns in a sector do not reach it
BLIND_RANK = 20
#: the capture platform: clusters of points (linked within PLATFORM_LINK_M) of at most PLATFORM_MAX_POINTS, all
#: more than PLATFORM_MARGIN_M inside the blind circle; a cluster reaching the ring is the street's (a car
#: parked beside, a wall)
PLATFORM_LINK_M = 0.5
PLATFORM_MARGIN_M = 0.3
PLATFORM_MAX_POINTS = 200


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


def _circle(xy: np.ndarray) -> tuple[np.ndarray, float]:
    """The least-squares circle through points ``xy`` (m, 2): (centre, radius)."""
    a = np.c_[2 * xy, np.ones(len(xy))]
    (cx, cy, c), *_ = np.linalg.lstsq(a, (xy ** 2).sum(axis=1), rcond=None)
    return np.array([cx, cy]), float(np.sqrt(max(c + cx * cx + cy * cy, 0.0)))


def blind_circle(points: np.ndarray, sensor: dict) -> dict | None:
    """The circle round :func:`ring_sensor`'s ``sensor`` inside which the sweep sampled no ground (the lowest
    beam's ring): in each of ``BLIND_SECTORS`` sectors the ``BLIND_RANK``-th nearest point, a circle fitted
    to those (sectors whose point lies off it, where something stands nearer than the ring, left out), the
    sectors taken again round the new centre until it stays. ``{"xy": centre, "radius_m", "sectors": used}``,
    or None when fewer than half the sectors hold a ring."""
    pts = np.asarray(points, dtype=np.float64)
    centre = np.asarray(sensor["xy"], dtype=np.float64)
    found = None
    for _ in range(4):
        d = pts[:, :2] - centre
        r = np.hypot(d[:, 0], d[:, 1])
        near = np.flatnonzero(r < BLIND_MAX_R_M)
        sector = ((np.arctan2(d[near, 1], d[near, 0]) + np.pi) / (2 * np.pi) * BLIND_SECTORS).astype(np.int64)
        sector %= BLIND_SECTORS
        order = np.lexsort((r[near], sector))
        first = np.searchsorted(sector[order], np.arange(BLIND_SECTORS))
        full = np.bincount(sector, minlength=BLIND_SECTORS) >= BLIND_RANK
        if full.sum() < BLIND_SECTORS // 2:
            return None
        edge = pts[near[order[first[full] + BLIND_RANK - 1]], :2]
        keep = np.ones(len(edge), bool)
        for _ in range(3):
            c, radius = _circle(edge[keep])
            res = np.abs(np.hypot(*(edge - c).T) - radius)
            keep = res < max(0.3, 3.0 * float(np.median(res[keep])))
            if keep.sum() < BLIND_SECTORS // 2:
                return None
        moved = float(np.hypot(*(c - centre)))
        centre, found = c, {"xy": [round(float(c[0]), 3), round(float(c[1]), 3)], "radius_m": round(radius, 3),
                            "sectors": int(keep.sum())}
        if moved < 0.05:
            break
    return found


def platform_returns(points: np.ndarray, sensor: dict) -> tuple[np.ndarray, dict | None]:
    """(n,) bool: the returns of the vehicle carrying a sweep's sensor (``sensor``: :func:`ring_sensor`), and
    the :func:`blind_circle` they lie in (None: not found, nothing flagged). A platform return lies in a small
    cluster (points linked within ``PLATFORM_LINK_M``, at most ``PLATFORM_MAX_POINTS``) wholly more than
    ``PLATFORM_MARGIN_M`` inside the blind circle; anything that reaches the ring (a car parked alongside, a
    wall, a pole's column of returns) belongs to the street."""
    from twinkit.surface.linked import linked_groups

    pts = np.asarray(points, dtype=np.float64)
    out = np.zeros(len(pts), bool)
    circle = blind_circle(pts, sensor)
    if circle is None:
        return out, None
    r = np.hypot(pts[:, 0] - circle["xy"][0], pts[:, 1] - circle["xy"][1])
    inner = circle["radius_m"] - PLATFORM_MARGIN_M
    near = np.flatnonzero(r < circle["radius_m"] + 2 * PLATFORM_LINK_M)
    if not (r[near] < inner).any():
        return out, circle
    count, label = linked_groups(pts[near], PLATFORM_LINK_M)
    reach = np.zeros(count)
    np.maximum.at(reach, label, r[near])
    small = np.bincount(label, minlength=count) <= PLATFORM_MAX_POINTS
    out[near[(reach[label] < inner) & small[label]]] = True
    return out, circle


def under_ceiling(points: np.ndarray, sensor: dict) -> np.ndarray:
    """(n,) how far each point lies under the top beam's cone of :func:`ring_sensor`'s ``sensor`` (m;
    negative above it)."""
    pts = np.asarray(points, dtype=np.float64)
    r = np.hypot(pts[:, 0] - sensor["xy"][0], pts[:, 1] - sensor["xy"][1])
    return sensor["z0_m"] + np.tan(np.radians(sensor["top_deg"])) * r - pts[:, 2]

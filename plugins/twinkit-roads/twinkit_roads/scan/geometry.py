"""Geometry of a road's axis: resampling, smoothing, a robust fit, normals, rays to the mask's edge, where
axes meet; and the lane layout of a carriageway width."""
from __future__ import annotations

import math

import numpy as np

from .model import Arm, ScanSourceParams


def resample(xy: np.ndarray, step: float) -> np.ndarray:
    d = np.r_[0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]
    if d[-1] < 1e-9:
        return xy[:1]
    n = max(2, int(math.ceil(d[-1] / step)) + 1)
    t = np.linspace(0, d[-1], n)
    return np.stack([np.interp(t, d, xy[:, 0]), np.interp(t, d, xy[:, 1])], 1)


def smooth(xy: np.ndarray, window: int) -> np.ndarray:
    """Moving average keeping the end points (reflected ends)."""
    if len(xy) < 3 or window < 2:
        return xy
    k = min(window, len(xy) - 1) | 1
    h = k // 2
    pad = np.concatenate([2 * xy[:1] - xy[h:0:-1], xy, 2 * xy[-1:] - xy[-2:-h - 2:-1]])
    ker = np.ones(k) / k
    return np.stack([np.convolve(pad[:, i], ker, mode="valid") for i in range(2)], 1)


def fit_axis(xy: np.ndarray, window: int, huber_m: float = 0.3) -> np.ndarray:
    """A road's axis through noisy centre points: a robust (Huber, IRLS) quadratic in the road's own frame
    (its principal direction), when the road turns less than 30 degrees; a moving average otherwise.
    The per-point centres wobble where a car or an occlusion eats one edge; a street is straight or
    gently curved over the length of one arm between junctions."""
    if len(xy) < 6:
        return smooth(xy, window)
    c = xy.mean(0)
    u, s_, vt = np.linalg.svd(xy - c, full_matrices=False)
    d = vt[0]
    n = np.array([-d[1], d[0]])
    t = (xy - c) @ d
    y = (xy - c) @ n
    tang = np.diff(smooth(xy, window), axis=0)
    ang = np.unwrap(np.arctan2(tang[:, 1], tang[:, 0]))
    if len(ang) and float(np.ptp(ang)) > math.radians(30) or np.any(np.diff(t) <= 0) and np.any(np.diff(t) >= 0):
        return smooth(xy, window)
    scale = max(float(np.abs(t).max()), 1.0)
    A = np.stack([np.ones_like(t), t / scale, (t / scale) ** 2], 1)
    w = np.ones(len(t))
    for _ in range(8):
        coef, *_ = np.linalg.lstsq(A * w[:, None], y * w, rcond=None)
        r = np.abs(y - A @ coef)
        w = np.sqrt(np.where(r <= huber_m, 1.0, huber_m / np.maximum(r, 1e-9)))
    yf = A @ coef
    return c + t[:, None] * d + yf[:, None] * n


def normals(xy: np.ndarray) -> np.ndarray:
    t = np.gradient(xy, axis=0)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-9)
    return np.stack([-t[:, 1], t[:, 0]], 1)  # left normal


def ray_lengths(mask, grid, xy, dirs, max_m, step) -> np.ndarray:
    """Distance from each point along its direction until the mask ends (first pixel off)."""
    ts = np.arange(0.0, max_m + step, step)
    pts = xy[:, None, :] + ts[None, :, None] * dirs[:, None, :]
    inside = grid.sample(mask.astype(np.uint8), pts) > 0
    off = ~inside
    off[:, -1] = True
    first = off.argmax(1)
    return ts[first]


def junction_point(lines: list[tuple[np.ndarray, np.ndarray]], fallback: np.ndarray) -> np.ndarray:
    """Least-squares meeting point of lines (point, unit direction); the fallback when they are parallel."""
    A = np.zeros((2, 2))
    b = np.zeros(2)
    for p, d in lines:
        P = np.eye(2) - np.outer(d, d)
        A += P
        b += P @ p
    if len(lines) < 2 or abs(np.linalg.det(A)) < 1e-3 * len(lines):
        return fallback
    q = np.linalg.solve(A, b)
    return q if np.hypot(*(q - fallback)) < 30 else fallback


def lane_layout(width_m: float, p: ScanSourceParams) -> dict:
    """Lanes per direction, their width and a strip at the curb, for a carriageway ``width_m`` wide."""
    half = width_m / 2
    if half < p.min_lane_width_m:  # one lane, one way (spread about the axis: strip_m at each curb)
        lane = min(p.max_lane_width_m, max(width_m - 2 * p.curb_clearance_m, 0.5 * width_m))
        return {"two_way": False, "lanes": 1, "lane_m": round(lane, 3), "strip_m": round(max((width_m - lane) / 2, 0.0), 3)}
    n = max(1, int(math.floor(half / p.lane_width_m + 1e-6)))
    rem = half - n * p.lane_width_m
    if rem >= p.min_strip_m and p.strip_type != "driving":
        return {"two_way": True, "lanes": n, "lane_m": p.lane_width_m, "strip_m": round(rem, 3)}
    if p.strip_type == "driving" and rem >= p.min_strip_m:
        return {"two_way": True, "lanes": n + 1, "lane_m": round(half / (n + 1), 3), "strip_m": 0.0}
    # widen the lanes, but keep curb_clearance_m free at the curb: the found edge lies a little outside the
    # curb's foot (a reconstructed curb is a ramp), and a lane reaching onto the curb drops the drop test
    lane = min(p.max_lane_width_m, max(p.lane_width_m, (half - p.curb_clearance_m) / n))
    if n * p.lane_width_m > half:  # a carriageway narrower than two nominal lanes (5-6.5 m: a village street):
        # narrower lanes (not below min_lane_width_m), not nominal ones that reach over the edges (a 5.2 m
        # street had two 3.25 m lanes, 0.65 m beyond each edge, over verges and walls: IGN, Autzen)
        lane = max(p.min_lane_width_m, min(p.lane_width_m, half - p.curb_clearance_m))
    return {"two_way": True, "lanes": n, "lane_m": round(lane, 3), "strip_m": round(max(half - n * lane, 0.0), 3)}


def unit(d) -> np.ndarray:
    d = np.asarray(d, float)
    n = float(np.hypot(*d))
    return d / n if n > 1e-9 else np.array([1.0, 0.0])


def on_polyline(points: np.ndarray, line: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points (k, 2) against a polyline (n >= 2, first two columns x, y): each point's distance to it, the
    arclength position of its nearest point on it, and the index of the segment that holds it."""
    a, b = line[:-1, :2], line[1:, :2]
    ab = b - a
    L2 = np.maximum((ab ** 2).sum(1), 1e-12)
    u = np.clip(((points[:, None, :] - a[None]) * ab[None]).sum(-1) / L2[None], 0.0, 1.0)
    dist = np.hypot(*(a[None] + u[..., None] * ab[None] - points[:, None, :]).transpose(2, 0, 1))
    j = dist.argmin(1)
    k = np.arange(len(points))
    seg = np.sqrt(L2)
    return dist[k, j], np.r_[0.0, np.cumsum(seg)][j] + u[k, j] * seg[j], j


def true_runs(b: np.ndarray) -> list[tuple[int, int]]:
    """``(start, stop)`` of each run of True in a 1-D bool array."""
    d = np.diff(np.r_[0, b.astype(np.int8), 0])
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def lanes_reach(arm: Arm, p: ScanSourceParams) -> float:
    """How far from the axis a road's outermost driving lane's edge lies (lane_layout; a one-way road's lane is
    centred; a parking strip at the kerb lies beyond it)."""
    lay = lane_layout(arm.width_m, p)
    return lay["lanes"] * lay["lane_m"] if lay["two_way"] else lay["lane_m"] / 2

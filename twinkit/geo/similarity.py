"""Photo branch: similarity transform from camera centres (mesh frame) to GPS positions (site frame).

    gps ~= s * Rz(yaw) @ centre + t      (rotation about up only, uniform scale, no shear)

Least squares in closed form (2D Procrustes on x, y for the yaw; scale from x, y and optionally z),
inside RANSAC on minimal samples of two cameras, so a few wild GPS fixes do not bend the result.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twinkit.errors import InputError


@dataclass
class Similarity:
    scale: float
    yaw_rad: float
    t: np.ndarray  # (3,)
    inliers: np.ndarray  # (n,) bool
    rmse_m: float  # over inliers, horizontal

    def apply(self, p) -> np.ndarray:
        p = np.asarray(p, float).reshape(-1, 3)
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        return self.scale * p @ R.T + self.t

    def to_json(self) -> dict:
        return {"scale": self.scale, "yaw_deg": math.degrees(self.yaw_rad), "t": [float(v) for v in self.t],
                "inliers": int(self.inliers.sum()), "n": int(len(self.inliers)), "rmse_m": self.rmse_m,
                "definition": "gps = scale * Rz(yaw) @ camera_centre + t"}


def _fit(src: np.ndarray, dst: np.ndarray, use_z: bool) -> tuple[float, float, np.ndarray]:
    cs, cd = src.mean(0), dst.mean(0)
    a, b = src - cs, dst - cd
    yaw = math.atan2(float(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])), float(np.sum(a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1])))
    c, s = math.cos(yaw), math.sin(yaw)
    ra = np.stack([c * a[:, 0] - s * a[:, 1], s * a[:, 0] + c * a[:, 1], a[:, 2]], 1)
    k = 3 if use_z else 2
    den = float(np.sum(ra[:, :k] ** 2))
    if den <= 1e-12:
        raise InputError("camera centres are all at one point; cannot fit a similarity")
    scale = float(np.sum(ra[:, :k] * b[:, :k])) / den
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    t = cd - scale * R @ cs
    return scale, yaw, t


def fit_similarity(centres, gps, *, threshold_m: float = 5.0, iterations: int = 500, use_z: bool = False,
                   seed: int = 0, min_scale: float = 1e-3) -> Similarity:
    """Robust fit; ``centres`` and ``gps`` are (n, 3) in metres (gps already in the site frame)."""
    src, dst = np.asarray(centres, float).reshape(-1, 3), np.asarray(gps, float).reshape(-1, 3)
    if len(src) != len(dst):
        raise InputError(f"{len(src)} camera centres but {len(dst)} GPS positions")
    if len(src) < 2:
        raise InputError("need at least two cameras with GPS to fit a similarity")
    rng = np.random.default_rng(seed)
    best = None
    n = len(src)
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)] if n * (n - 1) // 2 <= iterations else None
    for k in range(len(pairs) if pairs else iterations):
        i, j = pairs[k] if pairs else rng.choice(n, 2, replace=False)
        if np.linalg.norm(src[i, :2] - src[j, :2]) < 1e-6:
            continue
        try:
            s, yaw, t = _fit(src[[i, j]], dst[[i, j]], False)
        except InputError:
            continue
        if s < min_scale:
            continue
        c, si = math.cos(yaw), math.sin(yaw)
        pred = s * src @ np.array([[c, -si, 0], [si, c, 0], [0, 0, 1]]).T + t
        err = np.linalg.norm(pred[:, :2] - dst[:, :2], axis=1)
        inl = err < threshold_m
        score = (int(inl.sum()), -float(np.sum(np.minimum(err, threshold_m) ** 2)))
        if best is None or score > best[0]:
            best = (score, inl)
    if best is None or best[0][0] < 2:
        raise InputError("RANSAC found no consistent camera pair; are the GPS positions in the site frame?")
    inl = best[1]
    for _ in range(5):  # refit on inliers, re-select
        s, yaw, t = _fit(src[inl], dst[inl], use_z)
        sim = Similarity(s, yaw, t, inl, 0.0)
        err = np.linalg.norm(sim.apply(src)[:, :2] - dst[:, :2], axis=1)
        new = err < threshold_m
        if new.sum() < 2 or np.array_equal(new, inl):
            break
        inl = new
    s, yaw, t = _fit(src[inl], dst[inl], use_z)
    sim = Similarity(s, yaw, t, inl, 0.0)
    err = np.linalg.norm(sim.apply(src)[:, :2] - dst[:, :2], axis=1)
    sim.rmse_m = float(np.sqrt(np.mean(err[inl] ** 2)))
    return sim

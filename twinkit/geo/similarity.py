"""Similarity transforms ``dst ~= scale * R @ src + t``: the closed-form least-squares fit, and a robust one.

- :func:`closed_form_similarity` -- the one least-squares similarity (Umeyama 1991) between corresponding
  points, 2D or 3D, with or without scale, optionally a rotation about z only. Used by the photo branch
  (GCPs -> site, the SfM shape against the truth), the road source (an OpenDRIVE map's projection ->
  the site frame) and :func:`fit_similarity`.
- :func:`fit_similarity` -- camera centres (mesh frame) -> GPS positions (site frame), rotation about up
  only: the closed form inside RANSAC on minimal samples of two cameras, so a few wild GPS fixes do not
  bend the result.
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


@dataclass
class SimilarityTransform:
    """``x' = scale * R @ x + t`` in 2D or 3D (metres in both frames; R a proper rotation, (d, d))."""

    scale: float
    R: np.ndarray  # (d, d)
    t: np.ndarray  # (d,)
    #: the rotation angle (rad, counter-clockwise about z) of a planar fit; None for a full 3D rotation
    angle_rad: float | None = None

    def apply(self, p) -> np.ndarray:
        """(n, d) or (d,) points -> (n, d) float64."""
        p = np.asarray(p, float).reshape(-1, len(self.t))
        return self.scale * p @ self.R.T + self.t

    def rotate(self, R_wc: np.ndarray) -> np.ndarray:
        """A rotation (camera -> source frame) into the destination frame."""
        return self.R @ R_wc

    def compose_after(self, other: "SimilarityTransform") -> "SimilarityTransform":
        """self o other"""
        return SimilarityTransform(self.scale * other.scale, self.R @ other.R,
                                   self.scale * self.R @ other.t + self.t)

    def to_json(self) -> dict:
        return {"scale": float(self.scale), "R": self.R.tolist(), "t": self.t.tolist(),
                "definition": "x_site = scale * R @ x_model + t"}


def closed_form_similarity(src, dst, *, with_scale: bool = True, about_z: bool = False,
                           scale_dims: int | None = None) -> SimilarityTransform:
    """Least-squares similarity ``dst ~= scale * R @ src + t`` in closed form (Umeyama 1991).

    ``src``, ``dst``: (n, d) corresponding points, d = 2 or 3, n >= 2 (>= 3 for a 3D rotation), float
    metres. In 3D (``about_z=False``) R is the full rotation from the SVD of the cross-covariance, with
    the reflection fix. In 2D, or in 3D with ``about_z=True`` (z is up in both frames), R turns about z
    only: the same solution written for one axis, the angle ``atan2`` of the antisymmetric and the
    symmetric part of the x, y cross-covariance, returned as ``angle_rad``. ``scale_dims`` (planar fits):
    the axes the scale is fitted on (2 = x, y, the default; 3 = x, y and z). ``with_scale=False`` fixes
    the scale at 1. Raises InputError when a planar fit's source points are all at one point.
    """
    src, dst = np.asarray(src, float), np.asarray(dst, float)
    d = src.shape[1]
    cs, cd = src.mean(0), dst.mean(0)
    a, b = src - cs, dst - cd
    if d == 2 or about_z:
        yaw = math.atan2(float(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])),
                         float(np.sum(a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1])))
        c, s = math.cos(yaw), math.sin(yaw)
        ra = np.stack([c * a[:, 0] - s * a[:, 1], s * a[:, 0] + c * a[:, 1], *a[:, 2:].T], 1)
        k = scale_dims or 2
        scale = 1.0
        if with_scale:
            den = float(np.sum(ra[:, :k] ** 2))
            if den <= 1e-12:
                raise InputError("the points to fit a similarity to are all at one point (no spread to fit it on)")
            scale = float(np.sum(ra[:, :k] * b[:, :k])) / den
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) if d == 3 else np.array([[c, -s], [s, c]])
        return SimilarityTransform(scale, R, cd - scale * R @ cs, yaw)
    U, S, Vt = np.linalg.svd(b.T @ a / len(src))
    D = np.eye(d)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        D[-1, -1] = -1
    R = U @ D @ Vt
    var = float((a ** 2).sum() / len(src))
    scale = float(np.trace(np.diag(S) @ D) / var) if with_scale and var > 0 else 1.0
    return SimilarityTransform(scale, R, cd - scale * R @ cs)


def _robust_result(src: np.ndarray, dst: np.ndarray, use_z: bool, inliers: np.ndarray) -> Similarity:
    T = closed_form_similarity(src, dst, about_z=True, scale_dims=3 if use_z else 2)
    assert T.angle_rad is not None  # a planar fit (about_z) has its angle
    return Similarity(T.scale, T.angle_rad, T.t, inliers, 0.0)


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
            T = closed_form_similarity(src[[i, j]], dst[[i, j]], about_z=True)
        except InputError:
            continue
        if T.scale < min_scale:
            continue
        pred = T.apply(src)
        err = np.linalg.norm(pred[:, :2] - dst[:, :2], axis=1)
        inl = err < threshold_m
        score = (int(inl.sum()), -float(np.sum(np.minimum(err, threshold_m) ** 2)))
        if best is None or score > best[0]:
            best = (score, inl)
    if best is None or best[0][0] < 2:
        raise InputError("RANSAC found no consistent camera pair; are the GPS positions in the site frame?")
    inl = best[1]
    for _ in range(5):  # refit on inliers, re-select
        sim = _robust_result(src[inl], dst[inl], use_z, inl)
        err = np.linalg.norm(sim.apply(src)[:, :2] - dst[:, :2], axis=1)
        new = err < threshold_m
        if new.sum() < 2 or np.array_equal(new, inl):
            break
        inl = new
    sim = _robust_result(src[inl], dst[inl], use_z, inl)
    err = np.linalg.norm(sim.apply(src)[:, :2] - dst[:, :2], axis=1)
    sim.rmse_m = float(np.sqrt(np.mean(err[inl] ** 2)))
    return sim

"""Georeferencing an SfM model into the site frame.

Routes, best first:
  gcp   ground-control points: each GCP is triangulated from its pixel observations in the registered
        photos, then a full 3D similarity (scale, rotation, translation; Umeyama) maps the model onto the
        surveyed positions. Needs >= 3 GCPs seen in >= 2 registered photos. Centimetre-level when the
        GCPs are.
  gps   EXIF GPS: the model is levelled first (up = RANSAC ground-plane normal of the sparse cloud,
        checked against the photos' mean "up"), then the robust yaw-only similarity
        (twinkit.geo.similarity) maps the camera centres onto the GPS fixes. Consumer GPS is metres off,
        so the site frame is only as good as the average of the fixes (about sigma / sqrt(n)).
  base_point  no GPS: levelled and centred on the mean camera position, scale from ``scale`` (1 = the
        model's arbitrary unit; give a known distance's ratio).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from twinkit import InputError


@dataclass
class Transform:
    """x_site = scale * R @ x_model + t"""

    scale: float
    R: np.ndarray
    t: np.ndarray

    def apply(self, p) -> np.ndarray:
        p = np.asarray(p, float).reshape(-1, 3)
        return self.scale * p @ self.R.T + self.t

    def rotate(self, R_wc: np.ndarray) -> np.ndarray:
        return self.R @ R_wc

    def compose_after(self, other: "Transform") -> "Transform":
        """self o other"""
        return Transform(self.scale * other.scale, self.R @ other.R, self.scale * self.R @ other.t + self.t)

    def to_json(self) -> dict:
        return {"scale": float(self.scale), "R": self.R.tolist(), "t": self.t.tolist(),
                "definition": "x_site = scale * R @ x_model + t"}


def umeyama(src, dst, with_scale: bool = True) -> Transform:
    src, dst = np.asarray(src, float), np.asarray(dst, float)
    ms, md = src.mean(0), dst.mean(0)
    a, b = src - ms, dst - md
    U, S, Vt = np.linalg.svd(b.T @ a / len(src))
    D = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        D[2, 2] = -1
    R = U @ D @ Vt
    var = float((a ** 2).sum() / len(src))
    s = float(np.trace(np.diag(S) @ D) / var) if with_scale and var > 0 else 1.0
    return Transform(s, R, md - s * R @ ms)


def robust_umeyama(src, dst, outlier_m: float, min_keep: int = 3) -> tuple[Transform, np.ndarray]:
    """Umeyama similarity that drops, one at a time, the worst correspondence while its residual exceeds
    ``max(outlier_m, 3 x the median residual)`` and more than ``min_keep`` remain (a ground-control point
    triangulated from two grazing views, or one clicked on the wrong corner). Returns the transform and
    the mask of the points kept."""
    src, dst = np.asarray(src, float), np.asarray(dst, float)
    keep = np.ones(len(src), bool)
    T = umeyama(src, dst)
    while keep.sum() > min_keep:
        res = np.linalg.norm(T.apply(src) - dst, axis=1)
        worst = int(np.argmax(np.where(keep, res, -1.0)))
        if res[worst] <= max(outlier_m, 3.0 * float(np.median(res[keep]))):
            break
        keep[worst] = False
        T = umeyama(src[keep], dst[keep])
    return T, keep


def rotation_between(a, b) -> np.ndarray:
    a = np.asarray(a, float) / np.linalg.norm(a)
    b = np.asarray(b, float) / np.linalg.norm(b)
    v = np.cross(a, b)
    c = float(a @ b)
    if np.linalg.norm(v) < 1e-12:
        if c > 0:
            return np.eye(3)
        axis = np.cross(a, [1.0, 0, 0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(a, [0, 1.0, 0])
        axis /= np.linalg.norm(axis)
        return 2 * np.outer(axis, axis) - np.eye(3)
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx * ((1 - c) / (np.linalg.norm(v) ** 2))


def ransac_plane(pts: np.ndarray, threshold: float, iterations: int = 500, seed: int = 0,
                 normal_hint: np.ndarray | None = None, max_angle_deg: float = 35.0):
    """Plane n.x + d = 0 with the most inliers (optionally within ``max_angle_deg`` of ``normal_hint``)."""
    rng = np.random.default_rng(seed)
    best = (0, None)
    n = len(pts)
    if n < 3:
        return None, np.zeros(n, bool)
    cos_max = math.cos(math.radians(max_angle_deg))
    for _ in range(iterations):
        s = pts[rng.choice(n, 3, replace=False)]
        nv = np.cross(s[1] - s[0], s[2] - s[0])
        ln = np.linalg.norm(nv)
        if ln < 1e-12:
            continue
        nv /= ln
        if normal_hint is not None:
            if nv @ normal_hint < 0:
                nv = -nv
            if nv @ normal_hint < cos_max:
                continue
        d = -nv @ s[0]
        cnt = int((np.abs(pts @ nv + d) < threshold).sum())
        if cnt > best[0]:
            best = (cnt, (nv, d))
    if best[1] is None:
        return None, np.zeros(n, bool)
    nv, d = best[1]
    inl = np.abs(pts @ nv + d) < threshold
    # least-squares refit on the inliers
    c = pts[inl].mean(0)
    _, _, Vt = np.linalg.svd(pts[inl] - c)
    nv2 = Vt[2]
    if nv2 @ nv < 0:
        nv2 = -nv2
    return (nv2, float(-nv2 @ c)), np.abs(pts @ nv2 - nv2 @ c) < threshold


def camera_up(R_wc: np.ndarray) -> np.ndarray:
    """Mean 'up' of the photos (-y of an OpenCV camera) in the model frame."""
    ups = -np.asarray(R_wc)[:, :, 1]
    m = ups.mean(0)
    return m / np.linalg.norm(m)


def level(centres: np.ndarray, R_wc: np.ndarray, sparse: np.ndarray, log=None) -> tuple[np.ndarray, dict]:
    """Rotation that makes the model's up +z: the ground plane normal where one is found, else the photos' up."""
    up_cam = camera_up(R_wc)
    info: dict = {"camera_up_model": up_cam.tolist()}
    up = up_cam
    if len(sparse) >= 50:
        # scale-free threshold: a fraction of the camera spread (or of the cloud when cameras barely move)
        spread = float(np.median(np.linalg.norm(sparse - np.median(sparse, 0), axis=1)))
        plane, inl = ransac_plane(sparse, 0.01 * spread, normal_hint=up_cam, max_angle_deg=30.0)
        if plane is not None and inl.mean() > 0.05:
            nv = plane[0]
            # the ground is below the cameras
            below = float(np.median(centres @ nv + plane[1])) > 0
            info.update({"ground_plane_inlier_ratio": float(inl.mean()), "ground_below_cameras": below,
                         "ground_vs_camera_up_deg": math.degrees(math.acos(min(1.0, float(nv @ up_cam))))})
            if below:
                up = nv
                info["up_from"] = "ground_plane"
    info.setdefault("up_from", "camera_up")
    info["up_model"] = up.tolist()
    return rotation_between(up, [0.0, 0.0, 1.0]), info


# --------------------------------------------------------------------------- ground control points

def read_gcp_file(path: Path, frame) -> list[dict]:
    """Read GCPs: OpenSfM's ground_control_points.json (lat/lon/alt + normalised projections) or
    twinkit's {"points": [{"id", "site_xyz": [x, y, z] | "position": {latitude, longitude, altitude},
    "observations": [{"image", "pixel": [u, v]} | {"shot_id", "projection": [x, y]}]}]}."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
        pts = doc["points"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputError(f"{path}: not a ground-control-point file ({exc}); expected JSON with a 'points' list "
                         f"(see docs/photo.md)") from None
    out = []
    for p in pts:
        obs = []
        for o in p.get("observations", []):
            img = o.get("image", o.get("shot_id"))
            if "pixel" in o:
                obs.append({"image": img, "pixel": [float(v) for v in o["pixel"]]})
            elif "projection" in o:
                obs.append({"image": img, "normalized": [float(v) for v in o["projection"]]})
        if "site_xyz" in p:
            xyz = np.asarray(p["site_xyz"], float)
        elif "position" in p and frame is not None:
            pos = p["position"]
            if "latitude" not in pos or "longitude" not in pos:
                continue
            xy = frame.lonlat_to_local([[pos["longitude"], pos["latitude"]]])[0]
            xyz = np.array([xy[0], xy[1], float(pos.get("altitude", frame.alt)) - frame.alt])
        else:
            continue  # a GCP without a known position (OpenSfM allows these) cannot anchor anything
        out.append({"id": str(p.get("id", len(out))), "site_xyz": xyz, "observations": obs})
    return out


def triangulate(rows: dict, obs: list[dict]) -> tuple[np.ndarray | None, int]:
    """Linear triangulation (DLT) of one point from observations in registered photos (model frame)."""
    A = []
    for o in obs:
        r = rows.get(o["image"])
        if r is None:
            continue
        K = np.asarray(r["K"], float)
        w, h = r["width"], r["height"]
        if "pixel" in o:
            u, v = o["pixel"]
        else:  # OpenSfM normalised image coordinates: (pixel - size / 2) / max(w, h)
            u = o["normalized"][0] * max(w, h) + w / 2.0 - 0.5
            v = o["normalized"][1] * max(w, h) + h / 2.0 - 0.5
        R_wc = np.asarray(r["R_world_from_camera"], float)
        C = np.asarray(r["center"], float)
        P = K @ np.hstack([R_wc.T, (-R_wc.T @ C)[:, None]])
        A.append(u * P[2] - P[0])
        A.append(v * P[2] - P[1])
    if len(A) < 4:
        return None, len(A) // 2
    _, _, Vt = np.linalg.svd(np.asarray(A))
    X = Vt[-1]
    if abs(X[3]) < 1e-12:
        return None, len(A) // 2
    return X[:3] / X[3], len(A) // 2

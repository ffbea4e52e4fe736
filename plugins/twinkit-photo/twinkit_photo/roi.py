"""The region of interest of a photo site: a box around the cameras, standing on the ground plane.

Site frame throughout (metres when the georeference was scaled, else model units). The dense step keeps
only what lies inside the box; roi.json is meant to be edited by hand (the thesis's manual step 3.8.2).
"""
from __future__ import annotations

import numpy as np

from .georef import ransac_plane


def ground_plane(C: np.ndarray, pts: np.ndarray, threshold_m: float) -> dict:
    """The ground under the cameras: a RANSAC plane of the sparse points below the cameras near the walk,
    else 1.6 m under the cameras' median height. ``C`` (n, 3) camera centres, ``pts`` (N, 3) sparse points.
    Returns {"z_m" under the cameras' mean x, y, "normal", "source", ("inliers", "tilt_deg")}."""
    ground = {"z_m": float(np.median(C[:, 2]) - 1.6), "normal": [0.0, 0.0, 1.0], "source": "cameras - 1.6 m"}
    if len(pts) < 50:
        return ground
    near = pts[np.linalg.norm(pts[:, :2] - C[:, :2].mean(0), axis=1) < 3 * max(5.0, np.ptp(C[:, :2], 0).max())]
    below = near[near[:, 2] < np.median(C[:, 2])]
    plane, inl = ransac_plane(below if len(below) >= 30 else near, threshold_m,
                              normal_hint=np.array([0, 0, 1.0]), max_angle_deg=20.0)
    if plane is not None and inl.sum() >= 20:
        nv, d = plane
        cx, cy = C[:, :2].mean(0)
        z0 = float(-(d + nv[0] * cx + nv[1] * cy) / nv[2])
        ground = {"z_m": z0, "normal": nv.tolist(), "source": "RANSAC on the sparse points",
                  "inliers": int(inl.sum()),
                  "tilt_deg": float(np.degrees(np.arccos(min(1.0, abs(nv[2])))))}
    return ground


def subject_depth(C: np.ndarray, pts: np.ndarray, max_depth_m: float) -> tuple[float, str]:
    """The depth limit of the region of interest and the dense step: ``max_depth_m``, unless the photos' subject
    is far (half the sparse points lie over half of it from their nearest camera: a façade photographed from
    across a square; Sceaux scaled to metres has its median point 42 m away), then raised to the distance within
    which 98 % of the sparse points lie (the box's percentile). Returns (limit, why); 0 stays 0 (no limit)."""
    if max_depth_m <= 0 or len(pts) < 50:
        return max_depth_m, "steps.roi.max_depth_m"
    from scipy.spatial import cKDTree

    q50, q98 = (float(v) for v in np.quantile(cKDTree(C).query(pts)[0], [0.5, 0.98]))
    if q50 <= max_depth_m / 2 or q98 <= max_depth_m:
        return max_depth_m, "steps.roi.max_depth_m"
    return q98, (f"raised from steps.roi.max_depth_m {max_depth_m:g}: the median sparse point is {q50:.1f} from "
                 f"its nearest camera, 98 % lie within {q98:.1f}")


def roi_box(C: np.ndarray, pts: np.ndarray, ground_z: float, params, max_depth: float | None = None) -> dict:
    """{"min": [x, y, z], "max": [x, y, z]}: the cameras' extent plus ``margin_m``, grown to what the photos
    look at (2nd-98th percentile of the sparse points within ``max_depth`` (default ``max_depth_m``) of a
    camera), from ``below_ground_m`` under the ground to at least ``above_ground_m`` over it."""
    depth = params.max_depth_m if max_depth is None else max_depth
    lo = C[:, :2].min(0) - params.margin_m
    hi = C[:, :2].max(0) + params.margin_m
    zlo, zhi = ground_z - params.below_ground_m, ground_z + params.above_ground_m
    if len(pts) >= 50:
        from scipy.spatial import cKDTree

        seen = pts
        if depth > 0:
            dist, _ = cKDTree(C).query(pts)
            seen = pts[dist <= depth]
        if len(seen) >= 50:
            q0, q1 = np.quantile(seen, [0.02, 0.98], axis=0)
            lo, hi = np.minimum(lo, q0[:2]), np.maximum(hi, q1[:2])
            zhi = max(zhi, float(q1[2]))
    return {"min": [float(lo[0]), float(lo[1]), zlo], "max": [float(hi[0]), float(hi[1]), zhi]}


def roi_doc(C: np.ndarray, pts: np.ndarray, box: dict, ground: dict, max_depth_m: float, scaled: bool,
            depth_why: str = "steps.roi.max_depth_m", units: str | None = None) -> dict:
    """roi.json: the box, the ground, the dense step's depth limit (and where it came from), the frame's units
    (``units``: cameras_site.json's, which say when the scale is estimated) and how much of the sparse cloud
    is inside."""
    inside = np.all((pts >= box["min"]) & (pts <= box["max"]), axis=1).mean() if len(pts) else 0.0
    return {"_comment": "Edit this file to change what the dense step keeps (the thesis's manual step 3.8.2): "
                        "box min/max, ground z and max_depth_m in the site frame's units (see units). The next run keeps your edit and "
                        "re-runs only the steps after it.",
            "box": box, "ground": ground, "max_depth_m": max_depth_m, "max_depth_from": depth_why, "scaled": scaled,
            "units": (units or "metres") if scaled else "model units (unscaled)",
            "cameras_xy_extent": np.ptp(C[:, :2], 0).tolist(), "sparse_inside_ratio": float(inside)}

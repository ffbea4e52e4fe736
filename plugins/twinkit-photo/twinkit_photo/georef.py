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
from pathlib import Path

import numpy as np

from twinkit import InputError
from twinkit.geo.similarity import SimilarityTransform as Transform  # the photo branch's name for it
from twinkit.geo.similarity import closed_form_similarity


def robust_umeyama(src, dst, outlier_m: float, min_keep: int = 3) -> tuple[Transform, np.ndarray]:
    """Umeyama similarity that drops, one at a time, the worst correspondence while its residual exceeds
    ``max(outlier_m, 3 x the median residual)`` and more than ``min_keep`` remain (a ground-control point
    triangulated from two grazing views, or one clicked on the wrong corner). Returns the transform and
    the mask of the points kept."""
    src, dst = np.asarray(src, float), np.asarray(dst, float)
    keep = np.ones(len(src), bool)
    T = closed_form_similarity(src, dst)
    while keep.sum() > min_keep:
        res = np.linalg.norm(T.apply(src) - dst, axis=1)
        worst = int(np.argmax(np.where(keep, res, -1.0)))
        if res[worst] <= max(outlier_m, 3.0 * float(np.median(res[keep]))):
            break
        keep[worst] = False
        T = closed_form_similarity(src[keep], dst[keep])
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
    """Mean 'up' of the photos (-y of an OpenCV camera) in the model frame (plain mean; see camera_horizon)."""
    ups = -np.asarray(R_wc)[:, :, 1]
    m = ups.mean(0)
    return m / np.linalg.norm(m)


def _angle_deg(a, b) -> float:
    a = np.asarray(a, float) / np.linalg.norm(a)
    b = np.asarray(b, float) / np.linalg.norm(b)
    return math.degrees(math.acos(max(-1.0, min(1.0, float(a @ b)))))


def camera_horizon(R_wc: np.ndarray, max_dev_deg: float = 25.0) -> tuple[np.ndarray, dict]:
    """The photos' own vertical: the robust mean of the cameras' up axes (-y of an OpenCV camera).

    People hold a camera upright, so each photo's up axis is the true vertical give or take its roll and
    pitch (a few degrees, in every direction): their mean is the vertical to a fraction of a degree with a
    few dozen photos (the assumption COLMAP's orientation aligner and OpenSfM's upright prior make). Photos
    far from the mean (a photo turned 90 degrees without an EXIF flag, one looking at the sky) are left out
    and the mean taken again. Returns the unit vector and {photos, used, spread_deg (rms angle of the used
    ups to the mean), std_error_deg (spread / sqrt(used))}."""
    ups = -np.asarray(R_wc, float)[:, :, 1]
    ups = ups / np.linalg.norm(ups, axis=1, keepdims=True)
    m = ups.mean(0)
    if np.linalg.norm(m) < 1e-9:
        m = ups[0]
    m = m / np.linalg.norm(m)
    keep = np.ones(len(ups), bool)
    cos_max = math.cos(math.radians(max_dev_deg))
    for _ in range(10):
        k2 = ups @ m >= cos_max
        if k2.sum() < max(2, (len(ups) + 1) // 2):  # no consistent majority: keep the plain mean
            k2 = np.ones(len(ups), bool)
        m2 = ups[k2].mean(0)
        m2 /= np.linalg.norm(m2)
        done = bool(np.array_equal(k2, keep)) and float(m2 @ m) > 1 - 1e-12
        keep, m = k2, m2
        if done:
            break
    ang = np.degrees(np.arccos(np.clip(ups[keep] @ m, -1.0, 1.0)))
    spread = float(np.sqrt(np.mean(ang ** 2))) if len(ang) else 180.0
    return m, {"photos": int(len(ups)), "used": int(keep.sum()), "spread_deg": round(spread, 3),
               "std_error_deg": round(spread / math.sqrt(max(1, int(keep.sum()))), 3),
               "left_out": [int(i) for i in np.flatnonzero(~keep)]}


def tilt_components(up, ref, centres=None) -> dict:
    """Angle of ``up`` from ``ref`` in degrees, and (with camera centres) split into the tilt along the walk
    (the main horizontal direction of the centres) and sideways."""
    up = np.asarray(up, float) / np.linalg.norm(up)
    ref = np.asarray(ref, float) / np.linalg.norm(ref)
    out = {"total_deg": round(_angle_deg(up, ref), 3)}
    if centres is not None and len(centres) >= 2:
        P = np.asarray(centres, float)
        P = P - P.mean(0)
        P = P - np.outer(P @ ref, ref)  # horizontal part
        _, _, Vt = np.linalg.svd(P, full_matrices=False)
        along = Vt[0] - (Vt[0] @ ref) * ref
        if np.linalg.norm(along) > 1e-9:
            along /= np.linalg.norm(along)
            side = np.cross(ref, along)
            out["along_walk_deg"] = round(math.degrees(math.atan2(float(up @ along), float(up @ ref))), 3)
            out["sideways_deg"] = round(math.degrees(math.atan2(float(up @ side), float(up @ ref))), 3)
    return out


def _ground_plane_up(sparse, centres, up, up_cam, photos_agree: bool, sigma: float, min_ground_support: float,
                     ground_agree_deg: float) -> tuple[dict, np.ndarray] | None:
    """The levelling's ground-plane candidate: a RANSAC plane of the sparse points (threshold 1 % of the
    cloud's spread), its normal turned to ``up``, and whether it may be used (below the cameras, enough
    support, within ``max(ground_agree_deg, 3 sigma)`` of ``up`` where the photos agree). (info, normal) or
    None without a plane."""
    spread = float(np.median(np.linalg.norm(sparse - np.median(sparse, 0), axis=1)))
    plane, inl = ransac_plane(sparse, 0.01 * spread, normal_hint=up_cam if photos_agree else None,
                              max_angle_deg=30.0)
    if plane is None:
        return None
    nv = plane[0]
    if nv @ up < 0:
        nv = -nv
    below = float(np.median(centres @ nv + (plane[1] if nv @ plane[0] > 0 else -plane[1]))) > 0
    ratio = float(inl.mean())
    ang = _angle_deg(nv, up)
    tol = max(ground_agree_deg, 3.0 * sigma)
    g = {"inlier_ratio": round(ratio, 4), "below_cameras": below, "vs_photo_up_deg": round(ang, 3),
         "tilt_vs_photo_up": tilt_components(nv, up, centres), "agree_limit_deg": round(tol, 3),
         "min_support": min_ground_support}
    if not below:
        g["used"], g["why_not"] = False, "the plane is not below the cameras"
    elif ratio < min_ground_support:
        g["used"], g["why_not"] = False, (f"too little support: {100 * ratio:.1f} % of the points "
                                          f"(needs {100 * min_ground_support:.0f} %)")
    elif photos_agree and ang > tol:
        g["used"], g["why_not"] = False, (f"{ang:.1f} degrees from the photos' vertical (limit {tol:.1f}): "
                                          f"a sloped or cambered ground, or not the ground")
    else:
        g["used"] = True
    return g, nv


def level(centres: np.ndarray, R_wc: np.ndarray, sparse: np.ndarray, log=None, *, up_model=None,
          min_ground_support: float = 0.2, ground_agree_deg: float = 2.0, vertical: tuple | None = None,
          max_lines_vs_horizon_deg: float = 30.0) -> tuple[np.ndarray, dict]:
    """Rotation that makes the model's up +z, from the photos' own horizon first.

    Sources, in order:
      * ``up_model``: the user's up vector (model frame) -- used as given;
      * the photos' horizon (:func:`camera_horizon`), corrected by vertical structure (``vertical``: an
        estimate from vertical lines in the photos, (unit vector, info), used where it lies within
        ``max_lines_vs_horizon_deg`` of the photos' horizon: photos of a tall facade are all pitched up,
        by 11 degrees at Sceaux, which no average of their up axes removes);
      * a RANSAC ground plane of the sparse points, only with enough support (``min_ground_support`` of the
        points) and only where it agrees with the photos within ``max(ground_agree_deg, 3 x their standard
        error)`` -- a street's camber, a slope or a roof is a plane too -- or where the photos' up axes
        do not agree among themselves (nadir or randomly turned photos).
    ``info`` records every estimate, which one was used (``up_from``) and the final up's angle to the photos'
    horizon (``final_vs_camera_horizon``), so a reader can check the levelling."""
    up_cam, hinfo = camera_horizon(R_wc)
    info: dict = {"camera_up_model": up_cam.tolist(), "camera_horizon": hinfo}
    photos_agree = hinfo["used"] >= max(3, 0.6 * hinfo["photos"]) and hinfo["spread_deg"] <= 25.0
    info["photos_agree"] = bool(photos_agree)
    up, up_from = up_cam, "camera_horizon"
    sigma = hinfo["std_error_deg"]
    if vertical is not None and vertical[0] is not None:
        v = np.asarray(vertical[0], float)
        v = v / np.linalg.norm(v)
        if v @ up_cam < 0:
            v = -v
        vi = dict(vertical[1] or {})
        vi["vs_camera_horizon_deg"] = round(_angle_deg(v, up_cam), 3)
        info["vertical_lines"] = vi
        if photos_agree and vi["vs_camera_horizon_deg"] <= max_lines_vs_horizon_deg:
            up, up_from = v, "vertical_lines"
            sigma = min(sigma, float(vi.get("std_error_deg", sigma)))
    if len(sparse) >= 50:
        gp = _ground_plane_up(sparse, centres, up, up_cam, photos_agree, sigma, min_ground_support, ground_agree_deg)
        if gp is not None:
            g, nv = gp
            if g["used"]:
                up, up_from = nv, "ground_plane"
            info["ground_plane"] = g
            info["ground_plane_inlier_ratio"] = g["inlier_ratio"]
            info["ground_vs_camera_up_deg"] = round(_angle_deg(nv, up_cam), 3)
    if up_model is not None and len(up_model) == 3:
        u = np.asarray(up_model, float)
        if np.linalg.norm(u) <= 0:
            raise InputError("steps.georeference.up_model must be a non-zero vector (x, y, z in the SfM model frame)")
        up, up_from = u / np.linalg.norm(u), "user"
    if not photos_agree and up_from == "camera_horizon" and log is not None:
        log.warning("georeference: the photos' up axes disagree (spread %.0f degrees, %d of %d consistent) and no "
                    "ground plane has enough support: the levelling is uncertain; give steps.georeference.up_model",
                    hinfo["spread_deg"], hinfo["used"], hinfo["photos"])
    info["up_from"] = up_from
    info["up_model"] = up.tolist()
    info["final_vs_camera_horizon"] = tilt_components(up, up_cam, centres)
    if log is not None:
        log.info("georeference: up from the %s, %.2f degrees from the photos' horizon (%d photos, spread %.1f deg)",
                 up_from.replace("_", " "), info["final_vs_camera_horizon"]["total_deg"], hinfo["used"],
                 hinfo["spread_deg"])
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


# --------------------------------------------------------------------------- vertical structure

def line_segments(gray: np.ndarray, min_len_px: float) -> np.ndarray:
    """Straight line segments (x1, y1, x2, y2) of a grayscale image: OpenCV's LSD where the build has it,
    else Canny + probabilistic Hough."""
    import cv2

    segs = None
    try:
        lsd = cv2.createLineSegmentDetector(cv2.LSD_REFINE_STD)
        segs = lsd.detect(gray)[0]
    except (AttributeError, cv2.error):
        segs = None
    if segs is None:
        edges = cv2.Canny(gray, 60, 160)
        segs = cv2.HoughLinesP(edges, 1, np.pi / 720, threshold=40, minLineLength=int(min_len_px), maxLineGap=3)
    if segs is None:
        return np.zeros((0, 4))
    segs = np.asarray(segs, float).reshape(-1, 4)
    ln = np.hypot(segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1])
    return segs[ln >= min_len_px]


def undistort_normalized(p: np.ndarray, model: str | None, params) -> np.ndarray:
    """Homogeneous normalised image points (n, 3) with COLMAP's radial distortion (SIMPLE_RADIAL, RADIAL,
    OPENCV's k1, k2) taken out by fixed-point iteration; other models are returned as they are."""
    if not params:
        return p
    params = list(params)
    k1 = k2 = 0.0
    if model == "SIMPLE_RADIAL" and len(params) >= 4:
        k1 = params[3]
    elif model == "RADIAL" and len(params) >= 5:
        k1, k2 = params[3], params[4]
    elif model in ("OPENCV", "FULL_OPENCV") and len(params) >= 6:
        k1, k2 = params[4], params[5]
    if k1 == 0 and k2 == 0:
        return p
    xd = p[:, :2] / p[:, 2:3]
    xu = xd.copy()
    for _ in range(10):
        r2 = (xu ** 2).sum(1, keepdims=True)
        xu = xd / (1 + k1 * r2 + k2 * r2 ** 2)
    return np.c_[xu, np.ones(len(xu))]


def vertical_from_lines(photos_dir: Path, cams: list[dict], up_hint: np.ndarray, max_px: int = 1024,
                        max_image_deg: float = 25.0, inlier_deg: float = 1.5, min_lines: int = 40,
                        min_photos: int = 3) -> tuple[np.ndarray | None, dict]:
    """The vertical from vertical structure: building edges, posts and window frames are vertical lines, so
    the plane through a photo's centre and such a line (its normal n, in the model frame) contains the
    vertical v: n . v = 0. Line segments within ``max_image_deg`` of the photo's up axis are collected from
    every photo, then v is the least-squares null direction of their normals (weighted by length), starting
    from ``up_hint`` (the photos' horizon) and keeping the lines within ``inlier_deg`` of it (a road's edges
    and other lines that only look upright fall out). Returns (v or None, info)."""
    import cv2

    normals, weights, per_photo = [], [], {}
    tan_max = math.tan(math.radians(max_image_deg))
    for c in cams:
        path = Path(photos_dir) / c["image"]
        # the pixels as SfM saw them: no EXIF rotation (COLMAP ignores the orientation flag)
        img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE | cv2.IMREAD_IGNORE_ORIENTATION)
        if img is None:
            continue
        h0, w0 = img.shape
        if abs(w0 / h0 - float(c["width"]) / float(c["height"])) > 0.02:
            continue  # not the image the camera describes (turned, or another file)
        s = min(1.0, max_px / float(max(h0, w0)))
        if s < 1.0:
            img = cv2.resize(img, (int(round(w0 * s)), int(round(h0 * s))), interpolation=cv2.INTER_AREA)
        sx, sy = img.shape[1] / float(c["width"]), img.shape[0] / float(c["height"])
        K = np.diag([sx, sy, 1.0]) @ np.asarray(c["K"], float)
        segs = line_segments(img, 0.05 * max(img.shape))
        if not len(segs):
            continue
        dx, dy = segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1]
        up = np.abs(dx) <= tan_max * np.abs(dy)
        segs = segs[up]
        if not len(segs):
            continue
        Ki = np.linalg.inv(K)
        p1 = undistort_normalized(np.c_[segs[:, :2], np.ones(len(segs))] @ Ki.T, c.get("model"), c.get("params"))
        p2 = undistort_normalized(np.c_[segs[:, 2:], np.ones(len(segs))] @ Ki.T, c.get("model"), c.get("params"))
        n = np.cross(p1, p2)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        n = n @ np.asarray(c["R_world_from_camera"], float).T
        normals.append(n)
        weights.append(np.hypot(segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1]) / max(img.shape))
        per_photo[c["image"]] = len(n)
    info: dict = {"lines": 0, "photos_with_lines": 0}
    if not normals:
        return None, info
    N = np.vstack(normals)
    W = np.concatenate(weights)
    src = np.concatenate([np.full(len(n), k) for k, n in enumerate(normals)])
    v = np.asarray(up_hint, float) / np.linalg.norm(up_hint)
    sin_in = None
    for thr in (8.0, 4.0, 2.5, inlier_deg, inlier_deg):
        sin_in = math.sin(math.radians(thr))
        inl = np.abs(N @ v) < sin_in
        if inl.sum() < 3:
            break
        M = (N[inl] * W[inl, None]).T @ N[inl]
        _, vec = np.linalg.eigh(M)
        v2 = vec[:, 0]
        v = v2 if v2 @ v > 0 else -v2
    inl = np.abs(N @ v) < sin_in
    photos = len(set(src[inl].tolist()))
    res = np.degrees(np.arcsin(np.clip(np.abs(N[inl] @ v), 0, 1)))
    info = {"lines": int(inl.sum()), "candidates": int(len(N)), "photos_with_lines": photos,
            "rms_deg": round(float(np.sqrt(np.mean(res ** 2))) if len(res) else 0.0, 3),
            # lines in one photo share its pose error: count photos, not lines
            "std_error_deg": round(float(np.sqrt(np.mean(res ** 2))) / math.sqrt(max(1, photos)) if len(res) else 90.0, 3)}
    if inl.sum() < min_lines or photos < min_photos:
        info["why_not"] = f"{int(inl.sum())} vertical lines in {photos} photos (needs {min_lines} in {min_photos})"
        return None, info
    return v, info

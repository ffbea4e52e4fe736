"""The georeference step's route: which fit (ground-control points, EXIF GPS, none, the user's transform),
the fit itself, the ground height, the outlier cameras and what goes into georef.json and cameras_site.json.

The algorithms (levelling, Umeyama, GCP triangulation, RANSAC plane, vertical lines) are in :mod:`georef`;
this module chooses among them and explains the choice. Frames: "model" is the SfM model frame (arbitrary
scale and orientation), "site" the site's local frame (metres, x east, y north, z up) or, without GPS/GCPs,
the levelled model frame. A :class:`~twinkit_photo.georef.Transform` maps model -> site.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from twinkit import InputError
from twinkit.geo.similarity import closed_form_similarity

from .georef import Transform, level, robust_umeyama, triangulate


@dataclass
class SfmModel:
    """The sfm step's model as the georeference step reads it: cameras_model.json and sparse.npz."""

    doc: dict                      # cameras_model.json
    sparse: Any                    # sparse.npz (xyz, rgb, vis_image, vis_point)
    rows: dict = field(init=False)  # {photo name: camera row}
    names: list = field(init=False)  # registered photos, sorted
    C: np.ndarray = field(init=False)    # (n, 3) camera centres, model frame
    Rwc: np.ndarray = field(init=False)  # (n, 3, 3) world-from-camera rotations, model frame

    def __post_init__(self):
        self.rows = {c["image"]: c for c in self.doc["cameras"]}
        self.names = sorted(self.rows)
        self.C = np.array([self.rows[n]["center"] for n in self.names], float)
        self.Rwc = np.array([self.rows[n]["R_world_from_camera"] for n in self.names], float)

    def with_gps(self) -> list[str]:
        """The registered photos with an EXIF GPS fix."""
        return [n for n in self.names if n in self.doc.get("exif_gps", {})]


# --------------------------------------------------------------------------- validate

def known_distance(params) -> float | None:
    """Check the user's frame parameters (up vector, known distance); the known distance's length in model
    units, or None."""
    if params.up_model and len(params.up_model) != 3:
        raise InputError(f"steps.georeference.up_model has {len(params.up_model)} numbers; give 3 (x, y, z in the SfM "
                         f"model frame, e.g. read off sfm/sparse_model.ply) or none")
    if not (params.distance_points_model or params.distance_m):
        return None
    if len(params.distance_points_model) != 6 or params.distance_m <= 0:
        raise InputError("steps.georeference: a known distance needs steps.georeference.distance_points_model "
                         "(6 numbers: two points x1, y1, z1, x2, y2, z2 in the SfM model frame) and "
                         "steps.georeference.distance_m > 0 (their distance in metres)")
    pa, pb = np.asarray(params.distance_points_model, float).reshape(2, 3)
    known = float(np.linalg.norm(pa - pb))
    if known <= 0:
        raise InputError("steps.georeference.distance_points_model: the two points are the same point")
    return known


def usable_gcps(rows: dict, gcps: list[dict], min_views: int) -> list[tuple]:
    """The GCPs triangulated from at least ``min_views`` registered photos: (id, model xyz, site xyz, views)."""
    out = []
    for g in gcps:
        X, nv = triangulate(rows, g["observations"])
        if X is not None and nv >= min_views:
            out.append((g["id"], X, g["site_xyz"], nv))
    return out


def suggest_site(model: dict, names: list[str]) -> str:
    """With EXIF GPS and no site CRS: the UTM zone of the photos and a base point (their mean position)."""
    ll = np.array([model["exif_gps"][n] for n in names], dtype=float)
    lat, lon = float(np.nanmean(ll[:, 0])), float(np.nanmean(ll[:, 1]))
    alt = float(np.nanmean(ll[:, 2])) if np.isfinite(ll[:, 2]).any() else 0.0
    zone = int((lon + 180.0) // 6.0) % 60 + 1
    epsg = (32600 if lat >= 0 else 32700) + zone
    return (f"set site.crs=EPSG:{epsg} (WGS 84 / UTM zone {zone}{'N' if lat >= 0 else 'S'}, the photos' zone; "
            f"or your country's grid) and site.base_point={{lat: {lat:.6f}, lon: {lon:.6f}, alt: {alt:.1f}}} "
            f"(the photos' mean GPS position) in conf/site/<site>.yaml")


# --------------------------------------------------------------------------- choose the method

def choose_method(params, m: SfmModel, gcp_rows: list, n_gcps: int, gcp_json: Path | None, frame, log,
                  info: dict) -> str:
    """The route: ``params.method``, or for auto GCPs (3 usable), else GPS (3 fixes and a site CRS), else
    none; a 4x4 ``transform_model_to_site`` wins over all. Why a GCP file or the GPS went unused goes into
    ``info`` (and the log)."""
    method = params.method
    if method == "auto":
        gps_ok = m.with_gps()
        if gcp_json is not None and len(gcp_rows) < 3:
            # the user gave a GCP file: say why it was not used and what was used instead
            why = (f"only {len(gcp_rows)} of its {n_gcps} points are seen in >= {params.min_gcp_views} "
                   f"registered photos (3 needed)")
            instead = ("EXIF GPS" if len(gps_ok) >= 3 and frame is not None else
                       "nothing: the model is only levelled and centred")
            log.warning("georeference: the GCP file %s cannot be used: %s; using %s instead",
                        Path(gcp_json).name, why, instead)
            info["gcp_unused"] = {"file": Path(gcp_json).name, "why": why, "used_instead": instead,
                                  "points": n_gcps, "usable": len(gcp_rows)}
        method = _auto_method(params, m, gcp_rows, gps_ok, frame, log, info)
    if len(params.transform_model_to_site) not in (0, 16):
        raise InputError(f"steps.georeference.transform_model_to_site has {len(params.transform_model_to_site)} numbers; "
                         f"give 16 (a 4x4 similarity, row by row) or none")
    if params.transform_model_to_site:
        method = "transform"
    return method


def _auto_method(params, m: SfmModel, gcp_rows: list, gps_ok: list[str], frame, log, info: dict) -> str:
    if len(gcp_rows) >= 3:
        return "gcp"
    if len(gps_ok) >= 3 and frame is not None:
        return "gps"
    if len(gps_ok) >= 3 and frame is None:
        log.warning("georeference: %d photos carry EXIF GPS but the site has no crs/base_point, so "
                    "the GPS is not used: %s", len(gps_ok), suggest_site(m.doc, gps_ok))
        info["gps_unused"] = {"photos_with_gps": len(gps_ok), "why": "the site has no crs or base_point",
                              "suggestion": suggest_site(m.doc, gps_ok)}
    else:
        log.warning("georeference: no usable GCPs and fewer than 3 registered photos with EXIF GPS: the model is "
                    "levelled and centred, %s; give site.inputs.gcp for a georeferenced result", scale_words(params))
    return "none"


def scale_words(params) -> str:
    """What method none does about the scale, as the log says it: the known distance, the given scale, the
    nominal eye height, or nothing (model units)."""
    if params.distance_points_model or params.distance_m:
        return f"scaled by the known distance (steps.georeference.distance_m={params.distance_m:g})"
    if params.scale != 1.0:
        return f"scaled by steps.georeference.scale={params.scale:g} (metres per model unit)"
    if params.eye_height_m > 0:
        return (f"its scale estimated from a nominal eye height (steps.georeference.eye_height_m="
                f"{params.eye_height_m:g})")
    return "unscaled (model units; steps.georeference.eye_height_m=0)"


# --------------------------------------------------------------------------- compute: the fits

def level_model(params, m: SfmModel, photos_dir: Path | None, log) -> tuple[np.ndarray, dict]:
    """:func:`georef.level` with the step's options: the rotation that makes the model's up +z, and its info.
    With ``vertical_lines`` (and no ``up_model``) the photos' vertical lines refine the horizon."""
    lv: dict[str, Any] = {"up_model": list(params.up_model) or None, "min_ground_support": params.min_ground_support,
                          "ground_agree_deg": params.ground_agree_deg}
    if params.vertical_lines and photos_dir is not None and Path(photos_dir).is_dir() and not params.up_model:
        from .georef import camera_horizon, vertical_from_lines

        t_v = time.perf_counter()
        v = vertical_from_lines(Path(photos_dir), [m.rows[n] for n in m.names], camera_horizon(m.Rwc)[0])
        v[1]["seconds"] = round(time.perf_counter() - t_v, 3)
        lv = {**lv, "vertical": v}
    return level(m.C, m.Rwc, m.sparse["xyz"], log, **lv)


def fit_gcp(params, gcp_rows: list, gcp_json, log, info: dict) -> Transform:
    """Robust Umeyama of the triangulated GCPs onto their surveyed positions; residuals into info["gcp"]."""
    if len(gcp_rows) < 3:
        raise InputError(f"{gcp_json}: only {len(gcp_rows)} ground-control points are seen in "
                         f">= {params.min_gcp_views} registered photos with a known position; need 3")
    src = np.array([r[1] for r in gcp_rows])
    dst = np.array([r[2] for r in gcp_rows])
    T, keep = robust_umeyama(src, dst, params.gcp_outlier_m)
    res = np.linalg.norm(T.apply(src) - dst, axis=1)
    left_out = [r[0] for r, k in zip(gcp_rows, keep) if not k]
    if left_out:
        log.warning("georeference: %d of %d ground-control points left out of the fit (residual over "
                    "%.3f m and 3x the median): %s; check their positions and clicks",
                    len(left_out), len(gcp_rows), params.gcp_outlier_m, ", ".join(left_out))
    info["gcp"] = {"used": int(keep.sum()), "left_out": left_out,
                   "residual_m": {r[0]: float(e) for r, e in zip(gcp_rows, res)},
                   "views": {r[0]: int(r[3]) for r in gcp_rows},
                   "rmse_m": float(np.sqrt(np.mean(res[keep] ** 2)))}
    return T


def fit_gps(params, m: SfmModel, frame, sfm_dir: Path, photos_dir, log, info: dict) -> tuple[Transform, dict]:
    """Level, then twinkit.geo's robust yaw-only similarity of the camera centres onto their EXIF GPS fixes
    (site frame). Returns the transform and {photo: its GPS fix in the site frame}."""
    from twinkit.geo import fit_similarity

    if frame is None:
        gps_ok = m.with_gps()
        raise InputError("steps.georeference.method=gps needs the site's crs and base_point (conf/site/<site>.yaml)"
                         + (f"; {suggest_site(m.doc, gps_ok)}" if gps_ok else ""))
    R_lvl, info["level"] = level_model(params, m, photos_dir, log)
    gps_names = m.with_gps()
    if len(gps_names) < 3:
        raise InputError(f"{sfm_dir}: only {len(gps_names)} registered photos carry EXIF GPS; need 3 for "
                         f"steps.georeference.method=gps (give a GCP file with site.inputs.gcp, or "
                         f"steps.georeference.method=none)")
    ll = np.array([m.doc["exif_gps"][n] for n in gps_names], dtype=float)
    xy = frame.lonlat_to_local(ll[:, [1, 0]])
    z = np.where(np.isfinite(ll[:, 2]), ll[:, 2] - frame.alt, 0.0)
    dst = np.c_[xy, z]
    far = float(np.linalg.norm(np.median(dst[:, :2], 0)))
    if far > 20000.0:
        raise InputError(f"{sfm_dir.parent.name}: the photos' EXIF GPS lies {far / 1000:.0f} km from the site's "
                         f"base point; set site.base_point (and site.crs) to the place the photos show")
    src = (m.C[[m.names.index(n) for n in gps_names]]) @ R_lvl.T
    sim = fit_similarity(src, dst, threshold_m=params.gps_threshold_m, use_z=params.gps_use_z)
    c, s = np.cos(sim.yaw_rad), np.sin(sim.yaw_rad)
    Rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    T = Transform(sim.scale, Rz @ R_lvl, np.asarray(sim.t, float))
    res_gps = np.linalg.norm(sim.apply(src)[:, :2] - dst[:, :2], axis=1)
    info["gps"] = {**sim.to_json(), "photos_with_gps": len(gps_names),
                   "residual_m": {n: round(float(e), 3) for n, e in zip(gps_names, res_gps)}}
    return T, {n: dst[k].tolist() for k, n in enumerate(gps_names)}


def fit_none(params, m: SfmModel, known: float | None, photos_dir, log, info: dict) -> Transform:
    """Level and centre on the mean camera; the scale from the known distance, else ``params.scale``, else
    estimated from the nominal eye height (:func:`eye_height_scale`), else none (model units)."""
    R_lvl, info["level"] = level_model(params, m, photos_dir, log)
    scale = float(params.scale)
    if known is not None:
        scale = params.distance_m / known
        info["scale_from"] = "known distance"
    elif params.scale != 1.0:
        info["scale_from"] = "steps.georeference.scale"
    elif params.eye_height_m > 0:
        est = eye_height_scale(m.C @ R_lvl.T, np.asarray(m.sparse["xyz"], float).reshape(-1, 3) @ R_lvl.T,
                               params.eye_height_m)
        info["eye_height"] = est
        if est.get("scale"):
            scale = est["scale"]
            info["scale_from"] = "eye height"
        else:
            log.warning("georeference: the scale cannot be estimated from the eye height: %s", est["why_not"])
    return Transform(scale, R_lvl, -scale * R_lvl @ m.C.mean(0))


#: how far a scale from the nominal eye height may be off: people hold a camera 1.3-1.9 m high, and the ground
#: under them is a plane fitted to sparse points (docs/photo.md, "A nominal eye height")
EYE_HEIGHT_UNCERTAINTY = 0.2
#: the ground the photographer stands on is near level (a street's slope and camber stay under 10 degrees)
EYE_HEIGHT_MAX_TILT_DEG = 10.0


def eye_height_note(eye_height_m: float) -> str:
    """How an estimated scale is marked everywhere (log, georef.json, cameras_site.json, roi.json, report)."""
    return (f"scale estimated from a nominal eye height of {eye_height_m:g} m: "
            f"±{100 * EYE_HEIGHT_UNCERTAINTY:.0f} %")


def eye_height_scale(C: np.ndarray, pts: np.ndarray, eye_height_m: float) -> dict:
    """The scale (metres per model unit) that puts the cameras ``eye_height_m`` over the ground. ``C`` (n, 3)
    and ``pts`` (N, 3) in the levelled model frame (z up). The ground is the roi step's plane
    (:func:`~twinkit_photo.roi.ground_plane`, its default 10 cm inlier distance), fitted in a frame brought near metres by a
    first guess (the median point below the cameras), then refined twice; the cameras' median height over it
    gives the scale. A plane tilted over ``EYE_HEIGHT_MAX_TILT_DEG`` (a bank) gives none. Returns {"scale", "nominal_m", "camera_height_model", "camera_height_iqr_model",
    "ground_inliers", "ground_tilt_deg"}, or {"nominal_m", "why_not"} when no ground is found."""
    from .roi import ground_plane

    out: dict[str, Any] = {"nominal_m": float(eye_height_m)}
    below = pts[pts[:, 2] < np.median(C[:, 2])] if len(pts) else pts
    guess = float(np.median(C[:, 2]) - np.median(below[:, 2])) if len(below) >= 50 else 0.0
    if guess <= 0:
        return {**out, "why_not": f"{len(below)} sparse points below the cameras (50 needed)"}
    s = eye_height_m / guess
    for _ in range(3):
        g = ground_plane(C * s, pts * s, 0.10)
        if not g["source"].startswith("RANSAC"):
            return {**out, "why_not": "no ground plane under the cameras"}
        if g["tilt_deg"] > EYE_HEIGHT_MAX_TILT_DEG:  # a bank or a ramp, not the ground people stand on
            return {**out, "why_not": f"the plane under the cameras is tilted {g['tilt_deg']:.0f} degrees (over "
                                      f"{EYE_HEIGHT_MAX_TILT_DEG:g}: not the ground they stand on)"}
        n = np.asarray(g["normal"], float)
        p0 = np.r_[(C[:, :2] * s).mean(0), g["z_m"]]
        h = (C * s - p0) @ n
        if np.median(h) <= 0:
            return {**out, "why_not": "the ground plane found is not under the cameras"}
        h_model = h / s
        s *= eye_height_m / float(np.median(h))
    q1, q3 = np.quantile(h_model, [0.25, 0.75])
    return {**out, "scale": float(s), "camera_height_model": float(eye_height_m / s),
            "camera_height_iqr_model": [float(q1), float(q3)], "ground_inliers": g.get("inliers"),
            "ground_tilt_deg": g.get("tilt_deg"), "uncertainty": EYE_HEIGHT_UNCERTAINTY}


def user_transform(m16) -> Transform:
    """steps.georeference.transform_model_to_site (16 numbers, a 4x4 similarity row by row) as a Transform."""
    M = np.asarray(m16, float).reshape(4, 4)
    A = M[:3, :3]
    det = float(np.linalg.det(A))
    if not np.allclose(M[3], [0, 0, 0, 1], atol=1e-9) or det <= 0:
        raise InputError("steps.georeference.transform_model_to_site: not a similarity (last row must be 0 0 0 1 and the "
                         "3x3 part a rotation times a positive scale)")
    s = det ** (1.0 / 3.0)
    R = A / s
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-3):
        raise InputError("steps.georeference.transform_model_to_site: the 3x3 part is not a rotation times one scale "
                         "(shear or unequal scales); give a similarity")
    U, _, Vt = np.linalg.svd(R)
    return Transform(s, U @ Vt, M[:3, 3].copy())


def fit(method: str, params, m: SfmModel, *, gcp_rows: list, gcp_json, known: float | None, frame, sfm_dir: Path,
        photos_dir, log, info: dict) -> tuple[Transform, dict]:
    """The model -> site transform by ``method``; (transform, {photo: GPS fix in the site frame})."""
    if method == "gcp":
        return fit_gcp(params, gcp_rows, gcp_json, log, info), {}
    if method == "gps":
        return fit_gps(params, m, frame, sfm_dir, photos_dir, log, info)
    if method == "none":
        return fit_none(params, m, known, photos_dir, log, info), {}
    if method == "transform":
        T = user_transform(params.transform_model_to_site)
        info["level"] = {"up_from": "user transform"}
        return T, {}
    raise InputError(f"georeference: unknown method '{params.method}' (auto, gcp, gps or none)")


# --------------------------------------------------------------------------- after the fit

def describe_scale(method: str, params, T: Transform, known: float | None, log, info: dict,
                   degraded=None) -> bool:
    """Whether the site frame is in metres; that, the known distance's check and the levelling's angle to
    the photos' horizon go into ``info``. An unscaled frame is logged as a warning; a scale estimated from
    the eye height is marked in ``info["units"]`` and makes the run degraded (``degraded(reason, hint)``)."""
    scaled = method in ("gcp", "gps", "transform") or "scale_from" in info
    info["scaled"] = scaled
    info["units"] = "metres" if scaled else "model units (unscaled: no GPS, GCPs, known distance or scale)"
    if info.get("scale_from") == "eye height":
        note = eye_height_note(params.eye_height_m)
        info["units"] = f"metres ({note})"
        fix = ("give steps.georeference.distance_points_model=[x1,y1,z1,x2,y2,z2] with "
               "steps.georeference.distance_m=<metres>, or steps.georeference.scale=<metres per model unit>, or "
               "site.crs and site.base_point for the photos' GPS")
        why = (f"no GPS, GCPs, known distance or scale: {note} (the cameras stand "
               f"{info['eye_height']['camera_height_model']:.3g} model units over the sparse ground, "
               f"{T.scale:.3g} m per model unit); a guess, not a georeference")
        if degraded is not None:
            degraded(why, fix)
        else:
            log.warning("georeference: %s; %s", why, fix)
    if known is not None:
        got = float(T.scale * known)
        info["known_distance"] = {"given_m": params.distance_m, "in_site_frame_m": round(got, 4),
                                  "error_m": round(got - params.distance_m, 4)}
    if "level" in info and "final_vs_camera_horizon" in info["level"]:
        info["level_vs_camera_horizon_deg"] = info["level"]["final_vs_camera_horizon"]["total_deg"]
    if not scaled:
        why_not = (info.get("eye_height") or {}).get("why_not")
        log.warning("georeference: the site frame is in model units, not metres (no GPS with a site CRS, no "
                    "GCPs, no known distance%s): later steps' thresholds in metres do not mean metres; give "
                    "steps.georeference.distance_points_model + steps.georeference.distance_m, or "
                    "steps.georeference.scale", f", no eye-height estimate: {why_not}" if why_not else "")
    return scaled


def ground_height(params, T: Transform, xyz_model: np.ndarray, info: dict) -> tuple[Transform, np.ndarray]:
    """With ``height_from=ground``: shift the transform so the sparse ground plane lies at ``ground_z_m``.
    Returns the transform and the sparse points (N, 3) in the site frame."""
    xyz = T.apply(xyz_model) if len(xyz_model) else np.zeros((0, 3))
    if params.height_from == "ground" and len(xyz) >= 50:
        from .georef import ransac_plane

        plane, inl = ransac_plane(xyz, 0.1, normal_hint=np.array([0, 0, 1.0]), max_angle_deg=20)
        if plane is not None:
            gz = float(np.median(xyz[inl, 2]))
            T = Transform(T.scale, T.R, T.t + np.array([0, 0, params.ground_z_m - gz]))
            xyz = T.apply(xyz_model)
            info["height_shift_m"] = params.ground_z_m - gz
    return T, xyz


def outlier_cameras(names: list[str], centres, gps_residual: dict, params, metric: bool = True) -> dict[str, str]:
    """Cameras not to trust: a GPS fix far beyond the RANSAC threshold from where the fit puts the camera, or
    a camera standing off the walk (a misregistered photo). {name: why}."""
    out: dict[str, str] = {}
    if params.outlier_factor <= 0:
        return out
    for n, e in gps_residual.items():
        if e > params.outlier_factor * params.gps_threshold_m:
            out[n] = f"{e:.1f} m from its own GPS fix (RANSAC threshold {params.gps_threshold_m:g} m)"
    P = np.asarray(centres, float)
    if len(P) >= 5:
        from scipy.spatial import cKDTree

        d, _ = cKDTree(P).query(P, k=2)
        nn = d[:, 1]
        spacing = float(np.median(nn))
        limit = max(5.0 if metric else 0.0, 10.0 * spacing)
        for n, e in zip(names, nn):
            if e > limit and n not in out:
                unit = "m" if metric else "model units"
                out[n] = f"{e:.1f} {unit} from the nearest other camera (median spacing {spacing:.1f}): off the walk"
    return out


def flag_outliers(method: str, params, m: SfmModel, T: Transform, log, degraded, info: dict) -> dict[str, str]:
    """:func:`outlier_cameras` for the fitted model, logged (the run degraded past a fifth of the photos);
    info gets "outlier_cameras" and, per photo, where the model puts the camera and its GPS fix."""
    outliers = outlier_cameras(m.names, T.apply(m.C), info.get("gps", {}).get("residual_m", {}), params,
                               metric=bool(info.get("scaled", method != "none")))
    if outliers:
        log.warning("georeference: %d outlier camera(s) left out of the later steps: %s", len(outliers),
                    "; ".join(f"{n} ({why})" for n, why in outliers.items()))
        if len(outliers) > 0.2 * len(m.names):
            degraded(f"{len(outliers)} of {len(m.names)} registered photos are outlier cameras "
                     f"({', '.join(list(outliers)[:6])})", "check the photos and their GPS; see georef.json")
    info["outlier_cameras"] = outliers
    return outliers


def photos_table(m: SfmModel, T: Transform, gps_site: dict, outliers: dict, info: dict) -> dict:
    """Per photo, for the report's map and residual table: camera and GPS fix in the site frame, residual."""
    C_site = T.apply(m.C)
    res_map = info.get("gps", {}).get("residual_m", {})
    return {n: {"camera_m": [round(float(v), 3) for v in C_site[k]],
                "gps_m": ([round(float(v), 3) for v in gps_site[n]] if n in gps_site else None),
                "gps_residual_m": res_map.get(n), "outlier": outliers.get(n)}
            for k, n in enumerate(m.names)}


def site_cameras(m: SfmModel, T: Transform, outliers: dict) -> list[dict]:
    """The cameras_site.json rows: the registered cameras but the outliers, moved into the site frame."""
    cams_out = []
    for n in m.names:
        if n in outliers:
            continue
        r = m.rows[n]
        cams_out.append({**{k: r[k] for k in ("image", "model", "width", "height", "params", "K")},
                         "R_world_from_camera": (T.R @ np.asarray(r["R_world_from_camera"])).tolist(),
                         "center": T.apply(r["center"])[0].tolist()})
    return cams_out


def truth_check(m: SfmModel, cams_out: list[dict], truth: dict, method: str, log) -> dict:
    """With the site's true cameras (cameras.json): the camera centres' error in the site frame, and after the
    best similarity onto the truth (the SfM shape alone: what GCPs could reach at best). {} under 3 common."""
    centres = np.array([c["center"] for c in cams_out])
    tmap = {c["image"]: np.asarray(c.get("center", c.get("t_world_from_camera")), float)
            for c in truth.get("cameras", [])}
    common = [k for k, n in enumerate(m.names) if n in tmap]
    if len(common) < 3:
        return {}
    est = centres[common]
    tru = np.array([tmap[m.names[k]] for k in common])
    e = np.linalg.norm(est - tru, axis=1)
    Tb = closed_form_similarity(est, tru)
    eb = np.linalg.norm(Tb.apply(est) - tru, axis=1)
    log.info("georeference (%s): camera centres %.3f m from the truth on average (max %.3f); "
             "SfM shape alone %.3f m", method, e.mean(), e.max(), eb.mean())
    return {"camera_centre_error_m": {"mean": float(e.mean()), "median": float(np.median(e)),
                                      "max": float(e.max()), "n": len(common),
                                      "within_5cm": float((e <= 0.05).mean())},
            "camera_centre_error_after_best_similarity_m": {"mean": float(eb.mean()), "max": float(eb.max())}}


def cameras_site_doc(method: str, scaled: bool, cams_out: list[dict], info: dict | None = None) -> dict:
    """cameras_site.json: the site-frame cameras, their frame, units (marked where the scale is estimated,
    ``info["scale_from"]``) and camera convention."""
    units = "metres" if scaled else "model units"
    if (info or {}).get("scale_from") == "eye height":
        units = info["units"]  # type: ignore[index]
    return {
        "frame": ("site local (metres, x east, y north, z up)" if method in ("gcp", "gps", "transform") else
                  "levelled model frame (z up, " + ((units + ")") if scaled else "model units: unscaled)")),
        "scaled": scaled, "units": units, "scale_from": (info or {}).get("scale_from"),
        "convention": "OpenCV pinhole: X_world = R_world_from_camera @ X_cam + center; K at full photo size",
        "cameras": cams_out}


def step_summary(report: dict, T: Transform, n_outliers: int) -> dict:
    """What the georeference step returns (the run's summary): method, scale, outliers, levelling, truth."""
    out = {"method": report["method"], "scale": float(T.scale), "outlier_cameras": n_outliers,
           "scaled": report["scaled"], "scale_from": report.get("scale_from")}
    if "level_vs_camera_horizon_deg" in report:
        out["level_vs_camera_horizon_deg"] = report["level_vs_camera_horizon_deg"]
        out["up_from"] = report["level"]["up_from"]
    if "camera_centre_error_m" in report:
        out["camera_centre_error_mean_m"] = report["camera_centre_error_m"]["mean"]
        out["camera_centre_error_shape_m"] = report["camera_centre_error_after_best_similarity_m"]["mean"]
    return out

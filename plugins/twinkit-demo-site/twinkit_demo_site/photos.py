"""Photos for the photo branch: pinhole renders along a walked path, JPEG + EXIF (focal, GPS)."""
from __future__ import annotations

import io
import math
from fractions import Fraction
from pathlib import Path

import numpy as np

from twinkit_demo_site.raycast import Tracer, look_rotation

SENSOR_WIDTH_MM = 6.4


def walk_poses(path: np.ndarray, count: int, rng: np.random.Generator) -> list[dict]:
    """``count`` camera poses spread evenly along the polyline ``path`` (k, 2).

    Heights 1.45-1.95 m. The heading sweeps smoothly from 40 degrees left of the walking direction to
    40 degrees right and back (a period of eight photos, plus 3 degrees of jitter), as a photographer
    capturing a street for photogrammetry would, so that each photo overlaps its neighbours; pitch
    -10..+4 degrees.
    """
    seg = np.diff(path, axis=0)
    lens = np.linalg.norm(seg, axis=1)
    cum = np.concatenate([[0], np.cumsum(lens)])
    total = cum[-1]
    poses = []
    for i in range(count):
        d = (i + 0.5) * total / count
        k = int(np.clip(np.searchsorted(cum, d, side="right") - 1, 0, len(seg) - 1))
        xy = path[k] + seg[k] * (d - cum[k]) / lens[k]
        xy = xy + rng.normal(0, 0.15, 2)
        sweep = math.radians(40.0) * math.sin(2 * math.pi * i / 8.0)
        heading = math.atan2(seg[k, 1], seg[k, 0]) + sweep + rng.normal(0, math.radians(3))
        pitch = math.radians(rng.uniform(-10.0, 4.0))
        h = rng.uniform(1.45, 1.95)
        poses.append({"xy": xy, "height": h, "yaw": heading, "pitch": pitch})
    return poses


def _rat(x: float, den: int = 10000):
    f = Fraction(x).limit_denominator(den)
    return (f.numerator, f.denominator)


def _dms(deg: float):
    deg = abs(deg)
    d = int(deg)
    m = int((deg - d) * 60)
    s = (deg - d - m / 60) * 3600
    return ((d, 1), (m, 1), (int(round(s * 10000)), 10000))


def exif_bytes(focal_px: float, width: int, height: int, lat: float, lon: float, alt: float, index: int,
               heading_deg: float) -> bytes:
    import piexif

    f_mm = focal_px * SENSOR_WIDTH_MM / width
    stamp = f"2024:06:01 12:{index // 60:02d}:{index % 60:02d}"
    zeroth = {
        piexif.ImageIFD.Make: b"twinkit",
        piexif.ImageIFD.Model: b"demo-site pinhole camera",
        piexif.ImageIFD.Software: b"twinkit-demo-site",
        piexif.ImageIFD.DateTime: stamp.encode(),
        piexif.ImageIFD.Orientation: 1,
    }
    exif = {
        piexif.ExifIFD.DateTimeOriginal: stamp.encode(),
        piexif.ExifIFD.FocalLength: _rat(f_mm),
        piexif.ExifIFD.FocalLengthIn35mmFilm: int(round(focal_px * 36.0 / width)),
        piexif.ExifIFD.PixelXDimension: width,
        piexif.ExifIFD.PixelYDimension: height,
        piexif.ExifIFD.FocalPlaneXResolution: _rat(width / SENSOR_WIDTH_MM),
        piexif.ExifIFD.FocalPlaneYResolution: _rat(width / SENSOR_WIDTH_MM),
        piexif.ExifIFD.FocalPlaneResolutionUnit: 4,  # mm
    }
    gps = {
        piexif.GPSIFD.GPSVersionID: (2, 3, 0, 0),
        piexif.GPSIFD.GPSLatitudeRef: b"N" if lat >= 0 else b"S",
        piexif.GPSIFD.GPSLatitude: _dms(lat),
        piexif.GPSIFD.GPSLongitudeRef: b"E" if lon >= 0 else b"W",
        piexif.GPSIFD.GPSLongitude: _dms(lon),
        piexif.GPSIFD.GPSAltitudeRef: 0 if alt >= 0 else 1,
        piexif.GPSIFD.GPSAltitude: _rat(abs(alt), 1000),
        piexif.GPSIFD.GPSImgDirectionRef: b"T",
        piexif.GPSIFD.GPSImgDirection: _rat(heading_deg % 360.0, 100),
        piexif.GPSIFD.GPSMapDatum: b"WGS-84",
    }
    return piexif.dump({"0th": zeroth, "Exif": exif, "GPS": gps, "1st": {}, "thumbnail": None})


def render_photos(tracer: Tracer, poses: list[dict], out_dir: Path, geo, rng: np.random.Generator, *,
                  width: int, height: int, focal_px: float, gps_noise_m: float, supersample: int = 1,
                  shadows: bool = True, progress=None, threads: int = 1) -> dict:
    """Render, write ``photo_XXXX.jpg`` (+ ``labels/photo_XXXX.png`` trainIds, 255 = sky); return cameras.json content.

    ``threads`` > 1 renders that many photos at once (the tracer's shading is numpy, its ray casts release the
    GIL: 1.6x on 2 cores); they are written, and the GPS noise drawn, in order, so the files are the same."""
    from concurrent.futures import ThreadPoolExecutor

    out_dir = Path(out_dir)
    (out_dir / "labels").mkdir(parents=True, exist_ok=True)
    K = np.array([[focal_px, 0, width / 2], [0, focal_px, height / 2], [0, 0, 1.0]])
    cams = []

    def render(p):
        c = np.array([p["xy"][0], p["xy"][1], p["height"]])
        R = look_rotation(p["yaw"], p["pitch"])
        return c, R, tracer.render(K, R, c, width, height, supersample=supersample, shadows=shadows)

    ahead = max(1, int(threads))
    pool = ThreadPoolExecutor(ahead, thread_name_prefix="photo")
    try:
        pending = [pool.submit(render, p) for p in poses[:ahead + 1]]  # the photos being rendered, in order
        it = progress(list(enumerate(poses)), total=len(poses), desc="photos") if progress else enumerate(poses)
        for i, p in it:
            c, R, (rgb, lab, _) = pending.pop(0).result()
            if i + ahead + 1 < len(poses):
                pending.append(pool.submit(render, poses[i + ahead + 1]))
            cams.append(_write_photo(i, c, R, rgb, lab, p, out_dir, geo, rng, focal_px, width, height, gps_noise_m))
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    return _cameras_doc(cams, width, height, focal_px, K, gps_noise_m)


def _write_photo(i: int, c, R, rgb, lab, p: dict, out_dir: Path, geo, rng, focal_px: float, width: int, height: int,
                 gps_noise_m: float) -> dict:
    """One rendered photo's files (JPEG with EXIF GPS drawn from ``rng``, label PNG) and its cameras.json entry."""
    from PIL import Image

    from twinkit.artefacts import write_photo

    noise = rng.normal(0, gps_noise_m, 3) * np.array([1.0, 1.0, 1.6])
    gps_local = c + noise
    lon, lat = geo.local_to_lonlat(gps_local[None, :2])[0]
    alt = geo.alt + gps_local[2]
    heading_deg = (90.0 - math.degrees(p["yaw"])) % 360.0  # compass: clockwise from north
    name = f"photo_{i:04d}.jpg"
    buf = io.BytesIO()
    Image.fromarray(rgb).save(buf, format="JPEG", quality=92, subsampling=0,
                              exif=exif_bytes(focal_px, width, height, lat, lon, alt, i, heading_deg))
    write_photo(out_dir, name, buf.getvalue())
    Image.fromarray(lab).save(out_dir / "labels" / f"photo_{i:04d}.png")
    return {
        "image": name, "label_image": f"labels/photo_{i:04d}.png",
        "R_world_from_camera": R.round(9).tolist(), "center": c.round(6).tolist(),
        "t_world_from_camera": c.round(6).tolist(),
        "gps": {"lat": round(float(lat), 9), "lon": round(float(lon), 9), "alt": round(float(alt), 4),
                "local_xyz": gps_local.round(4).tolist()},
        "heading_deg": round(heading_deg, 4), "pitch_deg": round(math.degrees(p["pitch"]), 4),
    }


def _cameras_doc(cams: list, width: int, height: int, focal_px: float, K, gps_noise_m: float) -> dict:
    """cameras.json's content."""
    return {
        "convention": "OpenCV pinhole: camera x right, y down, z forward. Poses are world-from-camera: "
                      "X_world = R_world_from_camera @ X_cam + t_world_from_camera (t = camera centre); "
                      "world = site local frame (metres, x east, y north, z up, origin at the base point).",
        "intrinsics": {"width": width, "height": height, "fx": focal_px, "fy": focal_px, "cx": width / 2, "cy": height / 2,
                       "distortion": [0.0, 0.0, 0.0, 0.0, 0.0], "K": K.tolist(),
                       "sensor_width_mm": SENSOR_WIDTH_MM, "focal_mm": focal_px * SENSOR_WIDTH_MM / width},
        "gps_noise_sigma_m": {"horizontal": gps_noise_m, "vertical": gps_noise_m * 1.6},
        "label_images": "PNG, uint8 CityScapes trainId per pixel, 255 = sky/nothing; image paths are relative to the photos folder",
        "cameras": cams,
    }


def gcp_observations(tracer: Tracer, cameras: dict, points: list[dict], rng: np.random.Generator, *,
                     survey_noise_m: float = 0.005, pixel_noise_px: float = 0.5, margin_px: float = 8.0) -> dict:
    """Ground-control points as a surveyor and a user would deliver them, in twinkit's GCP format.

    ``site_xyz`` is the surveyed position (the true point plus ``survey_noise_m`` of noise, as RTK GNSS or
    a total station gives); each observation is the pixel where the point appears in a photo that sees
    it (projection with the photo's true pose, unoccluded by a ray cast, ``pixel_noise_px`` of clicking
    noise). Pixels are continuous image coordinates: (0, 0) is the top-left corner of the top-left pixel,
    so the centre of pixel (i, j) is (i + 0.5, j + 0.5), as in COLMAP.
    """
    intr = cameras["intrinsics"]
    K = np.asarray(intr["K"], float)
    w, h = intr["width"], intr["height"]
    out = []
    for g in points:
        X = np.asarray(g["xyz"], float)
        obs = []
        for cam in cameras["cameras"]:
            R = np.asarray(cam["R_world_from_camera"], float)
            c = np.asarray(cam["center"], float)
            xc = R.T @ (X - c)
            if xc[2] < 0.5:
                continue
            uv = (K @ xc)[:2] / xc[2]
            if not (margin_px <= uv[0] <= w - margin_px and margin_px <= uv[1] <= h - margin_px):
                continue
            d = X - c
            dist = float(np.linalg.norm(d))
            t, _, _ = tracer.cast(c[None].astype(np.float32), (d / dist)[None].astype(np.float32))
            if not np.isfinite(t[0]) or t[0] < dist - 0.02:
                continue  # something stands in front of it
            px = uv + rng.normal(0, pixel_noise_px, 2)
            obs.append({"image": cam["image"], "pixel": [round(float(px[0]), 3), round(float(px[1]), 3)]})
        surveyed = X + rng.normal(0, survey_noise_m, 3)
        out.append({"id": g["id"], "what": g.get("what", ""), "site_xyz": surveyed.round(4).tolist(),
                    "observations": obs})
    return {
        "format": "twinkit ground-control points (docs/photo.md): site_xyz in the site frame (metres); "
                  "pixel = continuous image coordinates, pixel (i, j) spans [i, i + 1) x [j, j + 1)",
        "survey_noise_sigma_m": survey_noise_m, "pixel_noise_sigma_px": pixel_noise_px,
        "points": out,
    }

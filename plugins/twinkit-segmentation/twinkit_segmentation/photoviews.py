"""The capture's own photos as segmentation views (issue 22, item 5).

A rendered view of the reconstruction is blurry, has holes and blotchy colours: a 2D model trained on
real street photos sees a different domain. Where the capture has photos with known poses (the photo
branch's ``cameras_site.json``), each photo can be a view itself: the 2D model segments the real photo,
and the per-pixel vertex map comes from rendering the mesh from the photo's pose and intrinsics, so
occlusion is the mesh's, exactly as for a rendered view.

Cameras follow ``cameras_site.json`` (written by twinkit-photo's georeference step; read here as a file,
the plugins never import each other): OpenCV convention ``X_world = R_world_from_camera @ X_cam + center``,
``K`` at the full photo size, and the COLMAP camera ``model`` with its ``params``. Distorted photos are
resampled onto the pinhole camera ``K`` (COLMAP's distortion models below), so that the rendered vertex
map (a pinhole projection) lines up with the image pixel for pixel.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# COLMAP camera models: parameter names in order. Fisheye models are not supported (a clear error).
CAMERA_MODELS = {
    "SIMPLE_PINHOLE": ("f", "cx", "cy"),
    "PINHOLE": ("fx", "fy", "cx", "cy"),
    "SIMPLE_RADIAL": ("f", "cx", "cy", "k1"),
    "RADIAL": ("f", "cx", "cy", "k1", "k2"),
    "OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"),
    "FULL_OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
}


def camera_parameters(model: str, params) -> dict:
    """Named parameters of a COLMAP camera (``fx``, ``fy``, ``cx``, ``cy`` and the distortion terms, 0 where
    the model has none). Raises ``ValueError`` for an unknown model or a wrong parameter count."""
    names = CAMERA_MODELS.get(str(model).upper())
    if names is None:
        raise ValueError(f"camera model {model!r} is not supported (use one of {', '.join(CAMERA_MODELS)})")
    params = [float(p) for p in params]
    if len(params) != len(names):
        raise ValueError(f"camera model {model} takes {len(names)} parameters ({', '.join(names)}), got {len(params)}")
    p = dict(zip(names, params))
    if "f" in p:
        p["fx"] = p["fy"] = p.pop("f")
    for k in ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"):
        p.setdefault(k, 0.0)
    return p


def has_distortion(p: dict) -> bool:
    return any(abs(p[k]) > 0 for k in ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"))


def max_distortion_px(p: dict, width: int, height: int, scale: float = 1.0) -> float:
    """The largest shift (pixels, at ``scale`` of the full size) the distortion makes along the image border,
    where it is largest for the radial and tangential models."""
    n = 64
    t = np.linspace(0.0, 1.0, n)
    u = np.concatenate([t * width, t * width, np.zeros(n), np.full(n, float(width))])
    v = np.concatenate([np.zeros(n), np.full(n, float(height)), t * height, t * height])
    x, y = (u - p["cx"]) / p["fx"], (v - p["cy"]) / p["fy"]
    xd, yd = distort(p, x, y)
    return float(np.hypot((xd - x) * p["fx"], (yd - y) * p["fy"]).max() * scale)


def distort(p: dict, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """COLMAP's forward distortion of normalised pinhole coordinates (x, y) = (X/Z, Y/Z)."""
    r2 = x * x + y * y
    radial = (1 + p["k1"] * r2 + p["k2"] * r2 ** 2 + p["k3"] * r2 ** 3) / (1 + p["k4"] * r2 + p["k5"] * r2 ** 2
                                                                          + p["k6"] * r2 ** 3)
    xy = x * y
    xd = x * radial + 2 * p["p1"] * xy + p["p2"] * (r2 + 2 * x * x)
    yd = y * radial + 2 * p["p2"] * xy + p["p1"] * (r2 + 2 * y * y)
    return xd, yd


def undistort_image(image: np.ndarray, p: dict, K_out: np.ndarray, width: int, height: int,
                    scale=(1.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """(image (height, width, 3), valid (height, width) bool): the pinhole image with intrinsics ``K_out`` of a
    photo taken with camera ``p``.

    ``image`` may be the photo already downscaled by ``scale`` = (sx, sy) (its distortion scales with it):
    each output pixel centre is un-projected through ``K_out``, distorted by the model and sampled
    bilinearly; pixels whose source falls outside the photo are black and not ``valid``."""
    from scipy.ndimage import map_coordinates

    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    x = (xs + 0.5 - K_out[0, 2]) / K_out[0, 0]
    y = (ys + 0.5 - K_out[1, 2]) / K_out[1, 1]
    xd, yd = distort(p, x, y)
    u = (p["fx"] * xd + p["cx"]) * scale[0] - 0.5  # continuous pixel -> array index of the (scaled) photo
    v = (p["fy"] * yd + p["cy"]) * scale[1] - 0.5
    valid = (u >= -0.5) & (u <= image.shape[1] - 0.5) & (v >= -0.5) & (v <= image.shape[0] - 0.5)
    out = np.empty((height, width, image.shape[2]), np.uint8)
    for c in range(image.shape[2]):
        out[..., c] = np.clip(map_coordinates(image[..., c].astype(np.float32), [v, u], order=1, mode="constant",
                                              cval=0.0), 0, 255).round().astype(np.uint8)
    out[~valid] = 0
    return out, valid


@dataclass
class PhotoCamera:
    """One registered photo: pose in the site frame (OpenCV camera) and its camera at full size."""

    image: str
    width: int
    height: int
    K: np.ndarray  # 3x3 pinhole at (width, height)
    R_wc: np.ndarray  # world-from-camera rotation
    center: np.ndarray
    params: dict  # camera_parameters()

    @classmethod
    def from_json(cls, c: dict) -> "PhotoCamera":
        w, h = int(c["width"]), int(c["height"])
        if "model" in c and "params" in c:
            p = camera_parameters(c["model"], c["params"])
        else:  # a plain pinhole record (K only)
            K0 = np.asarray(c["K"], float)
            p = camera_parameters("PINHOLE", [K0[0, 0], K0[1, 1], K0[0, 2], K0[1, 2]])
        K = np.array([[p["fx"], 0.0, p["cx"]], [0.0, p["fy"], p["cy"]], [0.0, 0.0, 1.0]])
        return cls(str(c["image"]), w, h, K, np.asarray(c["R_world_from_camera"], float),
                   np.asarray(c["center"], float), p)

    def output_size(self, long_side_px: int) -> tuple[int, int, float]:
        """(width, height, scale) of the view: long side ``long_side_px`` (never enlarged; 0 = full size)."""
        s = 1.0 if not long_side_px else min(1.0, long_side_px / max(self.width, self.height))
        return max(1, int(round(self.width * s))), max(1, int(round(self.height * s))), s

    def scaled_K(self, width: int, height: int) -> np.ndarray:
        return np.diag([width / self.width, height / self.height, 1.0]) @ self.K


def view_matrix_opencv(R_wc: np.ndarray, center: np.ndarray) -> np.ndarray:
    """World -> OpenGL camera (x right, y up, looking down -z) for an OpenCV pose (x right, y down, z forward)."""
    R_cw = np.asarray(R_wc, float).T
    m = np.eye(4)
    m[:3, :3] = np.diag([1.0, -1.0, -1.0]) @ R_cw
    m[:3, 3] = -m[:3, :3] @ np.asarray(center, float)
    return m


def projection_from_K(K: np.ndarray, width: int, height: int, near: float = 0.05, far: float = 1000.0) -> np.ndarray:
    """OpenGL projection of a pinhole ``K`` (pixel (i, j) spans [i, i+1), row 0 at the top of the image)."""
    m = np.zeros((4, 4))
    m[0, 0] = 2 * K[0, 0] / width
    m[0, 1] = -2 * K[0, 1] / width
    m[0, 2] = 1 - 2 * K[0, 2] / width
    m[1, 1] = 2 * K[1, 1] / height
    m[1, 2] = 2 * K[1, 2] / height - 1
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def photo_view_image(path, cam: PhotoCamera, long_side_px: int, min_shift_px: float = 0.25):
    """(image (h, w, 3) uint8 undistorted and downscaled, its pinhole K, valid (h, w) bool or None where every
    pixel is, whether it was undistorted: only when the distortion shifts some pixel by ``min_shift_px`` or
    more at the view's size). A photo stored at another size than its camera (same aspect
    ratio) is scaled like it. Raises ``ValueError`` when the aspect ratio differs."""
    from PIL import Image

    w, h, _ = cam.output_size(long_side_px)
    with Image.open(path) as im:
        im = im.convert("RGB")
        if abs(im.size[0] / im.size[1] - cam.width / cam.height) > 0.01 * cam.width / cam.height:
            raise ValueError(f"is {im.size[0]}x{im.size[1]} px but its camera is {cam.width}x{cam.height} "
                             f"(another aspect ratio)")
        small = im.resize((w, h), Image.LANCZOS) if (w, h) != im.size else im
        img = np.asarray(small)
    K = cam.scaled_K(w, h)
    # a shift under a quarter pixel of the view is below what the nearest-vertex map resolves; resampling
    # would only blur the photo (SfM refines a small k1 even for an undistorted camera)
    if max_distortion_px(cam.params, cam.width, cam.height, w / cam.width) < min_shift_px:
        return np.ascontiguousarray(img), K, None, False
    und, valid = undistort_image(img, cam.params, K, w, h, scale=(w / cam.width, h / cam.height))
    return und, K, valid, True


def photo_view_id(image: str, used: set) -> str:
    """A file-name-safe, unique view id for a photo ("photo_<stem>"); adds it to ``used``."""
    import re
    from pathlib import Path

    base = "photo_" + re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(image).with_suffix("").as_posix())
    vid, k = base, 1
    while vid in used:
        vid, k = f"{base}_{k}", k + 1
    used.add(vid)
    return vid


def photo_view_set(mesh, cams: list, photos_dir, cameras_json, long_side_px: int, min_coverage: float, out_dir,
                   progress) -> tuple[list, list, dict]:
    """Each registered photo as a view in ``out_dir``: ``<id>.png`` (undistorted, long side ``long_side_px``)
    and ``<id>_vertex.npz`` (the mesh's vertex index per pixel (h, w) int, -1 none, rendered from the
    photo's pose). ``cams``: ``cameras_site.json`` records. A photo whose pose sees the mesh in fewer than
    ``min_coverage`` of its pixels is dropped. Returns (kept view records, dropped records, {undistorted:
    count, max_distortion_px, load_seconds, render_seconds}); InputError on an unreadable photo or camera."""
    import time
    from pathlib import Path

    from PIL import Image

    from twinkit import InputError

    from .render import Renderer, write_vertex_map

    kept: list = []
    dropped: list = []
    renderers: dict = {}
    t_load = t_render = 0.0
    n_undistorted = 0
    shift = 0.0
    used_ids: set = set()
    try:
        for c in progress(cams, total=len(cams), desc="photo views"):
            try:
                cam = PhotoCamera.from_json(c)
            except (KeyError, ValueError) as exc:
                raise InputError(f"{cameras_json}: camera of {c.get('image', '?')}: {exc}") from None
            path = Path(photos_dir) / cam.image
            t1 = time.perf_counter()
            try:
                img, K, valid, undist = photo_view_image(path, cam, long_side_px)
            except OSError as exc:
                raise InputError(f"{path}: cannot read the photo ({exc}); put the photos georeference used "
                                 f"in {photos_dir}, or re-run sfm") from None
            except ValueError as exc:
                raise InputError(f"{path}: {exc}; use the photos the SfM registered") from None
            t_load += time.perf_counter() - t1
            h, w = img.shape[:2]
            dist_px = max_distortion_px(cam.params, cam.width, cam.height, w / cam.width)
            shift = max(shift, dist_px)
            if (w, h) not in renderers:  # the vertex map only: no texture needed
                renderers[(w, h)] = Renderer(mesh.vertices, mesh.faces, None, None, w, h)
            t1 = time.perf_counter()
            vertex = renderers[(w, h)].vertex_map(view_matrix_opencv(cam.R_wc, cam.center),
                                                     projection_from_K(K, w, h))
            t_render += time.perf_counter() - t1
            if valid is not None:
                vertex[~valid] = -1  # no photo pixel there after undistortion
            coverage = float((vertex >= 0).mean())
            vid = photo_view_id(cam.image, used_ids)
            if coverage < min_coverage:
                dropped.append({"id": vid, "image": cam.image, "reason": "off_mesh", "coverage": round(coverage, 4)})
                continue
            n_undistorted += int(undist)
            Image.fromarray(img).save(out_dir / f"{vid}.png", compress_level=1)
            write_vertex_map(out_dir / f"{vid}_vertex.npz", vertex)
            kept.append({"id": vid, "sampler": "photo", "image": cam.image, "width": w, "height": h,
                         "K": K.round(4).tolist(), "R_world_from_camera": cam.R_wc.tolist(),
                         "center": cam.center.tolist(), "undistorted": bool(undist),
                         "max_distortion_px": round(dist_px, 3),
                         "empty_fraction": round(1 - coverage, 4)})
    finally:
        for r in renderers.values():
            r.release()
    return kept, dropped, {"undistorted": n_undistorted, "max_distortion_px": shift, "load_seconds": t_load,
                           "render_seconds": t_render}


def photo_summary(kept: list, dropped: list, cams: list, stats: dict, min_coverage: float, log) -> dict:
    """Log the photo views kept and dropped (a warning when most photos miss the mesh); their metrics."""
    n_photo = len(kept)
    off = [d for d in dropped if d["reason"] == "off_mesh"]
    sizes = sorted({(v["width"], v["height"]) for v in kept})
    shift = stats["max_distortion_px"]
    log.info("photo views: %d of %d registered photos kept at %s px (%d of them undistorted; largest "
             "distortion %.2f px, resampled from 0.25 px), %d dropped (the pose sees the mesh in < %.0f %% of the "
             "pixels)", n_photo, len(cams), ", ".join(f"{a}x{b}" for a, b in sizes) or "-", stats["undistorted"],
             shift, len(off), 100 * min_coverage)
    if cams and len(off) > len(cams) / 2:
        log.warning("photo views: %d of %d photos miss the mesh; check the georeference (cameras_site.json) "
                    "against the mesh", len(off), len(cams))
    return {"photos": len(cams), "photo_views": n_photo, "dropped_off_mesh": len(off),
            "undistorted": stats["undistorted"], "max_distortion_px": round(shift, 3),
            "photo_sizes": [list(s) for s in sizes],
            "photo_load_seconds": round(stats["load_seconds"], 3),
            "photo_render_seconds": round(stats["render_seconds"], 3)}

"""A synthetic walked street for the dense tests: a textured road (z = 0) between two textured façades
(x = -4 and x = +5), photographed by a camera 1.6 m high walking forward along +y, looking down the
street (slightly turned and tilted per photo, as a hand-held phone is). Rendered by ray casting, so
every pixel's true depth is known."""
from __future__ import annotations

import numpy as np


def _texture(seed: int, n: int = 512) -> np.ndarray:
    """Multi-scale value noise in 0..1 (asphalt- and plaster-like), tiled."""
    import cv2

    rng = np.random.default_rng(seed)
    img = np.zeros((n, n), np.float32)
    for cells, amp in ((8, 0.5), (32, 0.3), (128, 0.25), (512, 0.2)):
        g = rng.random((cells, cells)).astype(np.float32)
        img += amp * cv2.resize(g, (n, n), interpolation=cv2.INTER_CUBIC if cells < n else cv2.INTER_NEAREST)
    img -= img.min()
    return img / img.max()


def _lookup(tex, a, b, metres_per_tile):
    n = tex.shape[0]
    x = np.mod(a / metres_per_tile, 1.0) * n
    y = np.mod(b / metres_per_tile, 1.0) * n
    x0, y0 = np.floor(x).astype(int) % n, np.floor(y).astype(int) % n
    x1, y1 = (x0 + 1) % n, (y0 + 1) % n
    fx, fy = x - np.floor(x), y - np.floor(y)
    return ((tex[y0, x0] * (1 - fx) + tex[y0, x1] * fx) * (1 - fy) + (tex[y1, x0] * (1 - fx) + tex[y1, x1] * fx) * fy)


def look_rotation(yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """R_world_from_camera (OpenCV camera: x right, y down, z forward) looking along +y turned by yaw, down by pitch."""
    y, p = np.radians(yaw_deg), np.radians(pitch_deg)
    fwd = np.array([np.sin(y) * np.cos(p), np.cos(y) * np.cos(p), -np.sin(p)])
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    return np.stack([right, down, fwd], 1)


def render_street(n_photos: int = 5, step_m: float = 1.0, size=(160, 120), f_px: float = 140.0, seed: int = 0):
    """Photos (gray float32 0..1), cameras {K, R_world_from_camera, center}, true depths (h, w)."""
    w, h = size
    K = np.array([[f_px, 0, (w - 1) / 2], [0, f_px, (h - 1) / 2], [0, 0, 1.0]])
    road, left, right = _texture(seed), _texture(seed + 1), _texture(seed + 2)
    rng = np.random.default_rng(seed + 10)
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    rays_c = np.stack([u, v, np.ones_like(u)], -1) @ np.linalg.inv(K).T
    photos, cams, depths = [], [], []
    for i in range(n_photos):
        C = np.array([0.3 * rng.standard_normal(), i * step_m, 1.6])
        R = look_rotation(yaw_deg=8 * rng.standard_normal(), pitch_deg=8 + 3 * rng.standard_normal())
        d = rays_c @ R.T  # world directions, camera z = 1
        best = np.full((h, w), np.inf)
        val = np.zeros((h, w))
        for axis, pos, tex, ab in ((2, 0.0, road, (0, 1)), (0, -4.0, left, (1, 2)), (0, 5.0, right, (1, 2))):
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (pos - C[axis]) / d[..., axis]
            P = C + t[..., None] * d
            hit = (t > 0) & (t < best)
            if axis == 0:
                hit &= (P[..., 2] > 0) & (P[..., 2] < 12)
            col = _lookup(tex, P[..., ab[0]], P[..., ab[1]], 6.0)
            val = np.where(hit, col, val)
            best = np.where(hit, t, best)
        depth = np.where(np.isfinite(best) & (best < 60), best, 0.0)  # camera z (rays have z = 1)
        photos.append((0.15 + 0.7 * val).astype(np.float32))
        cams.append({"K": K.copy(), "R_world_from_camera": R, "center": C})
        depths.append(depth.astype(np.float32))
    return photos, cams, depths

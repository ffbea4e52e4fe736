"""Procedural texture atlas (numpy only, deterministic from a seed).

The atlas is a square RGB image of ``grid x grid`` tiles of ``tile_px`` pixels.
Every material of the demo site owns one tile; geometry maps its UVs into the
tile's rectangle (see :meth:`Atlas.uv`). Textures are albedo (unlit); the
renderer adds sun light and shadows.

Ground textures are tileable (noise made with wrap-around filters) because the
ground geometry repeats them every ``period`` metres.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

TILE_PX = 256
GRID = 8  # 8 x 8 tiles -> 2048 px atlas


def _noise(rng: np.random.Generator, n: int, sigma: float, aniso: tuple[float, float] | None = None) -> np.ndarray:
    """Tileable gaussian-filtered noise (n, n) float32, zero mean, unit std."""
    a = rng.standard_normal((n, n)).astype(np.float32)
    s = (sigma * aniso[0], sigma * aniso[1]) if aniso else sigma
    a = ndimage.gaussian_filter(a, s, mode="wrap")
    a -= a.mean()
    a /= a.std() + 1e-9
    return a


def _fbm(rng: np.random.Generator, n: int, sigmas=(32, 12, 4, 1.2), weights=(0.5, 0.3, 0.15, 0.08)) -> np.ndarray:
    out = np.zeros((n, n), np.float32)
    for s, w in zip(sigmas, weights):
        out += w * _noise(rng, n, s)
    return out


def _rgb(c, n: int) -> np.ndarray:
    return np.broadcast_to(np.asarray(c, np.float32), (n, n, 3)).copy()


def _blend(img: np.ndarray, col, mask: np.ndarray) -> np.ndarray:
    m = mask[..., None].astype(np.float32)
    return img * (1 - m) + np.asarray(col, np.float32) * m


def _yx(n: int):
    y, x = np.mgrid[0:n, 0:n].astype(np.float32)
    return (y + 0.5) / n, (x + 0.5) / n  # v (0 top), u


# ---------------------------------------------------------------- ground
def asphalt(rng, n, marking: bool = False):
    base = 0.33 + 0.035 * _fbm(rng, n)
    img = np.stack([base, base * 1.0, base * 1.04], -1)
    grain = 0.05 * rng.standard_normal((n, n)).astype(np.float32)
    img += grain[..., None]
    speck = rng.random((n, n))
    img[speck > 0.985] += 0.16
    img[speck < 0.012] -= 0.12
    wear = _noise(rng, n, 40)
    img += (0.05 * np.clip(wear, 0, None))[..., None]  # lighter worn wheel paths
    # a few cracks: random walks with wrap-around
    for _ in range(3):
        p = rng.random(2) * n
        d = rng.random() * 2 * np.pi
        for _s in range(int(n * 0.6)):
            d += rng.normal(0, 0.35)
            p = (p + [np.cos(d), np.sin(d)]) % n
            img[int(p[0]), int(p[1])] *= 0.55
    # an oil stain
    v, u = _yx(n)
    c = rng.random(2)
    dd = np.minimum(abs(v - c[0]), 1 - abs(v - c[0])) ** 2 + np.minimum(abs(u - c[1]), 1 - abs(u - c[1])) ** 2
    img *= (1 - 0.18 * np.exp(-dd / 0.004))[..., None]
    if marking:
        paint = np.clip(1.6 + 0.25 * _noise(rng, n, 1.5) - 0.6 * np.clip(_noise(rng, n, 6), 0, None), 0, 1)
        img = img * (1 - paint[..., None]) + np.array([0.88, 0.88, 0.85], np.float32) * paint[..., None]
        img += 0.03 * rng.standard_normal((n, n, 1)).astype(np.float32)
    return img


def paving(rng, n, period_m=4.0):
    """Concrete slabs 0.4 x 0.4 m with a band of small reddish pavers; tile covers period_m."""
    img = _rgb((0.68, 0.64, 0.58), n)
    px_m = n / period_m
    v, u = np.mgrid[0:n, 0:n].astype(np.float32) / px_m  # metres
    size = 0.4
    row = np.floor(v / size).astype(int)
    col = np.floor(u / size).astype(int)
    k = int(round(period_m / size)) + 1
    shade = rng.normal(0, 0.045, (k, k, 1)).astype(np.float32) + np.array([0.0, -0.005, -0.01], np.float32)
    img = img + shade[row % k, col % k]
    # every third row of slabs: reddish small pavers (0.2 x 0.1, herringbone-ish offset)
    red = (row % 5) == 2
    small_r = np.floor(v / 0.1).astype(int)
    small_c = np.floor((u + (small_r % 2) * 0.1) / 0.2).astype(int)
    tint = rng.normal(0, 0.05, (64, 64, 1)).astype(np.float32)
    red_col = np.array([0.58, 0.40, 0.34], np.float32) + tint[small_r % 64, small_c % 64]
    img = np.where(red[..., None], red_col, img)
    ju = (u / size) % 1.0
    jv = (v / size) % 1.0
    joint = np.where(red, ((v / 0.1) % 1 < 0.1) | (((u + (small_r % 2) * 0.1) / 0.2) % 1 < 0.05), (ju < 0.025) | (jv < 0.025))
    img = _blend(img, (0.30, 0.29, 0.27), joint)
    img += (0.04 * _fbm(rng, n))[..., None]
    img += 0.03 * rng.standard_normal((n, n, 1)).astype(np.float32)
    return img


def granite(rng, n):
    img = _rgb((0.56, 0.55, 0.54), n)
    s = rng.random((n, n))
    img[s > 0.9] -= 0.2
    img[s < 0.07] += 0.15
    img = ndimage.uniform_filter(img, (2, 2, 1), mode="wrap")
    v, u = _yx(n)
    img = _blend(img, (0.3, 0.3, 0.3), (u % 0.25) < 0.01)  # 1 m stones when tile = 4 m
    return img + (0.03 * _fbm(rng, n))[..., None]


def grass(rng, n):
    g = _noise(rng, n, 0.8, aniso=(2.5, 0.6))
    big = _fbm(rng, n)
    img = np.stack([0.22 + 0.05 * big, 0.40 + 0.08 * big, 0.12 + 0.03 * big], -1)
    img += (0.07 * g)[..., None] * np.array([0.8, 1.0, 0.5], np.float32)
    dirt = _noise(rng, n, 20) > 1.3
    img = _blend(img, (0.36, 0.31, 0.22), dirt * 0.6)
    img += 0.035 * rng.standard_normal((n, n, 3)).astype(np.float32)
    return img


# ---------------------------------------------------------------- buildings
def _window(img, rng, x0, x1, y0, y1, frame=(0.92, 0.92, 0.9), shop=False):
    n = img.shape[0]
    X0, X1, Y0, Y1 = (int(round(t * n)) for t in (x0, x1, y0, y1))
    f = max(2, n // 64)
    img[Y0 - f:Y1 + f, X0 - f:X1 + f] = frame
    h, w = Y1 - Y0, X1 - X0
    gy = np.linspace(0, 1, h, dtype=np.float32)[:, None]
    gx = np.linspace(0, 1, w, dtype=np.float32)[None, :]
    # reflections: bright sky at the top, the opposite street's facades lower down, a dim interior
    refl = 0.22 + 0.30 * np.clip(1 - gy * 1.2 + 0.25 * gx, 0, 1) ** 1.5
    glass = np.stack([refl * 0.88, refl * 0.95, refl * 1.05], -1)
    band = (gy > 0.55) & (gy < 0.9)
    glass = np.where(band[..., None] & np.ones((1, w, 1), bool), glass * 0.8 + np.array([0.12, 0.1, 0.08], np.float32), glass)
    glass += 0.025 * _noise(rng, max(h, w), 4)[:h, :w, None]
    if shop:  # lit interior with goods and a door
        glass = glass * 0.6 + np.array([0.28, 0.25, 0.2], np.float32)
        for _ in range(16):
            a, b = rng.integers(0, w - 8), rng.integers(h // 3, h - 6)
            glass[b:b + rng.integers(4, 14), a:a + rng.integers(4, 18)] = rng.random(3).astype(np.float32) * 0.5 + 0.25
        dw = w // 5
        glass[:, w // 2 - dw // 2:w // 2 + dw // 2] = glass[:, w // 2 - dw // 2:w // 2 + dw // 2] * 0.5 + 0.12
        glass[:, w // 2 - dw // 2 - 2:w // 2 - dw // 2 + 1] = frame
        glass[:, w // 2 + dw // 2 - 1:w // 2 + dw // 2 + 2] = frame
    elif rng.random() < 0.6:  # curtain
        cw = int(w * rng.uniform(0.15, 0.35))
        glass[:, :cw] = glass[:, :cw] * 0.3 + np.array([0.75, 0.72, 0.65], np.float32) * 0.7
    img[Y0:Y1, X0:X1] = glass
    # mullion and sill
    img[Y0:Y1, (X0 + X1) // 2 - f // 2:(X0 + X1) // 2 + f // 2 + 1] = frame
    img[Y1 + f:Y1 + 2 * f + 1, X0 - 2 * f:X1 + 2 * f] = (0.7, 0.7, 0.68)


def _wall_base(rng, n, kind, col):
    if kind == "brick":
        img = _rgb(col, n)
        bh, bw = 3.2 / 0.075, 3.0 / 0.26  # rows/cols per tile
        v, u = np.mgrid[0:n, 0:n].astype(np.float32) / n
        row = np.floor(v * bh).astype(int)
        uu = u * bw + (row % 2) * 0.5
        colidx = np.floor(uu).astype(int)
        shade = rng.normal(0, 0.05, (int(bh) + 2, int(bw) + 3, 3)).astype(np.float32)
        img += shade[row, colidx]
        mortar = ((v * bh) % 1 < 0.18) | (uu % 1 < 0.06)
        img = _blend(img, (0.72, 0.70, 0.66), mortar)
    else:
        img = _rgb(col, n)
        img += (0.03 * _fbm(rng, n))[..., None]
        streak = _noise(rng, n, 3, aniso=(12, 0.5))
        img -= (0.025 * np.clip(streak, 0, None))[..., None]
    img += 0.02 * rng.standard_normal((n, n, 1)).astype(np.float32)
    return img


def facade(rng, n, kind, col, shop=False):
    img = _wall_base(rng, n, kind, col)
    if shop:
        img[int(0.05 * n):int(0.17 * n)] = np.clip(rng.random(3) * 0.6 + 0.2, 0, 1)  # sign band
        _window(img, rng, 0.18, 0.82, 0.28, 0.97, frame=(0.35, 0.35, 0.37), shop=True)
    else:
        _window(img, rng, 0.28, 0.72, 0.22, 0.70)
    # horizontal cornice line at the floor boundary
    img[-max(2, n // 80):] *= 0.85
    return img


def roof(rng, n):
    img = _rgb((0.28, 0.27, 0.27), n) + (0.05 * _fbm(rng, n))[..., None]
    return img + 0.03 * rng.standard_normal((n, n, 1)).astype(np.float32)


def concrete_wall(rng, n):
    img = _rgb((0.66, 0.65, 0.62), n) + (0.05 * _fbm(rng, n))[..., None]
    v, u = _yx(n)
    img = _blend(img, (0.45, 0.45, 0.43), ((u * 2) % 1 < 0.012))  # panel joints every 1.5 m
    for cy in (0.25, 0.75):  # form-tie holes
        for cx in (0.125, 0.375, 0.625, 0.875):
            img = _blend(img, (0.35, 0.35, 0.35), ((v - cy) ** 2 + (u - cx) ** 2) < 0.00012)
    stains = _noise(rng, n, 4, aniso=(10, 0.6))
    img -= (0.06 * np.clip(stains, 0, None) * v)[..., None]
    moss = np.clip(_noise(rng, n, 6), 1.0, None) - 1.0
    img = _blend(img, (0.3, 0.36, 0.2), np.clip(moss * (v > 0.7), 0, 0.8))
    return img + 0.025 * rng.standard_normal((n, n, 1)).astype(np.float32)


# ---------------------------------------------------------------- street furniture
def metal(rng, n, col, streaks=True):
    img = _rgb(col, n)
    if streaks:
        img += (0.04 * _noise(rng, n, 2, aniso=(15, 0.3)))[..., None]
    return img + 0.02 * rng.standard_normal((n, n, 1)).astype(np.float32)


def traffic_light_front(rng, n):
    img = metal(rng, n, (0.08, 0.08, 0.08), streaks=False)
    v, u = _yx(n)
    lit = int(rng.integers(0, 3))
    cols = [(1.0, 0.15, 0.1), (1.0, 0.7, 0.1), (0.2, 1.0, 0.5)]
    for i, c in enumerate(cols):
        cy = (i + 0.5) / 3
        d2 = ((v - cy) * 3) ** 2 + (u - 0.5) ** 2
        img = _blend(img, (0.02, 0.02, 0.02), d2 < 0.16)  # visor shadow
        lamp = np.asarray(c) * (1.0 if i == lit else 0.22)
        img = _blend(img, lamp, d2 < 0.09)
    return img


def sign(rng, n, kind):
    v, u = _yx(n)
    img = _rgb((0.85, 0.85, 0.85), n)
    if kind == "crossing":  # blue square, white triangle, black walking figure
        img = _rgb((0.05, 0.25, 0.65), n)
        img = _blend(img, (0.95, 0.95, 0.95), (np.abs(u - 0.5) > 0.44) | (np.abs(v - 0.5) > 0.44))
        tri = (v > 0.22) & (v < 0.82) & (np.abs(u - 0.5) < (v - 0.22) * 0.62)
        img = _blend(img, (0.95, 0.95, 0.95), tri)
        fig = ((u - 0.5) ** 2 + (v - 0.45) ** 2 < 0.0015) | ((np.abs(u - 0.5 - (v - 0.5) * 0.2) < 0.025) & (v > 0.48) & (v < 0.66))
        fig |= (np.abs(np.abs(u - 0.5) - (v - 0.66) * 0.5) < 0.02) & (v > 0.66) & (v < 0.78)
        fig |= (v > 0.76) & (v < 0.79) & (np.abs(u - 0.5) < 0.2) & ((u * 20) % 2 < 1)
        img = _blend(img, (0.05, 0.05, 0.05), fig)
    elif kind == "no_entry":
        d = np.hypot(u - 0.5, v - 0.5)
        img = _rgb((0.80, 0.08, 0.08), n)
        img = _blend(img, (0.95, 0.95, 0.95), (np.abs(v - 0.5) < 0.09) & (np.abs(u - 0.5) < 0.33))
        img = _blend(img, (0.95, 0.95, 0.95), d > 0.47)
    elif kind == "yield":
        img = _rgb((0.8, 0.08, 0.08), n)
        inner = (v > 0.16) & (v < 0.8) & (np.abs(u - 0.5) < (0.8 - v) * 0.5)
        img = _blend(img, (0.96, 0.85, 0.2), inner)
    elif kind == "stop":
        img = _rgb((0.8, 0.06, 0.06), n)
        for k in range(4):  # crude "STOP" letters as white bars
            x0 = 0.2 + k * 0.155
            img = _blend(img, (0.97, 0.97, 0.97), (u > x0) & (u < x0 + 0.11) & (np.abs(v - 0.5) < 0.11) & ~((u > x0 + 0.03) & (u < x0 + 0.08) & (np.abs(v - 0.5) < 0.06 + 0.05 * (k % 2))))
        d = np.maximum(np.abs(u - 0.5), np.abs(v - 0.5))
        img = _blend(img, (0.97, 0.97, 0.97), (d > 0.45) & (d < 0.48))
    elif kind == "speed":
        d = np.hypot(u - 0.5, v - 0.5)
        img = _rgb((0.96, 0.96, 0.96), n)
        img = _blend(img, (0.8, 0.08, 0.08), (d > 0.36))
        img = _blend(img, (0.05, 0.05, 0.05), ((np.abs(u - 0.38) < 0.08) | (np.abs(u - 0.62) < 0.08)) & (np.abs(v - 0.5) < 0.17)
                     & ~((np.abs(u - 0.38) < 0.04) & (np.abs(v - 0.5) < 0.12) & ((v < 0.45) | (v > 0.55)) ) & ~((np.abs(u - 0.62) < 0.04) & (np.abs(v - 0.5) < 0.13)))
    return img + 0.015 * rng.standard_normal((n, n, 1)).astype(np.float32)


# ---------------------------------------------------------------- vegetation
def foliage(rng, n, dark=False):
    """Leaves: many small bright/dark blobs (fine scale) over a clumpy base."""
    f = _fbm(rng, n, sigmas=(12, 5, 2.0, 0.8), weights=(0.3, 0.3, 0.3, 0.2))
    leaf = np.clip(f * 1.5 + 0.3, -1, 1)
    base = np.array([0.24, 0.40, 0.12] if not dark else [0.16, 0.30, 0.10], np.float32)
    img = base + (0.13 * leaf)[..., None] * np.array([0.8, 1.2, 0.5], np.float32)
    holes = f < -1.0
    img = _blend(img, (0.07, 0.10, 0.05), holes)
    hi = rng.random((n, n)) > 0.93
    img = _blend(img, (0.50, 0.62, 0.25), hi * 0.6)
    img = ndimage.uniform_filter(img, (2, 2, 1), mode="wrap")
    return img + 0.05 * rng.standard_normal((n, n, 3)).astype(np.float32)


def bark(rng, n):
    s = _noise(rng, n, 1.5, aniso=(8, 0.6))
    img = np.array([0.33, 0.27, 0.21], np.float32) + (0.07 * s)[..., None]
    return img + 0.03 * rng.standard_normal((n, n, 1)).astype(np.float32)


# ---------------------------------------------------------------- vehicles
def car_side(rng, n, paint):
    v, u = _yx(n)
    p = np.asarray(paint, np.float32)
    img = p * (0.85 + 0.3 * (1 - v))[..., None]  # brighter at top (sky reflection)
    img = _blend(img, p * 0.55, (v > 0.47) & (v < 0.5))  # crease
    for x in (0.36, 0.62):  # door seams
        img = _blend(img, p * 0.4, np.abs(u - x) < 0.003)
    for x in (0.30, 0.56):
        img = _blend(img, (0.15, 0.15, 0.15), (np.abs(u - x) < 0.03) & (np.abs(v - 0.35) < 0.025))
    img = _blend(img, (0.08, 0.08, 0.09), v > 0.88)  # sill/rocker
    for cx in (0.19, 0.81):  # wheel arches (dark)
        img = _blend(img, (0.05, 0.05, 0.05), ((u - cx) / 0.09) ** 2 + ((v - 0.97) / 0.58) ** 2 < 1.0)
    return img + 0.01 * rng.standard_normal((n, n, 1)).astype(np.float32)


def car_window(rng, n, paint):
    v, u = _yx(n)
    p = np.asarray(paint, np.float32)
    refl = 0.08 + 0.2 * np.clip(1 - v * 1.2 + 0.4 * u - 0.2, 0, 1) ** 2
    img = np.stack([refl * 0.9, refl, refl * 1.15], -1)
    frame = (u < 0.05) | (u > 0.95) | (v < 0.1) | (v > 0.92) | (np.abs(u - 0.5) < 0.03)
    img = _blend(img, p * 0.9, frame)
    return img + 0.01 * rng.standard_normal((n, n, 1)).astype(np.float32)


def car_end(rng, n, paint, front: bool):
    v, u = _yx(n)
    p = np.asarray(paint, np.float32)
    img = p * (0.8 + 0.2 * (1 - v))[..., None]
    lamp = (0.95, 0.95, 0.9) if front else (0.75, 0.05, 0.05)
    img = _blend(img, lamp, (np.abs(v - 0.3) < 0.12) & ((u < 0.2) | (u > 0.8)) & (u > 0.04) & (u < 0.96))
    if front:
        img = _blend(img, (0.06, 0.06, 0.07), (np.abs(v - 0.45) < 0.12) & (np.abs(u - 0.5) < 0.25))
    img = _blend(img, (0.95, 0.95, 0.95), (np.abs(v - 0.72) < 0.08) & (np.abs(u - 0.5) < 0.13))  # plate
    img = _blend(img, (0.1, 0.1, 0.1), v > 0.86)  # bumper
    return img + 0.01 * rng.standard_normal((n, n, 1)).astype(np.float32)


def tire(rng, n):
    v, u = _yx(n)
    d = np.hypot(u - 0.5, v - 0.5)
    img = _rgb((0.06, 0.06, 0.06), n)
    img = _blend(img, (0.55, 0.56, 0.58), d < 0.3)
    img = _blend(img, (0.2, 0.2, 0.2), (d < 0.3) & ((np.arctan2(v - 0.5, u - 0.5) * 5 / np.pi) % 2 < 0.5) & (d > 0.1))
    return img + 0.02 * rng.standard_normal((n, n, 1)).astype(np.float32)


# ---------------------------------------------------------------- the atlas
CAR_PAINTS = {
    "white": (0.86, 0.86, 0.86),
    "silver": (0.62, 0.63, 0.65),
    "black": (0.09, 0.09, 0.10),
    "red": (0.62, 0.08, 0.07),
    "blue": (0.10, 0.20, 0.48),
}
FACADES = {  # name: (kind, colour)
    "ochre": ("plaster", (0.80, 0.66, 0.42)),
    "white": ("plaster", (0.84, 0.83, 0.79)),
    "grey": ("plaster", (0.58, 0.58, 0.57)),
    "brick": ("brick", (0.55, 0.25, 0.17)),
    "brownbrick": ("brick", (0.42, 0.28, 0.20)),
}


def _material_table():
    t = [
        ("asphalt", lambda r, n: asphalt(r, n)),
        ("marking", lambda r, n: asphalt(r, n, marking=True)),
        ("paving", lambda r, n: paving(r, n)),
        ("granite", granite),
        ("grass", grass),
        ("roof", roof),
        ("concrete_wall", concrete_wall),
        ("fence", lambda r, n: metal(r, n, (0.13, 0.2, 0.15))),
        ("pole", lambda r, n: metal(r, n, (0.45, 0.46, 0.47))),
        ("tl_front", traffic_light_front),
        ("tl_housing", lambda r, n: metal(r, n, (0.1, 0.1, 0.1), streaks=False)),
        ("sign_back", lambda r, n: metal(r, n, (0.6, 0.6, 0.62))),
        ("foliage", foliage),
        ("hedge", lambda r, n: foliage(r, n, dark=True)),
        ("bark", bark),
        ("tire", tire),
        ("bike_frame", lambda r, n: metal(r, n, (0.1, 0.25, 0.5), streaks=False)),
        ("moto_body", lambda r, n: metal(r, n, (0.55, 0.08, 0.06), streaks=False)),
        ("dark_metal", lambda r, n: metal(r, n, (0.12, 0.12, 0.13), streaks=False)),
    ]
    for k in ("crossing", "no_entry", "yield", "stop", "speed"):
        t.append((f"sign_{k}", (lambda kk: lambda r, n: sign(r, n, kk))(k)))
    for name, (kind, col) in FACADES.items():
        t.append((f"facade_{name}", (lambda kk, cc: lambda r, n: facade(r, n, kk, cc))(kind, col)))
        t.append((f"shop_{name}", (lambda kk, cc: lambda r, n: facade(r, n, kk, cc, shop=True))(kind, col)))
        t.append((f"plain_{name}", (lambda kk, cc: lambda r, n: _wall_base(r, n, kk, cc))(kind, col)))
    for name, col in CAR_PAINTS.items():
        t.append((f"car_{name}_side", (lambda c: lambda r, n: car_side(r, n, c))(col)))
        t.append((f"car_{name}_window", (lambda c: lambda r, n: car_window(r, n, c))(col)))
        t.append((f"car_{name}_front", (lambda c: lambda r, n: car_end(r, n, c, True))(col)))
        t.append((f"car_{name}_rear", (lambda c: lambda r, n: car_end(r, n, c, False))(col)))
        t.append((f"car_{name}_paint", (lambda c: lambda r, n: car_side(r, n, c) * 0 + np.asarray(c, np.float32) * 0.95)(col)))
    return t


@dataclass
class Atlas:
    """The texture atlas: ``image`` (H, W, 3) uint8, ``slots`` material name -> (row, col)."""

    image: np.ndarray
    slots: dict[str, tuple[int, int]] = field(default_factory=dict)
    tile_px: int = TILE_PX
    grid: int = GRID

    def uv(self, material: str, st: np.ndarray) -> np.ndarray:
        """Map tile-local coordinates ``st`` (..., 2) in [0, 1] (s right, t up) to atlas UVs (OBJ convention, v up).

        Coordinates are clamped half a pixel inside the tile so bilinear lookups never bleed.
        """
        r, c = self.slots[material]
        eps = 0.5 / self.tile_px
        st = np.clip(np.asarray(st, np.float64), eps, 1 - eps)
        u = (c + st[..., 0]) / self.grid
        v = 1.0 - (r + 1 - st[..., 1]) / self.grid
        return np.stack([u, v], -1)

    def sample(self, uv: np.ndarray) -> np.ndarray:
        """Bilinear lookup of atlas UVs (n, 2) -> (n, 3) float32 in [0, 1]."""
        img = self.image
        h, w = img.shape[:2]
        x = np.clip(uv[:, 0] * w - 0.5, 0, w - 1.001)
        y = np.clip((1.0 - uv[:, 1]) * h - 0.5, 0, h - 1.001)
        x0 = np.floor(x).astype(np.int64)
        y0 = np.floor(y).astype(np.int64)
        fx = (x - x0).astype(np.float32)[:, None]
        fy = (y - y0).astype(np.float32)[:, None]
        f = img.astype(np.float32) if img.dtype != np.float32 else img
        a = f[y0, x0] * (1 - fx) + f[y0, x0 + 1] * fx
        b = f[y0 + 1, x0] * (1 - fx) + f[y0 + 1, x0 + 1] * fx
        return (a * (1 - fy) + b * fy) / 255.0


def build_atlas(seed: int) -> Atlas:
    """Generate every material tile into one atlas image (deterministic for ``seed``)."""
    table = _material_table()
    assert len(table) <= GRID * GRID, f"{len(table)} materials do not fit the {GRID}x{GRID} atlas"
    img = np.zeros((GRID * TILE_PX, GRID * TILE_PX, 3), np.float32)
    slots = {}
    for i, (name, fn) in enumerate(table):
        rng = np.random.default_rng([seed, 7919, i])
        tile = fn(rng, TILE_PX)
        r, c = divmod(i, GRID)
        img[r * TILE_PX:(r + 1) * TILE_PX, c * TILE_PX:(c + 1) * TILE_PX] = tile
        slots[name] = (r, c)
    out = np.clip(img * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return Atlas(image=out, slots=slots)

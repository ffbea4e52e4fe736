"""Weathering: a world-space albedo variation that makes every square metre of the site unique.

The atlas tiles repeat (a facade shows one tile per floor and bay, a road one asphalt tile per few
metres), which no real street does: grime, stains, repairs and wear differ everywhere. Without that,
photos of the demo site match look-alike windows of different bays and buildings, and structure from
motion builds a consistent but wrong model. This layer multiplies the albedo by ``1 + amount * n(p)``
where ``n`` is fractal value noise evaluated at the 3-D surface point ``p`` (site frame, metres).
The photos are weathered; the scanner's colours only with ``weathering_scan`` (see docs/demo-site.md).
"""
from __future__ import annotations

import numpy as np

#: octaves: (wavelength m, weight). Coarse stains down to 2 cm grain (a photo pixel at 10 m is 1.2 cm).
OCTAVES = ((1.6, 0.30), (0.55, 0.28), (0.19, 0.22), (0.07, 0.13), (0.025, 0.07))

_P1, _P2, _P3 = np.uint64(0x9E3779B185EBCA87), np.uint64(0xC2B2AE3D27D4EB4F), np.uint64(0x165667B19E3779F9)
_MIX = np.uint64(0xBF58476D1CE4E5B9)
_S29, _S32, _S40 = np.uint64(29), np.uint64(32), np.uint64(40)
#: points per block: the lattice hash's temporaries of one block stay in the CPU cache (6x faster than whole arrays).
BLOCK = 16384


def _hash01(ix: np.ndarray, iy: np.ndarray, iz: np.ndarray, salt: int) -> np.ndarray:
    """Deterministic lattice hash -> float32 in [-1, 1) (the reference form of what :func:`value_noise` inlines)."""
    h = ix.astype(np.uint64) * _P1 ^ iy.astype(np.uint64) * _P2 ^ iz.astype(np.uint64) * _P3 ^ np.uint64(salt)
    h ^= h >> _S29
    h *= _MIX
    h ^= h >> _S32
    return ((h >> _S40).astype(np.float32) * np.float32(1.0 / (1 << 23))) - np.float32(1.0)


def value_noise(points: np.ndarray, wavelength: float, salt: int) -> np.ndarray:
    """Trilinear value noise (smoothstep weights) at ``points`` (n, 3) -> (n,) float32 in [-1, 1]."""
    pts = np.asarray(points, np.float64)
    out = np.empty(len(pts), np.float32)
    for s in range(0, len(pts), BLOCK):
        out[s:s + BLOCK] = _value_noise_block(pts[s:s + BLOCK], wavelength, salt)
    return out


def _value_noise_block(points: np.ndarray, wavelength: float, salt: int) -> np.ndarray:
    """:func:`value_noise` on one block: each axis's hash term is computed once for both lattice corners, then the
    eight corners are mixed in place; bit-identical to summing ``wx * wy * wz * _hash01(...)`` over the corners."""
    q = points / wavelength
    base = np.floor(q)
    f = (q - base).astype(np.float32)
    w = f * f * (np.float32(3.0) - np.float32(2.0) * f)
    i = base.astype(np.int64)
    n = len(q)
    out = np.zeros(n, np.float32)
    with np.errstate(over="ignore"):
        terms = [(np.ascontiguousarray(i[:, a]).view(np.uint64) * p, (i[:, a] + 1).view(np.uint64) * p)
                 for a, p in enumerate((_P1, _P2, _P3))]
        hz = [t ^ np.uint64(salt) for t in terms[2]]
        ws = [(1 - w[:, a], w[:, a]) for a in range(3)]
        h, t, hxy = np.empty(n, np.uint64), np.empty(n, np.uint64), np.empty(n, np.uint64)
        v, wxy, wxyz = np.empty(n, np.float32), np.empty(n, np.float32), np.empty(n, np.float32)
        for dx in (0, 1):
            for dy in (0, 1):
                np.bitwise_xor(terms[0][dx], terms[1][dy], out=hxy)
                np.multiply(ws[0][dx], ws[1][dy], out=wxy)
                for dz in (0, 1):
                    np.bitwise_xor(hxy, hz[dz], out=h)
                    np.right_shift(h, _S29, out=t)
                    h ^= t
                    h *= _MIX
                    np.right_shift(h, _S32, out=t)
                    h ^= t
                    h >>= _S40
                    v[:] = h
                    v *= np.float32(1.0 / (1 << 23))
                    v -= np.float32(1.0)
                    np.multiply(wxy, ws[2][dz], out=wxyz)
                    v *= wxyz
                    out += v
    return out


def weathering(points: np.ndarray, seed: int) -> np.ndarray:
    """Fractal noise (n,) float32, roughly in [-1, 1] (standard deviation about 0.3), at ``points`` (n, 3)."""
    out = np.zeros(len(points), np.float32)
    for k, (wl, wt) in enumerate(OCTAVES):
        out += np.float32(wt) * value_noise(points, wl, (int(seed) * 7919 + k * 104729) & 0xFFFFFFFF)
    return out


def apply_weathering(albedo: np.ndarray, points: np.ndarray, amount: float, seed: int) -> np.ndarray:
    """``albedo`` (n, 3) in [0, 1] times ``1 + amount * noise``, with a slight warm/cool tint, clipped."""
    if amount <= 0 or len(points) == 0:
        return albedo
    n = weathering(points, seed)
    tint = np.float32(0.25 * amount) * value_noise(points, 0.9, (int(seed) * 31 + 5) & 0xFFFFFFFF)
    f = 1.0 + np.float32(amount) * n
    out = albedo * f[:, None]
    out[:, 0] *= 1.0 + tint
    out[:, 2] *= 1.0 - tint
    return np.clip(out, 0.0, 1.0)

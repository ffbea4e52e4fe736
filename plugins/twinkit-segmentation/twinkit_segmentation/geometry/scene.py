"""A small labelled street capture made by code: the 3D classifier's check scene (tests, the model's record).

A straight street (road, raised pavements with curbs, facades, parked cars, lamp posts, trees) sampled
the way a sensor standing in the road sees it: point density falling with the square of the range, range
noise along the ray, nothing behind the first surface is modelled (the scene has few occlusions).
"""
from __future__ import annotations

import numpy as np

from twinkit.cityscapes import BUILDING, CAR, POLE, ROAD, SIDEWALK, VEGETATION


def _plane(rng, origin, u, v, n_pts):
    a, b = rng.random((2, n_pts))
    return np.asarray(origin) + a[:, None] * np.asarray(u) + b[:, None] * np.asarray(v)


def street_capture(seed: int = 0, *, half_length_m: float = 25.0, density: float = 1.0, noise_m: float = 0.015,
                   sensor=(0.0, 0.0, 1.8)) -> dict:
    """``{"xyz": (n, 3) float64 metres (z up), "label": (n,) uint8 trainIds}`` of a generated street.

    ``density`` scales the point count (1: about 0.3 M points before the range fall-off)."""
    rng = np.random.default_rng(seed)
    L = half_length_m
    parts: list[tuple[np.ndarray, int]] = []

    def add(pts, lab):
        parts.append((np.asarray(pts, np.float64), lab))

    k = density * 6000.0  # points per square metre-ish budget scale

    def n_for(area):
        return max(10, int(k * area / 40.0))

    add(_plane(rng, (-L, -5, 0), (2 * L, 0, 0), (0, 10, 0), n_for(20 * L)), ROAD)
    for s in (-1, 1):
        add(_plane(rng, (-L, 5 * s, 0.0), (2 * L, 0, 0), (0, 0, 0.13), n_for(0.26 * L)), SIDEWALK)  # curb face
        add(_plane(rng, (-L, 5 * s, 0.13), (2 * L, 0, 0), (0, 3 * s, 0), n_for(6 * L)), SIDEWALK)
        add(_plane(rng, (-L, 8 * s, 0.13), (2 * L, 0, 0), (0, 0, 9.0), n_for(18 * L)), BUILDING)
        for x0 in rng.uniform(-L + 3, L - 8, 2):  # parked cars: sides and roof
            y0 = 3.2 * s
            lo = np.array([x0, y0 - 0.9, 0.25])
            faces: tuple = (((0, 0, 0), (4.5, 0, 0), (0, 0, 1.25)), ((0, 1.8, 0), (4.5, 0, 0), (0, 0, 1.25)),
                              ((0, 0, 0), (0, 1.8, 0), (0, 0, 1.25)), ((4.5, 0, 0), (0, 1.8, 0), (0, 0, 1.25)),
                              ((0.6, 0, 1.25), (3.2, 0, 0), (0, 1.8, 0)))
            for o, u, v in faces:
                add(_plane(rng, lo + np.asarray(o), u, v, n_for(6)), CAR)
        for x0 in np.arange(-L + 4, L - 2, 12.0) + rng.uniform(-1, 1):  # lamp posts
            t = rng.random(n_for(2.5))
            ang = rng.random(len(t)) * 2 * np.pi
            add(np.column_stack([x0 + 0.08 * np.cos(ang), 5.6 * s + 0.08 * np.sin(ang), 0.13 + 6.0 * t]), POLE)
        for x0 in np.arange(-L + 9, L - 2, 12.0) + rng.uniform(-1, 1):  # trees: trunk and a leafy crown
            t = rng.random(n_for(1.5))
            ang = rng.random(len(t)) * 2 * np.pi
            add(np.column_stack([x0 + 0.15 * np.cos(ang), 6.5 * s + 0.15 * np.sin(ang), 0.13 + 3.0 * t]), VEGETATION)
            c = rng.normal(0, 1, (n_for(40), 3))
            c /= np.linalg.norm(c, axis=1, keepdims=True)
            r = 2.2 * rng.random(len(c)) ** 0.3
            add(np.array([x0, 6.5 * s, 5.0]) + c * r[:, None] * np.array([1, 1, 0.8]), VEGETATION)
    xyz = np.concatenate([p for p, _ in parts])
    lab = np.concatenate([np.full(len(p), c, np.uint8) for p, c in parts])
    # the sensor's view: density falls with range squared, noise along the ray
    origin = np.asarray(sensor, np.float64)
    d = xyz - origin
    r = np.linalg.norm(d, axis=1)
    keep = rng.random(len(r)) < np.clip((6.0 / np.maximum(r, 1e-6)) ** 2, 0, 1)
    xyz, lab, d, r = xyz[keep], lab[keep], d[keep], r[keep]
    xyz = xyz + d / r[:, None] * np.clip(rng.normal(0, noise_m, len(r)), -3 * noise_m, 3 * noise_m)[:, None]
    return {"xyz": xyz, "label": lab}

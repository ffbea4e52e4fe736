"""A small synthetic street block for tests: wavy ground, a box building, a pole and a low wall,
sampled as points with outward normals (no holes under objects: the ground is only sampled
outside them). ``ground_hole=(x, y, r)`` leaves a disc of ground unsampled, like the occlusion
shadow of a parked car. Deterministic from ``seed``."""
from __future__ import annotations

import numpy as np


def street_block(size_m: float = 20.0, spacing_m: float = 0.08, seed: int = 0, noise_m: float = 0.002,
                 ground_hole: tuple | None = None):
    rng = np.random.default_rng(seed)
    h = size_m / 2
    pts, nrm = [], []

    def ground_z(x, y):
        return 0.15 * np.sin(x / 3.0) * np.cos(y / 4.0)

    g = np.arange(-h, h + 1e-9, spacing_m)
    X, Y = np.meshgrid(g, g)
    X, Y = X.ravel(), Y.ravel()
    bx0, bx1, by0, by1, bh = -6.0, -1.0, 2.0, 7.5, 6.0  # building
    inside_b = (X > bx0) & (X < bx1) & (Y > by0) & (Y < by1)
    X, Y = X[~inside_b], Y[~inside_b]
    if ground_hole is not None:
        hx, hy, hr = ground_hole
        keep = np.hypot(X - hx, Y - hy) > hr
        X, Y = X[keep], Y[keep]
    Z = ground_z(X, Y)
    dzdx = 0.15 / 3.0 * np.cos(X / 3.0) * np.cos(Y / 4.0)
    dzdy = -0.15 / 4.0 * np.sin(X / 3.0) * np.sin(Y / 4.0)
    n = np.stack([-dzdx, -dzdy, np.ones_like(X)], axis=1)
    pts.append(np.stack([X, Y, Z], axis=1))
    nrm.append(n / np.linalg.norm(n, axis=1, keepdims=True))
    # building walls and roof
    zs = np.arange(0, bh + 1e-9, spacing_m)
    for (x0, y0, x1, y1, nv) in ((bx0, by0, bx1, by0, (0, -1, 0)), (bx1, by0, bx1, by1, (1, 0, 0)),
                                 (bx1, by1, bx0, by1, (0, 1, 0)), (bx0, by1, bx0, by0, (-1, 0, 0))):
        L = np.hypot(x1 - x0, y1 - y0)
        s = np.arange(0, L, spacing_m) / L
        S, Zs = np.meshgrid(s, zs)
        S, Zs = S.ravel(), Zs.ravel()
        P = np.stack([x0 + (x1 - x0) * S, y0 + (y1 - y0) * S, Zs], axis=1)
        P[:, 2] = np.maximum(P[:, 2], ground_z(P[:, 0], P[:, 1]))
        pts.append(P)
        nrm.append(np.tile(np.asarray(nv, float), (len(P), 1)))
    rx, ry = np.meshgrid(np.arange(bx0, bx1, spacing_m), np.arange(by0, by1, spacing_m))
    pts.append(np.stack([rx.ravel(), ry.ravel(), np.full(rx.size, bh)], axis=1))
    nrm.append(np.tile([0.0, 0.0, 1.0], (rx.size, 1)))
    # a pole (cylinder r 0.12 m, 4 m) standing across the x = 0 seam area
    px, py, r = 0.3, -3.0, 0.12
    ang = np.arange(0, 2 * np.pi, spacing_m / r)
    A, Zp = np.meshgrid(ang, np.arange(0, 4.0, spacing_m / 2))
    A, Zp = A.ravel(), Zp.ravel()
    pts.append(np.stack([px + r * np.cos(A), py + r * np.sin(A), Zp], axis=1))
    nrm.append(np.stack([np.cos(A), np.sin(A), np.zeros_like(A)], axis=1))
    P = np.vstack(pts)
    N = np.vstack(nrm)
    P = P + rng.normal(0, noise_m, P.shape)
    C = np.clip(np.stack([128 + 40 * np.sin(P[:, 0]), 128 + 40 * np.cos(P[:, 1]), 100 + 10 * P[:, 2]], axis=1), 0, 255)
    return P, N.astype(np.float32), C.astype(np.uint8)

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[3]
SHARED_CLOUDS = REPO.parent / "shared" / "data" / "pointclouds"


def shared_file(name: str) -> Path:
    p = SHARED_CLOUDS / name
    if not p.exists():
        pytest.skip(f"needs ../shared/data/pointclouds/{name} (shared sample data not present)")
    return p


def box_scene(n_ground: int = 30000, n_face: int = 5000, seed: int = 0):
    """A 10 x 10 m ground (z = 0) with a red/blue 1 m checker and a 2 x 2 x 2 m box on it
    (centre (0, 0, 1)). Returns (points (n, 3), colours (n, 3) uint8, true normals (n, 3))."""
    rng = np.random.default_rng(seed)
    g = np.c_[rng.uniform(-5, 5, n_ground), rng.uniform(-5, 5, n_ground), np.zeros(n_ground)]
    gn = np.tile([0.0, 0.0, 1.0], (n_ground, 1))
    parts, norms = [g], [gn]
    for ax in range(3):
        for s in (-1.0, 1.0):
            if ax == 2 and s < 0:
                continue  # the bottom is on the ground
            p = rng.uniform(-1, 1, (n_face, 3))
            p[:, ax] = s
            p[:, 2] += 1.0
            nn = np.zeros((n_face, 3))
            nn[:, ax] = s
            keep = ~((np.abs(p[:, 0]) < 1) & (np.abs(p[:, 1]) < 1) & (p[:, 2] <= 0))
            parts.append(p[keep])
            norms.append(nn[keep])
    pts = np.vstack(parts)
    nrm = np.vstack(norms)
    col = checker_colour(pts)
    return pts, col, nrm


def checker_colour(pts: np.ndarray) -> np.ndarray:
    even = ((np.floor(pts[:, 0]) + np.floor(pts[:, 1])) % 2) == 0
    return np.where(even[:, None], [230, 20, 20], [20, 20, 230]).astype(np.uint8)


@pytest.fixture
def ctx(tmp_path):
    from twinkit.testing import make_context

    return make_context(tmp_path / "work", site={"name": "test"})

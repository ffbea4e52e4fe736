"""How densely a cloud samples its surfaces, and what kind of capture it is.

Several steps choose a setting from the cloud when their parameter is left at "auto" (-1): the trim
distance of the clean step, the Poisson depth, the texture size, the camera heights and the view
budget. They all call :func:`measure` on their own input, so a step needs no extra file and the
same cloud always gives the same numbers (a fixed random subsample, a fixed seed).

* ``spacing_m``: the median distance from a point to its nearest neighbour.
* ``spacing_p90_m``: the 90th percentile of it (the sparse parts: far range, walls of an aerial scan).
* ``vertical_share``: the share of points on near-vertical surfaces (|normal z| < 0.3, normals from
  a local PCA of 16 neighbours; the file's normals are not trusted for this).
* ``ground_two_way_share``: of the points on near-horizontal surfaces, the share whose 16 neighbours spread
  both ways (the middle spread at least ``TWO_WAY_SPREAD`` of their radius): a patch of ground, not one
  scan line. A single spinning sweep samples its ground in rings a few centimetres apart along the ring and
  decimetres across: 0.26-0.33 on the real SemanticKITTI sweeps, 0.997 and more on mobile and terrestrial
  street scans. A kerb step is measured across, so a capture whose ground is mostly single lines shows none.
  None when no point lies on a near-horizontal surface.
* ``capture``: ``aerial`` when under ``AERIAL_VERTICAL_SHARE`` of the points lie on vertical surfaces
  (an airborne scanner sees roofs and ground, few walls: Autzen 6 %, IGN LiDAR HD 9 %, against
  19-45 % for street scans), else ``terrestrial`` when the file has several scanner positions (static
  setups), else ``mobile``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: below this share of points on vertical surfaces a cloud is taken for an aerial capture
AERIAL_VERTICAL_SHARE = 0.12
#: points sampled for the measurement (the result does not change noticeably above ~10k)
SAMPLE = 20_000
#: k neighbours spread both ways when their middle spread (sqrt of the middle eigenvalue) is at least this share
#: of their radius (one scan line: about 0); the segmentation's cue gates use the same test
TWO_WAY_SPREAD = 0.25
#: under this ``ground_two_way_share`` a capture's ground is sampled in rings, not patches (a single spinning
#: sweep: 0.26-0.33 on real ones; street and aerial scans 0.99+): the cues, the kerb level and the classifier's
#: floor that depend on it share this default
RING_CAPTURE_SHARE = 0.5


def measure(points: np.ndarray, *, scanner_positions=None, sample: int = SAMPLE, seed: int = 0) -> dict:
    """Spacing and capture type of ``points`` (N x 3, metres). See the module's docstring."""
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    if n < 20:
        return {"points": int(n), "spacing_m": float("nan"), "spacing_p90_m": float("nan"),
                "vertical_share": float("nan"), "ground_two_way_share": None, "capture": "unknown",
                "extent_m": [0.0, 0.0, 0.0]}
    pts = pts - pts.mean(axis=0)
    nbh = neighbourhoods(pts, sample=sample, seed=seed)
    nn = nbh.radius_1
    nn = nn[nn > 0] if (nn > 0).any() else nn  # duplicates (a file with repeated points) say nothing
    vertical = float((nbh.nz < 0.3).mean())
    flat = nbh.flat
    horizontal = float(flat.mean())
    two_way_share = round(float(nbh.two_way[flat].mean()), 4) if flat.any() else None
    n_scanners = 0
    if scanner_positions is not None:
        sp = np.asarray(scanner_positions, dtype=float).reshape(-1, 3)
        n_scanners = int(np.isfinite(sp).all(axis=1).sum())
    if vertical < AERIAL_VERTICAL_SHARE:
        capture = "aerial"
    elif n_scanners >= 1:
        capture = "terrestrial"
    else:
        capture = "mobile"
    ext = np.ptp(pts, axis=0)
    return {"points": int(n), "spacing_m": float(np.median(nn)), "spacing_p90_m": float(np.quantile(nn, 0.9)),
            "vertical_share": round(vertical, 4), "horizontal_share": round(horizontal, 4),
            "ground_two_way_share": two_way_share,
            "capture": capture, "scanners": n_scanners, "extent_m": [round(float(e), 3) for e in ext]}


@dataclass
class Neighbourhoods:
    """The 16-neighbour PCA of a sample of a cloud's points (:func:`neighbourhoods`): ``idx`` the sampled
    points, ``radius_1`` / ``radius_k`` the distance to the nearest / the 16th neighbour, ``nz`` |z| of the
    normal, ``major`` (m, 3) the main direction, ``two_way`` whether the neighbours spread both ways
    (``TWO_WAY_SPREAD``: not one scan line)."""

    idx: np.ndarray
    radius_1: np.ndarray
    radius_k: np.ndarray
    nz: np.ndarray
    major: np.ndarray
    two_way: np.ndarray

    @property
    def flat(self) -> np.ndarray:
        """Points on near-horizontal surfaces."""
        return self.nz > 0.9


def neighbourhoods(pts: np.ndarray, *, sample: int = SAMPLE, seed: int = 0) -> Neighbourhoods:
    """The local shape around a fixed random sample of ``pts`` (n, 3), n >= 2: what :func:`measure` and
    :func:`twinkit.surface.rings.ring_sensor` read."""
    from scipy.spatial import cKDTree

    n = len(pts)
    tree = cKDTree(pts)
    rng = np.random.default_rng(seed)
    idx = rng.choice(n, min(sample, n), replace=False) if n > sample else np.arange(n)
    k = min(16, n)
    d, nb = tree.query(pts[idx], k=k)
    q = pts[nb] - pts[nb].mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", q, q) / k
    ev, vec = np.linalg.eigh(cov)
    two_way = np.sqrt(np.maximum(ev[:, 1], 0.0)) >= TWO_WAY_SPREAD * d[:, -1]
    return Neighbourhoods(idx=idx, radius_1=d[:, 1], radius_k=d[:, -1], nz=np.abs(vec[:, 2, 0]),
                          major=vec[:, :, 2], two_way=two_way)


def describe(m: dict) -> str:
    """One log line."""
    return (f"point spacing {m['spacing_m']:.3g} m (p90 {m['spacing_p90_m']:.3g} m), "
            f"{100 * m['vertical_share']:.0f} % of the points on vertical surfaces: capture {m['capture']}")


# ----------------------------------------------------------------------------- settings that follow the density

#: the trim distance never goes below this (the setting before issue 28; right for street scans)
TRIM_FLOOR_M = 0.10
#: ... and is this many times the median nearest-neighbour distance
TRIM_SPACING_FACTOR = 2.0


def trim_distance(m: dict) -> float:
    """The clean step's ``max_dist_m`` for this cloud: a surface vertex between samples lies up to about
    0.7 x their spacing from the nearest one (the centre of a square of four), so ``TRIM_SPACING_FACTOR``
    x the median spacing keeps the surface the samples support and still cuts the bubbles that grow away
    from them; never below 0.10 m. The median, not a high percentile: a street scanner's far range is
    sparse too (the demo's p90 is 0.10 m, its median 0.043 m), and the gap rule of the clean step already
    keeps the ground between its far scan lines."""
    s = m.get("spacing_m")
    if s is None or not math.isfinite(s):
        return TRIM_FLOOR_M
    return round(max(TRIM_FLOOR_M, TRIM_SPACING_FACTOR * float(s)), 3)


def poisson_depth(m: dict, scale: float = 1.1, lo: int = 6, hi: int = 11) -> int:
    """The octree depth whose voxel is about the median spacing (a finer octree has no samples to fill
    it), between ``lo`` and ``hi`` (11: the setting before issue 28; deeper costs time for nothing on
    the scans measured, docs/pointcloud.md)."""
    s = m.get("spacing_m")
    ext = max(m.get("extent_m") or [0.0])
    if s is None or not math.isfinite(s) or s <= 0 or ext <= 0:
        return hi
    return int(min(hi, max(lo, math.ceil(math.log2(ext * scale / s)))))


#: share of the texture atlas the charts fill (the built-in chart packer's padding and gaps)
ATLAS_FILL = 0.6


def texture_size(area_m2: float, texel_m: float, lo: int = 1024, hi: int = 8192) -> int:
    """The power-of-two texture side nearest (on a log scale) to the one that gives ``area_m2`` of surface
    texels of ``texel_m`` (the atlas being ``ATLAS_FILL`` full), between ``lo`` and ``hi`` (8192: the setting
    before issue 28). Nearest, not the next one up (issue 48): the demo needs 4,944 px, so rounding up gave
    8192, texels a seventh of its dense mesh's 64 mm edge; its colours live on those vertices, and 4096
    holds them to 0.4 colour levels (8192: 0.2), equal against the truth, mIoU 81.1 (8192: 81.0), bake 4x
    faster."""
    if not (area_m2 > 0 and texel_m > 0):
        return lo
    side = math.sqrt(area_m2 / ATLAS_FILL) / texel_m
    px = 1 << max(0, round(math.log2(max(side, 1.0))))
    return int(min(hi, max(lo, px)))


#: texels never finer than this (a street model seen from a car)
MIN_TEXEL_M = 0.01


def mesh_texel(vertices: np.ndarray, faces: np.ndarray) -> tuple[float, float]:
    """(surface area m², texel m) of a dense mesh: a quarter of its median edge length (its colours live on
    the vertices: a few texels across each triangle hold them, finer ones only interpolate), never
    below ``MIN_TEXEL_M``."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if len(f) == 0:
        return 0.0, 0.005
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    area = float(0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())
    rng = np.random.default_rng(0)
    sel = f[rng.choice(len(f), min(len(f), 50_000), replace=False)]
    edge = np.linalg.norm(v[sel[:, 0]] - v[sel[:, 1]], axis=1)
    return area, max(MIN_TEXEL_M, 0.25 * float(np.median(edge)))

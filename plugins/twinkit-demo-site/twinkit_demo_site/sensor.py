"""The sensor model of the simulated captures (:mod:`twinkit_demo_site.captures`): per-capture realism draws
(:class:`Sensor`), the rays cast against the site and what a real sensor makes of them (:func:`trace`), and,
opt-in, returns moved where a real surface is not where the mesh is (:func:`surface_depth`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from twinkit import cityscapes as cs
from twinkit_demo_site.weathering import _hash01 as lattice_hash

if TYPE_CHECKING:
    from twinkit_demo_site.captures import World

#: rough near-infrared reflectance per trainId (0..1), the centre of each capture's random draw
REFLECTANCE = {cs.ROAD: 0.28, cs.SIDEWALK: 0.32, cs.BUILDING: 0.32, cs.WALL: 0.32, cs.FENCE: 0.3, cs.POLE: 0.3,
               cs.TRAFFIC_LIGHT: 0.22, cs.TRAFFIC_SIGN: 0.85, cs.VEGETATION: 0.45, cs.TERRAIN: 0.45, cs.PERSON: 0.3,
               cs.CAR: 0.25, cs.MOTORCYCLE: 0.25, cs.BICYCLE: 0.2}

@dataclass
class Sensor:
    """Per-capture realism draws. ``noise_m`` range noise sigma (m); ``dropout`` share of returns lost at random;
    ``cos_min`` incidence cosine below which a return is lost; ``snr_thr`` detection threshold of the return
    strength; ``gain``, ``range_half_m`` intensity gain and range fall-off; ``refl`` (256,) float32 reflectance per
    trainId; ``max_range_m``."""

    noise_m: float
    dropout: float
    cos_min: float
    snr_thr: float
    gain: float
    range_half_m: float
    refl: np.ndarray
    max_range_m: float
    surfaces: bool = False
    foliage_m: float = 0.0
    glass: float = 0.0
    relief_m: float = 0.0
    window_period_m: float = 3.0


def draw_sensor(rng: np.random.Generator, max_range_m: float, surfaces: bool = False) -> Sensor:
    """Random realism settings for one capture (see :class:`Sensor`); ``surfaces`` draws those of
    :func:`surface_depth` too (after the others: without it the random stream is what it always was)."""
    refl = np.full(256, 0.3, np.float32)
    for c, r in REFLECTANCE.items():
        refl[c] = r * float(np.exp(rng.normal(0.0, 0.35)))
    s = Sensor(noise_m=float(rng.uniform(0.01, 0.03)), dropout=float(rng.uniform(0.0, 0.08)),
               cos_min=float(rng.uniform(0.01, 0.04)), snr_thr=float(np.exp(rng.uniform(np.log(3e-4), np.log(3e-3)))),
               gain=float(rng.uniform(0.75, 1.4)), range_half_m=float(rng.uniform(40.0, 150.0)),
               refl=np.clip(refl, 0.02, 1.0), max_range_m=float(max_range_m))
    if surfaces:
        s.surfaces, s.foliage_m, s.glass = True, float(rng.uniform(0.1, 0.6)), float(rng.uniform(0.0, 0.3))
        s.relief_m, s.window_period_m = float(rng.uniform(0.0, 0.03)), float(rng.uniform(2.4, 3.6))
    return s


def surface_depth(sensor: Sensor, hit: np.ndarray, normal: np.ndarray, label: np.ndarray, cos: np.ndarray,
                  rng: np.random.Generator) -> np.ndarray:
    """(n,) metres to add to each return's range where the real surface is not the mesh's: ``hit`` (n, 3) the
    hit points, ``normal`` (n, 3) the hit faces' unit normals, ``label`` (n,) their trainIds, ``cos`` (n,) the
    incidence cosines.

    - Vegetation: a crown or hedge is a volume of leaves, not a skin; a return comes from an exponential depth
      of mean ``sensor.foliage_m`` (at most 4x that) inside it.
    - Building facades (near-vertical building faces): a grid of windows (``window_period_m`` wide bays, one
      1.3 x 1.4 m window per bay on 3 m floors, the grid's phase per facade plane); a return on a window comes
      from inside the room behind the pane (0.2-1.5 m farther) with chance ``sensor.glass``, else from the
      recessed frame (8-25 cm along the normal); elsewhere a relief of ``sensor.relief_m`` (sills, pipes,
      render) along the normal. Walls get the relief too.
    Real single sweeps show both: at 0.25 m the scattering of a real facade is ten times a clean plane's, and of
    real foliage five times a skin's (docs/segmentation.md "3D classifier")."""
    n = len(hit)
    out = np.zeros(n)
    inv_cos = 1.0 / np.maximum(cos, 0.2)
    veg = label == cs.VEGETATION
    if sensor.foliage_m > 0 and veg.any():
        out[veg] = np.minimum(rng.exponential(sensor.foliage_m, int(veg.sum())), 4 * sensor.foliage_m)
    fac = np.isin(label, (cs.BUILDING, cs.WALL)) & (np.abs(normal[:, 2]) < 0.3)
    if fac.any():
        i = np.flatnonzero(fac)
        nxy = normal[i, :2] / np.maximum(np.linalg.norm(normal[i, :2], axis=1, keepdims=True), 1e-9)
        u = hit[i, 0] * -nxy[:, 1] + hit[i, 1] * nxy[:, 0]
        # a facade plane: its offset (m) and direction (tenths), hashed into the grid's phases
        off = np.round(hit[i, 0] * nxy[:, 0] + hit[i, 1] * nxy[:, 1]).astype(np.int64)
        nx, ny = np.round(nxy[:, 0] * 10).astype(np.int64), np.round(nxy[:, 1] * 10).astype(np.int64)
        per = sensor.window_period_m
        fu = np.mod(u / per + 0.5 * (lattice_hash(off, nx, ny, 44) + 1.0), 1.0)
        fz = np.mod(hit[i, 2] + 1.5 * (lattice_hash(off, nx, ny, 45) + 1.0), 3.0)
        win = (label[i] == cs.BUILDING) & (np.abs(fu - 0.5) * per < 0.65) & (fz > 0.9) & (fz < 2.3)
        relief = np.clip(rng.normal(0.0, 1.0, len(i)), -3, 3) * sensor.relief_m
        inside = win & (rng.random(len(i)) < sensor.glass)
        recess = rng.uniform(0.08, 0.25, len(i))
        d = np.where(win, recess, relief) * inv_cos[i]
        d[inside] = rng.uniform(0.2, 1.5, int(inside.sum()))
        out[i] = d
    return out


def trace(world: World, sensor: Sensor, org: np.ndarray, dirs: np.ndarray, rng: np.random.Generator,
          ref_range_m: float = 10.0) -> dict:
    """Cast rays ``org``, ``dirs`` (k, 3) (unit directions, site frame) and apply the sensor model.

    Returns the kept returns: ``keep`` (n,) int64 ray indices, ``xyz`` (n, 3) float64 noisy points, ``label`` (n,)
    uint8 trainId of the hit face, ``intensity`` (n,) float32 0..1, ``range`` (n,) float64 true range (m),
    ``cos`` (n,) float32 incidence cosine, ``prim`` (n,) int64 hit face."""
    tr = world.tracer
    t, prim, _bary = tr.cast(org.astype(np.float32), dirs.astype(np.float32))
    hit = (prim >= 0) & (t < sensor.max_range_m) & (t > 0.3)
    idx = np.flatnonzero(hit)
    t, prim = t[idx].astype(np.float64), prim[idx]
    d = dirs[idx]
    n = tr.face_normals[prim]
    cos = np.abs(n[:, 0] * d[:, 0] + n[:, 1] * d[:, 1] + n[:, 2] * d[:, 2]).astype(np.float32)
    lab = tr.face_labels[prim]
    refl = np.minimum(sensor.refl[lab] * world.mod[prim], 1.0)
    strength = refl * cos / np.maximum(t / ref_range_m, 1.0) ** 2
    p_det = 1.0 - np.exp(-strength / sensor.snr_thr)
    ok = (cos >= sensor.cos_min) & (rng.random(len(t)) < p_det) & (rng.random(len(t)) >= sensor.dropout)
    idx, t, prim, d, cos, lab, refl = idx[ok], t[ok], prim[ok], d[ok], cos[ok], lab[ok], refl[ok]
    noise = np.clip(rng.standard_normal(len(t)), -3, 3) * sensor.noise_m
    if sensor.surfaces:
        noise += surface_depth(sensor, org[idx] + d * t[:, None], tr.face_normals[prim], lab, cos, rng)
    xyz = org[idx] + d * (t + noise)[:, None]
    inten = sensor.gain * refl * (0.7 + 0.3 * cos) / (1.0 + (t / sensor.range_half_m) ** 2)
    inten = np.clip(inten + rng.normal(0.0, 0.02, len(t)), 0.0, 1.0)
    inten = np.round(inten * 100) / 100  # stored in 0.01 steps, as the SemanticKITTI scans are
    return {"keep": idx, "xyz": xyz, "label": lab.astype(np.uint8), "intensity": inten.astype(np.float32),
            "range": t, "cos": cos, "prim": prim}


def sensor_meta(s: Sensor) -> dict:
    return {"noise_m": s.noise_m, "dropout": s.dropout, "cos_min": s.cos_min, "snr_thr": s.snr_thr, "gain": s.gain,
            "max_range_m": s.max_range_m, "foliage_m": s.foliage_m, "glass": s.glass, "relief_m": s.relief_m,
            "window_period_m": s.window_period_m}

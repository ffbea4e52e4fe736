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

#: near-infrared (~905 nm) reflectance per trainId of the material a street is commonly made of, the centre of
#: each capture's draw with ``materials``: asphalt 0.1-0.25, concrete and stone paving 0.25-0.45, brick and render
#: 0.3-0.5, leaves and grass bright past the red edge (0.4-0.6), painted or galvanised steel (poles, signal
#: housings) and car paint dark and mirror-like (:data:`SPECULAR`), retroreflective sheeting far brighter than
#: anything else
MATERIAL_REFLECTANCE = {cs.ROAD: 0.16, cs.SIDEWALK: 0.3, cs.BUILDING: 0.4, cs.WALL: 0.35, cs.FENCE: 0.3,
                        cs.POLE: 0.15, cs.TRAFFIC_LIGHT: 0.12, cs.TRAFFIC_SIGN: 0.85, cs.VEGETATION: 0.45,
                        cs.TERRAIN: 0.42, cs.PERSON: 0.3, cs.CAR: 0.14, cs.MOTORCYCLE: 0.2, cs.BICYCLE: 0.2}
#: share of the ``materials`` captures whose pavements are asphalt like the road (the reflectance then tells
#: them apart no more), and whose verges are bare soil or gravel rather than grass
ASPHALT_PAVEMENT_SHARE = 0.25
BARE_VERGE_SHARE = 0.25
#: metal, paint and glass: a mirror-like surface sends most of a beam back only near its normal, so with
#: ``materials`` their incidence term is ``SPECULAR_SHARE`` of the cosine's :data:`SPECULAR_POWER` and the rest
#: the diffuse term (a pole, a cylinder, comes back dark but for the strip facing the sensor; a car's sloped
#: panels and windows darker than a facade)
SPECULAR = (cs.POLE, cs.TRAFFIC_LIGHT, cs.CAR, cs.TRUCK, cs.BUS, cs.MOTORCYCLE, cs.BICYCLE)
SPECULAR_POWER = 4.0
SPECULAR_SHARE = 0.7
#: with ``materials``, a return off foliage is a leaf's edge or part of the beam's footprint as often as a
#: whole leaf: its intensity is the leaf's times a uniform draw in this range (a crown comes back darker and
#: more varied than a wall of the same reflectance)
FOLIAGE_FILL = (0.3, 1.0)


def texture_modulation(tracer, n_site_faces: int | None = None) -> np.ndarray:
    """(faces,) float32 per face of ``tracer``'s mesh: its texture's brightness at the centre against its class's
    area-weighted mean (0.4-2.5; markings brighter than asphalt, a dark stain darker), the intensity's texture
    term. Faces from ``n_site_faces`` on (an apron with flat textures) get 1."""
    n = len(tracer.face_labels) if n_site_faces is None else int(n_site_faces)
    faces = tracer.mesh.faces
    bary = np.tile(np.array([[1 / 3, 1 / 3]], np.float32), (len(faces), 1))
    lum = tracer.albedo(np.arange(len(faces)), bary).mean(1).astype(np.float32)
    lab = tracer.face_labels
    v = tracer.mesh.vertices[faces]
    area = np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)[:n]
    mean = np.full(256, 0.5)
    sums = np.bincount(lab[:n], weights=area * lum[:n], minlength=256)
    wts = np.bincount(lab[:n], weights=area, minlength=256)
    mean[wts > 0] = sums[wts > 0] / wts[wts > 0]
    mod = np.clip((0.2 + lum) / (0.2 + mean[lab]), 0.4, 2.5).astype(np.float32)
    mod[n:] = 1.0
    return mod


def material_intensity(label: np.ndarray, cos: np.ndarray, mod: np.ndarray, range_m: np.ndarray,
                       range_half_m: float) -> np.ndarray:
    """(n,) float64 0..1: the intensity of returns off ``label`` (n,) trainIds at incidence cosines ``cos`` with
    texture terms ``mod`` (:func:`texture_modulation`) and ranges ``range_m``, for a sensor without per-capture
    draws (the demo's own scanner): :data:`MATERIAL_REFLECTANCE` (0.3 for other classes), the metal's mirror-like
    and the diffuse incidence terms as with ``materials``, and a range fall-off of half at ``range_half_m``."""
    refl = np.full(256, 0.3)
    for c, r in MATERIAL_REFLECTANCE.items():
        refl[c] = r
    out = refl[label] * mod * incidence_term(label, cos) / (1.0 + (np.asarray(range_m) / range_half_m) ** 2)
    return np.clip(out, 0.0, 1.0)


def incidence_term(label: np.ndarray, cos: np.ndarray) -> np.ndarray:
    """(n,) float64: the intensity's incidence term of returns off ``label`` at incidence cosines ``cos``: the
    diffuse ``0.7 + 0.3 cos``, and for :data:`SPECULAR` materials mostly ``cos ** SPECULAR_POWER``."""
    diffuse = 0.7 + 0.3 * np.asarray(cos, np.float64)
    mirror = SPECULAR_SHARE * np.asarray(cos, np.float64) ** SPECULAR_POWER + (1 - SPECULAR_SHARE) * diffuse
    return np.where(np.isin(label, SPECULAR), mirror, diffuse)


@dataclass
class Sensor:
    """Per-capture realism draws. ``noise_m`` range noise sigma (m); ``dropout`` share of returns lost at random;
    ``cos_min`` incidence cosine below which a return is lost; ``snr_thr`` detection threshold of the return
    strength; ``gain``, ``range_half_m`` intensity gain and range fall-off; ``refl`` (256,) float32 reflectance per
    trainId; ``max_range_m``; ``materials``: the intensity's incidence term per material (draw_sensor).
    ``surfaces`` and the four after it: :func:`surface_depth`."""

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
    materials: bool = False


def draw_sensor(rng: np.random.Generator, max_range_m: float, surfaces: bool = False,
                materials: bool = False) -> Sensor:
    """Random realism settings for one capture (see :class:`Sensor`); ``surfaces`` draws those of
    :func:`surface_depth` too; ``materials`` redraws the reflectances around :data:`MATERIAL_REFLECTANCE` (a
    spread of 20 % per class and capture, against 35 % around :data:`REFLECTANCE` without it, where the classes'
    order is drawn anew each capture), with pavements of the road's asphalt in :data:`ASPHALT_PAVEMENT_SHARE` of
    the captures and bare verges (0.3) in :data:`BARE_VERGE_SHARE`, and gives metal, paint and glass
    (:data:`SPECULAR`) a mostly mirror-like incidence term (:func:`incidence_term`) and foliage partial returns
    (:data:`FOLIAGE_FILL`). ``surfaces`` draws after the others (without it the random stream is what it always
    was), ``materials`` from a child stream (the pose and the other draws stay those made without it; which far
    returns a dark surface loses follows its reflectance)."""
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
    if materials:
        mat = rng.spawn(1)[0]
        refl = np.full(256, 0.3, np.float32)
        for c, r in MATERIAL_REFLECTANCE.items():
            refl[c] = r * float(np.exp(mat.normal(0.0, 0.2)))
        if mat.random() < ASPHALT_PAVEMENT_SHARE:
            refl[cs.SIDEWALK] = refl[cs.ROAD] * float(np.exp(mat.normal(0.0, 0.1)))
        if mat.random() < BARE_VERGE_SHARE:
            refl[cs.TERRAIN] = 0.3 * float(np.exp(mat.normal(0.0, 0.2)))
        s.refl, s.materials = np.clip(refl, 0.02, 1.0), True
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
    incidence = 0.7 + 0.3 * cos
    if sensor.materials:
        incidence = incidence_term(lab, cos)
        leaf = lab == cs.VEGETATION
        incidence[leaf] *= rng.uniform(*FOLIAGE_FILL, int(leaf.sum()))
    inten = sensor.gain * refl * incidence / (1.0 + (t / sensor.range_half_m) ** 2)
    inten = np.clip(inten + rng.normal(0.0, 0.02, len(t)), 0.0, 1.0)
    inten = np.round(inten * 100) / 100  # stored in 0.01 steps, as the SemanticKITTI scans are
    return {"keep": idx, "xyz": xyz, "label": lab.astype(np.uint8), "intensity": inten.astype(np.float32),
            "range": t, "cos": cos, "prim": prim}


def sensor_meta(s: Sensor) -> dict:
    return {"noise_m": s.noise_m, "dropout": s.dropout, "cos_min": s.cos_min, "snr_thr": s.snr_thr, "gain": s.gain,
            "max_range_m": s.max_range_m, "foliage_m": s.foliage_m, "glass": s.glass, "relief_m": s.relief_m,
            "window_period_m": s.window_period_m,
            "reflectance": {cs.name_of(c): round(float(s.refl[c]), 4) for c in MATERIAL_REFLECTANCE}}

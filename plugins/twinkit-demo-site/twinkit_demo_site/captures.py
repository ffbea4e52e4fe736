"""Simulated captures of the demo street: the ways real lidar comes, with per-point CityScapes labels.

Training data for a 3D classifier (issue 44). Every kind casts rays against the demo site's ground-truth
mesh with the site's own :class:`~twinkit_demo_site.raycast.Tracer`; the label of a point is the label of
the face its ray hit. Kinds:

- ``spinning``: one 360-degree sweep of a multi-beam spinning sensor on a car standing in a lane (an
  HDL-64E-like layout: 64 beams from -24.9 to +2 degrees, 0.08-0.17 degree azimuth steps, ~1.73 m high);
- ``tls``: a few terrestrial tripod stations on the sidewalks and corners;
- ``mobile``: the demo's push-broom van (:mod:`twinkit_demo_site.scanner`) over a random subset of its passes;
- ``aerial``: airborne laser strips from a few hundred metres (swath +-20 degrees, 5-50 points/m^2).

Realism, drawn per capture from ``rng_seed``: range noise (1-3 cm sigma), random dropout, returns lost at
grazing incidence and on dark or far surfaces, no colour, an intensity, the sensor pose within the site, and a
density factor. With ``surfaces`` (``--surfaces``; off by default; the shipped 3D classifier's spinning sweeps are
made with it and with ``--tall-hedges``: docs/segmentation.md "Rough hedges and rough facades: m16") returns are also moved along their ray where a real surface is not where
the mesh is (:func:`twinkit_demo_site.sensor.surface_depth`): into foliage, behind window panes, into window recesses and over facade
relief. Beyond the site's edge the ground continues (an "apron": the roads, sidewalks and grass go on
for the sensor's range) so that far rings land on ground as they do on a real street.

Intensity is a rough model, not a radiometric one: a reflectance per class varied per capture, modulated by the
texture's brightness (markings brighter than asphalt), times a cosine-of-incidence term and a range fall-off, times
a per-capture gain, plus noise. By default each class's reflectance is drawn on its own (the classes' order changes
from capture to capture); with ``materials`` (``--materials``; opt-in, docs/segmentation.md "Intensity from
materials: m18") it is drawn around its material's near-infrared reflectance (asphalt dark, concrete paving
lighter, grass and foliage bright, metal mirror-like, signs retroreflective), a quarter of the sites paving their
pavements with the road's asphalt (:func:`twinkit_demo_site.sensor.draw_sensor`).
"""
from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from twinkit import cityscapes as cs
from twinkit.mesh import Mesh
from twinkit_demo_site.layout import Scene
from twinkit_demo_site.raycast import Tracer
from twinkit_demo_site.sensor import draw_sensor, sensor_meta, texture_modulation, trace

KINDS = ("spinning", "tls", "mobile", "aerial")
MAX_POINTS = 300_000

#: HDL-64E-like beam elevations (degrees): an upper block of 32 beams at 1/3 degree, a lower one at 1/2 degree
HDL64_ELEVATIONS = np.concatenate([np.linspace(2.0, -8.33, 32), np.linspace(-8.87, -24.9, 32)])


@dataclass
class World:
    """The demo site for one seed, ready to trace: ``scene`` (layout.Scene), ``tracer`` (raycast.Tracer over the
    site mesh plus the apron), ``n_site_faces`` (faces below this index are the site's), per-face ``mod`` (m,)
    float32 reflectance modulation from the texture's brightness (about 1 on average per class; road markings
    ~2x the asphalt)."""

    scene: Scene
    tracer: Tracer
    n_site_faces: int
    mod: np.ndarray


def build_world(seed: int, size: str = "small", variety: bool = True, apron_m: float = 130.0,
                apron_objects: bool = True, threads: int | None = None, tall_hedges: bool = False) -> World:
    """Build the demo site of ``seed`` and ``size`` (a plugin.PRESETS name) with the ground continued ``apron_m``
    metres beyond its edge, and its tracer. ``apron_objects``: the streets beyond the edge are lined (for 70 m)
    with buildings, tree groups, street trees and parked cars (:func:`_apron_objects`), so that far ranges see
    a street, not an empty plain. ``variety``: the layout's knobs drawn at random from the seed
    (layout.random_variety: building heights, parked cars, trees, verges, street widths; ``tall_hedges``: and the
    hedges' height); off = the demo's own site."""
    from twinkit_demo_site.layout import build_scene, random_variety  # noqa: I001
    from twinkit_demo_site.plugin import _preset
    from twinkit_demo_site.textures import build_atlas

    atlas = build_atlas(seed)
    knobs = random_variety(np.random.default_rng([seed, 10]), tall_hedges) if variety else None
    scene = build_scene(_preset(size)["half_m"], seed, atlas, knobs)
    site = scene.mesh
    if apron_objects:
        site = _merge(site, _apron_objects(atlas, scene.dims, np.random.default_rng([seed, 11]),
                                           knobs.floors if knobs else (3, 7)))
    mesh = _with_apron(site, scene.dims, apron_m)
    assert mesh.faces is not None and site.faces is not None
    tracer = Tracer(mesh, atlas, threads=threads)
    n_site = int(len(site.faces))
    mod = texture_modulation(tracer, n_site)
    return World(scene=scene, tracer=tracer, n_site_faces=n_site, mod=mod)


def _apron_objects(atlas, d, rng: np.random.Generator, floors: tuple[int, int], reach_m: float = 70.0) -> Mesh:
    """Objects along the four road arms beyond the site edge (out to ``reach_m``): frontage slots of 11-20 m holding
    a building (``floors`` drawn in [lo, hi)), a group of trees and bushes, or nothing; street trees on the sidewalks
    and parked cars on the main road's parking strips."""
    from twinkit_demo_site import objects as ob
    from twinkit_demo_site.meshbuild import MeshBuilder
    from twinkit_demo_site.textures import CAR_PAINTS, FACADES

    mb = MeshBuilder(atlas)
    H, cz = d.half_m, d.curb_m
    facades, paints = list(FACADES), list(CAR_PAINTS)
    for axis in (0, 1):  # 0: the main road's arms (along x), 1: the side street's (along y)
        edge = d.bm if axis == 0 else d.bs  # back of the sidewalk
        for s_along in (-1, 1):
            for s_side in (-1, 1):
                u = H + float(rng.uniform(0.5, 3.0))
                while u < H + reach_m:
                    w = float(rng.uniform(11.0, 20.0))
                    depth = float(rng.uniform(9.0, 14.0))
                    a0, a1 = sorted((s_along * u, s_along * (u + w)))
                    b0, b1 = sorted((s_side * edge, s_side * (edge + depth)))
                    x0, x1, y0, y1 = (a0, a1, b0, b1) if axis == 0 else (b0, b1, a0, a1)
                    k = rng.random()
                    if k < 0.55:
                        street = {("-y" if s_side > 0 else "+y") if axis == 0 else ("-x" if s_side > 0 else "+x")}
                        ob.building(mb, x0, x1, y0, y1, cz, int(rng.integers(*floors)),
                                    facades[int(rng.integers(len(facades)))], street)
                    elif k < 0.85:
                        for _ in range(int(rng.integers(1, 5))):
                            ob.tree(mb, rng, rng.uniform(x0 + 2, x1 - 2), rng.uniform(y0 + 2, y1 - 2), cz,
                                    float(rng.uniform(0.7, 1.3)))
                        for _ in range(int(rng.integers(0, 4))):
                            ob.bush(mb, rng, rng.uniform(x0 + 1, x1 - 1), rng.uniform(y0 + 1, y1 - 1), cz)
                    u += w + float(rng.uniform(1.5, 6.0))
                # street trees on the sidewalk and (main road) parked cars
                kerb = d.rm if axis == 0 else d.rs
                if rng.random() < 0.6:
                    u = H + float(rng.uniform(2.0, 8.0))
                    while u < H + reach_m:
                        c = (s_along * u, s_side * (kerb + 1.5))
                        ob.tree(mb, rng, *(c if axis == 0 else c[::-1]), cz, float(rng.uniform(0.7, 1.0)))
                        u += float(rng.uniform(8.0, 14.0))
                if axis == 0:
                    u = H + 3.0
                    park_p = float(rng.uniform(0.2, 0.9))
                    while u < H + reach_m:
                        if rng.random() < park_p:
                            ob.car(mb, rng, s_along * u, s_side * (d.main_traffic + d.park_m / 2), 0.0,
                                   0.0 if s_side < 0 else math.pi, paints[int(rng.integers(len(paints)))])
                        u += 6.2
    return mb.finish()


def _merge(a: Mesh, b: Mesh) -> Mesh:
    """Two meshes with ``uv`` and face ``label`` as one (``a``'s faces first)."""
    assert a.faces is not None and b.faces is not None
    return Mesh(vertices=np.concatenate([a.vertices, b.vertices]),
                faces=np.concatenate([a.faces, b.faces + len(a.vertices)]),
                attrs={"uv": np.concatenate([np.asarray(a.attrs["uv"], np.float32), np.asarray(b.attrs["uv"], np.float32)])},
                face_attrs={"label": np.concatenate([a.face_attrs["label"], b.face_attrs["label"]])})


def _with_apron(mesh: Mesh, d, apron_m: float) -> Mesh:
    """``mesh`` plus flat ground cells outside the site square |x|, |y| <= half: the main road (|y| < rm) and the
    side street (|x| < rs) go on as road at z = 0, their sidewalks as sidewalk and the rest as grass at curb
    height."""
    H, A = d.half_m, d.half_m + apron_m
    xs = np.unique(np.array([-A, -H, -d.bs, -d.rs, d.rs, d.bs, H, A]))
    ys = np.unique(np.array([-A, -H, -d.bm, -d.rm, d.rm, d.bm, H, A]))
    verts: list[list[list[float]]] = []
    faces: list[list[int]] = []
    labels: list[int] = []
    for j in range(len(ys) - 1):
        for i in range(len(xs) - 1):
            cx, cy = (xs[i] + xs[i + 1]) / 2, (ys[j] + ys[j + 1]) / 2
            if abs(cx) < H and abs(cy) < H:
                continue
            if (abs(cy) < d.rm and abs(cx) > H) or (abs(cx) < d.rs and abs(cy) > H):
                lab, z = cs.ROAD, 0.0
            elif (abs(cy) < d.bm and abs(cx) > H) or (abs(cx) < d.bs and abs(cy) > H):
                lab, z = cs.SIDEWALK, d.curb_m
            else:
                lab, z = cs.TERRAIN, d.curb_m
            k = len(verts) * 4 + len(mesh.vertices)
            verts.append([[xs[i], ys[j], z], [xs[i + 1], ys[j], z], [xs[i + 1], ys[j + 1], z], [xs[i], ys[j + 1], z]])
            faces += [[k, k + 1, k + 2], [k, k + 2, k + 3]]
            labels += [lab, lab]
    v = np.asarray(verts, np.float64).reshape(-1, 3)
    uv = np.zeros((len(v), 2), np.float32)
    return Mesh(vertices=np.concatenate([mesh.vertices, v]),
                faces=np.concatenate([mesh.faces, np.asarray(faces, np.int64)]),
                attrs={"uv": np.concatenate([np.asarray(mesh.attrs["uv"], np.float32), uv])},
                face_attrs={"label": np.concatenate([mesh.face_attrs["label"], np.asarray(labels, np.uint8)])})


def _rot(yaw: float, pitch: float = 0.0, roll: float = 0.0) -> np.ndarray:
    """World-from-sensor rotation (3, 3): roll about x, then pitch about y, then yaw about z (radians)."""
    cy, sy, cp, sp, cr, sr = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch), math.cos(roll), math.sin(roll)
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1.0]])
    Ry = np.array([[cp, 0, sp], [0, 1.0, 0], [-sp, 0, cp]])
    Rx = np.array([[1.0, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return Rz @ Ry @ Rx


def _ground_at(world: World, xy: np.ndarray, z0: float = 30.0):
    """Surface height (k,) and label (k,) under the points ``xy`` (k, 2) (a ray cast down from ``z0``)."""
    org = np.column_stack([xy, np.full(len(xy), z0)])
    dirs = np.tile([0.0, 0.0, -1.0], (len(xy), 1))
    t, prim, _ = world.tracer.cast(org.astype(np.float32), dirs.astype(np.float32))
    lab = np.where(prim >= 0, world.tracer.face_labels[np.maximum(prim, 0)], cs.IGNORE)
    return z0 - t, lab


def _clear(world: World, p: np.ndarray, radius: float) -> bool:
    """True when no surface lies within ``radius`` metres of ``p`` (3,) horizontally (16 rays)."""
    a = np.linspace(0, 2 * math.pi, 16, endpoint=False)
    dirs = np.column_stack([np.cos(a), np.sin(a), np.zeros(16)])
    t, _, _ = world.tracer.cast(np.tile(p, (16, 1)).astype(np.float32), dirs.astype(np.float32))
    return bool(np.all(t > radius))


# ----------------------------------------------------------------------------- the kinds
def spinning(world: World, rng: np.random.Generator, density: float = 1.0, surfaces: bool = False,
             materials: bool = False) -> dict:
    """One 360-degree sweep of an HDL-64E-like sensor on a car standing in a lane at a random place.

    ``density`` scales the ray count: the beam count follows ``64 * sqrt(density)`` (16 to 128 beams over the
    same -24.9..+2 degree fan) and the azimuth step the rest. Returns :func:`trace`'s dict plus ``origin``
    (1, 3), ``sensor`` (n,) uint16 zeros and ``ring`` (n,) uint8 beam index (0 = highest)."""
    d = world.scene.dims
    H = d.half_m
    height = float(rng.uniform(1.6, 2.0))
    for _ in range(200):
        if rng.random() < 0.7:  # main road lanes
            lane = float(rng.choice([-1.5, -0.5, 0.5, 1.5])) * d.lane_m + rng.normal(0, 0.2)
            xy = np.array([rng.uniform(-H + 4, H - 4), lane])
            yaw = (0.0 if lane < 0 else math.pi)
        else:  # side street
            lane = float(rng.choice([-0.5, 0.5])) * d.lane_m + rng.normal(0, 0.2)
            xy = np.array([lane, rng.uniform(-H + 4, H - 4)])
            yaw = -math.pi / 2 if lane < 0 else math.pi / 2
        zg, lab = _ground_at(world, xy[None])
        if lab[0] != cs.ROAD or abs(zg[0]) > 0.05:
            continue
        o = np.array([xy[0], xy[1], zg[0] + height])
        if _clear(world, np.array([xy[0], xy[1], zg[0] + 0.8]), 2.6) and _clear(world, o, 1.5):
            break
    R = _rot(yaw + rng.normal(0, 0.05), math.radians(rng.normal(0, 0.7)), math.radians(rng.normal(0, 0.7)))
    sensor = draw_sensor(rng, rng.uniform(80.0, 120.0), surfaces, materials)
    step0 = float(rng.uniform(0.08, 0.17))
    n_beams = int(np.clip(round(64 * math.sqrt(density)), 16, 128))
    elev = np.interp(np.linspace(0, 63, n_beams), np.arange(64), HDL64_ELEVATIONS)
    elev = elev + rng.normal(0, 0.05, n_beams)  # per-beam calibration error
    step = step0 / (density / (n_beams / 64.0))
    n_az = int(round(360.0 / step))
    az = np.arange(n_az) * (2 * math.pi / n_az) + rng.uniform(0, 2 * math.pi / n_az)
    el = np.radians(elev)
    ring = np.repeat(np.arange(n_beams), n_az)
    A = np.tile(az, n_beams) + rng.normal(0, 0.0005, n_beams * n_az)
    E = el[ring]
    local = np.column_stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)])
    dirs = local @ R.T
    org = np.tile(o, (len(dirs), 1))
    out = trace(world, sensor, org, dirs, rng)
    out["ring"] = ring[out["keep"]].astype(np.uint8)
    out["origin"] = o[None].astype(np.float64)
    out["sensor"] = np.zeros(len(out["keep"]), np.uint16)
    out["meta"] = {"height_m": height, "beams": n_beams, "azimuth_step_deg": 360.0 / n_az,
                   "yaw_deg": math.degrees(yaw), **sensor_meta(sensor)}
    return out


def tls(world: World, rng: np.random.Generator, density: float = 1.0, surfaces: bool = False,
        materials: bool = False) -> dict:
    """Two to five terrestrial tripod stations (1.5-1.8 m) on sidewalks and corners, each a panorama from -60 to +90
    degrees elevation; the angular step gives ``0.12 m / sqrt(density)`` point spacing at 10 m."""
    d = world.scene.dims
    H = d.half_m
    k = int(rng.integers(2, 6))
    stations: list[np.ndarray] = []
    for _ in range(400):
        if len(stations) == k:
            break
        u = rng.random()
        if u < 0.35:  # a corner
            xy = np.array([rng.choice([-1, 1]) * rng.uniform(d.rs + 0.8, d.bs - 0.4),
                           rng.choice([-1, 1]) * rng.uniform(d.rm + 0.8, d.bm - 0.4)])
        elif u < 0.8:  # a main-road sidewalk
            xy = np.array([rng.uniform(-H + 3, H - 3), rng.choice([-1, 1]) * rng.uniform(d.rm + 0.8, d.bm - 0.4)])
        else:  # a side-street sidewalk
            xy = np.array([rng.choice([-1, 1]) * rng.uniform(d.rs + 0.8, d.bs - 0.4), rng.uniform(-H + 3, H - 3)])
        zg, lab = _ground_at(world, xy[None])
        if lab[0] not in (cs.SIDEWALK, cs.TERRAIN):
            continue
        o = np.array([xy[0], xy[1], zg[0] + rng.uniform(1.5, 1.8)])
        if any(np.hypot(*(o[:2] - s[:2])) < 8.0 for s in stations) or not _clear(world, o, 0.6):
            continue
        if not _clear(world, np.array([o[0], o[1], zg[0] + 0.5]), 0.5):
            continue
        stations.append(o)
    sensor = draw_sensor(rng, rng.uniform(120.0, 250.0), surfaces, materials)
    yaws = rng.uniform(0, 2 * math.pi, len(stations))
    step = math.atan(0.12 / math.sqrt(density) / 10.0)
    az = np.arange(0, 2 * math.pi, step)
    el = np.arange(math.radians(-60), math.radians(90), step)
    A, E = np.meshgrid(az, el)
    local = np.column_stack([(np.cos(E) * np.cos(A)).ravel(), (np.cos(E) * np.sin(A)).ravel(), np.sin(E).ravel()])
    parts = []
    for si, o in enumerate(stations):
        dirs = local @ _rot(yaws[si]).T
        r = trace(world, sensor, np.tile(o, (len(dirs), 1)), dirs, rng)
        r["sensor"] = np.full(len(r["keep"]), si, np.uint16)
        parts.append(r)
    out = _concat(parts)
    out["origin"] = np.asarray(stations, np.float64).reshape(-1, 3)
    out["meta"] = {"stations": len(stations), "angular_step_deg": math.degrees(step), **sensor_meta(sensor)}
    return out


def mobile(world: World, rng: np.random.Generator, density: float = 1.0, surfaces: bool = False,
           materials: bool = False) -> dict:
    """The demo's push-broom van (:mod:`twinkit_demo_site.scanner`) over its first pass and a random subset of the
    others, at the small preset's sampling times ``density`` (profile spacing / sqrt, rays per profile x sqrt);
    the van's own points, re-noised and re-detected with this capture's sensor model, intensity recomputed.
    Origins are the van positions (the ``sensor`` index per point)."""
    import copy

    from twinkit_demo_site.plugin import PRESETS
    from twinkit_demo_site.scanner import ScanSettings, scan, trajectory

    pre = PRESETS["small"]  # the small preset's sampling on every size (the large one's is ~100x the rays)
    f = math.sqrt(max(density, 1e-3))
    sensor = draw_sensor(rng, rng.uniform(60.0, 100.0), surfaces, materials)
    st = ScanSettings(profile_spacing_m=pre["profile_spacing_m"] / f, rays_per_profile=int(round(pre["rays_per_profile"] * f)),
                      scanner_height_m=float(rng.uniform(1.9, 2.6)), noise_mm=0.0, max_range_m=sensor.max_range_m,
                      shadows=False)
    scene = copy.copy(world.scene)
    passes = world.scene.scan_passes
    chosen = [0] + [i for i in range(1, len(passes)) if rng.random() < 0.5]
    scene.scan_passes = [passes[i] for i in chosen]
    traj = trajectory(scene, st, rng)
    xyz, sid = [], []
    for ch in scan(scene, world.tracer, st, traj, rng):
        xyz.append(ch.xyz)
        sid.append(ch.scanner)
    p = np.concatenate(xyz)
    s = np.concatenate(sid).astype(np.int64)
    org = traj["xyz"][s]
    v = p - org
    t = np.linalg.norm(v, axis=1)
    dirs = v / np.maximum(t, 1e-9)[:, None]
    out = trace(world, sensor, org, dirs, rng)  # the same rays again, through this capture's sensor model
    out["sensor"] = s[out["keep"]].astype(np.uint32)
    out["origin"] = traj["xyz"].astype(np.float64)
    out["meta"] = {"passes": chosen, "profile_spacing_m": st.profile_spacing_m, "rays_per_profile": st.rays_per_profile,
                   "height_m": st.scanner_height_m, **sensor_meta(sensor)}
    return out


def aerial(world: World, rng: np.random.Generator, density: float = 1.0, surfaces: bool = False,
           materials: bool = False) -> dict:
    """Airborne laser strips over the site: altitude 300-900 m, zigzag mirror swath +-20 degrees, 5-50 points/m^2
    on the ground times ``density`` (as many as 500 on a dense draw), a random heading; a share of the rays that
    hit vegetation also gives a return from below the canopy; returns at incidence cosines below 0.12-0.3 are lost
    (few facade points). Points are kept within the site square."""
    d = world.scene.dims
    H = d.half_m
    alt = float(rng.uniform(300.0, 900.0))
    rho = float(np.exp(rng.uniform(np.log(5.0), np.log(50.0)))) * density
    half_swath = math.radians(20.0)
    width = 2 * alt * math.tan(half_swath)
    sp = 1.0 / math.sqrt(rho)
    heading = rng.uniform(0, 2 * math.pi)
    R = _rot(heading)
    sensor = draw_sensor(rng, alt * 1.3, surfaces, materials)
    sensor.cos_min = float(rng.uniform(0.12, 0.3))  # facades seen edge-on from above give few returns
    under = float(rng.uniform(0.2, 0.5))
    L = math.sqrt(2) * H + 5.0
    n_lines = int(2 * L / sp)
    n_across = int(width / sp)
    # strip centre offset across track so that the site lies inside the swath
    off = float(rng.uniform(-(width / 2 - L), width / 2 - L)) if width / 2 > L else 0.0
    along = -L + (np.arange(n_lines) + rng.uniform(0, 1)) * sp
    frac = (np.arange(n_across) + 0.5) / n_across
    ang = (2 * frac - 1) * half_swath
    ang = np.where((np.arange(n_lines) % 2 == 0)[:, None], ang[None, :], ang[::-1][None, :])  # zigzag
    ang = ang + rng.normal(0, 0.0002, ang.shape)
    pos_along = np.repeat(along, n_across) + np.tile(np.linspace(0, sp, n_across), n_lines)
    local_org = np.column_stack([pos_along, np.full(len(pos_along), off), np.full(len(pos_along), alt)])
    local_dir = np.column_stack([np.zeros(len(pos_along)), -np.sin(ang.ravel()), -np.cos(ang.ravel())])
    # keep only rays whose ground footprint falls on the site
    foot = local_org[:, :2] + local_dir[:, :2] * (alt / -local_dir[:, 2:3])
    fw = foot @ R[:2, :2].T
    on = (np.abs(fw[:, 0]) < H) & (np.abs(fw[:, 1]) < H)
    org = local_org[on] @ R.T
    dirs = local_dir[on] @ R.T
    out = trace(world, sensor, org, dirs, rng, ref_range_m=alt)
    veg = np.flatnonzero(out["label"] == cs.VEGETATION)
    veg = veg[rng.random(len(veg)) < under]
    parts = [out]
    if len(veg):
        ri = out["keep"][veg]
        o2 = out["xyz"][veg] + dirs[ri] * 0.3
        sub = trace(world, sensor, o2, dirs[ri], rng, ref_range_m=alt)
        sub["keep"] = ri[sub["keep"]]
        parts.append(sub)
    out = _concat(parts)
    inside = (np.abs(out["xyz"][:, 0]) < H) & (np.abs(out["xyz"][:, 1]) < H)
    out = _take(out, np.flatnonzero(inside))
    out["sensor"] = np.zeros(len(out["label"]), np.uint16)
    out["origin"] = (np.array([[0.0, off, alt]]) @ R.T).astype(np.float64)
    out["meta"] = {"altitude_m": alt, "ground_density_per_m2": rho, "heading_deg": math.degrees(heading),
                   **sensor_meta(sensor)}
    return out


def _concat(parts: list[dict]) -> dict:
    keys = [k for k in parts[0] if isinstance(parts[0][k], np.ndarray)]
    return {k: np.concatenate([p[k] for p in parts]) for k in keys}


def _take(out: dict, idx: np.ndarray) -> dict:
    n = len(out["label"])
    return {k: (v[idx] if isinstance(v, np.ndarray) and len(v) == n else v) for k, v in out.items()}


# ----------------------------------------------------------------------------- the API
_WORLDS: dict[tuple[int, str, bool, bool], World] = {}


def simulate_capture(seed: int, kind: str, rng_seed: int, density: float = 1.0, size: str = "small",
                     max_points: int = MAX_POINTS, world: World | None = None, variety: bool = True,
                     surfaces: bool = False, tall_hedges: bool = False, materials: bool = False) -> dict:
    """Simulate one capture of the demo site ``seed`` (``size`` a plugin.PRESETS name; ``variety``, ``tall_hedges``:
    see :func:`build_world`; ``world``: a prebuilt one, which then replaces these four) of ``kind`` (one of
    :data:`KINDS`), every random draw (pose, sensor, noise) from ``rng_seed``; the same arguments give the same
    capture. ``surfaces``, ``materials``: see :func:`twinkit_demo_site.sensor.draw_sensor`. ``density`` scales
    the point count (about linearly, 0.1-10); at most ``max_points`` points are kept
    (a uniform random subsample).

    Returns ``xyz`` (n, 3) float32 site frame (metres, z up), ``label`` (n,) uint8 CityScapes trainId (255 =
    unlabelled), ``intensity`` (n,) float32 0..1 (a rough model, see the module doc), ``origin`` (k, 3) float64 the
    sensor positions, ``sensor`` (n,) int64 index into ``origin`` per point, ``ring`` (n,) uint8 beam index
    (spinning only; 255 elsewhere), ``meta`` dict of the draws, ``kind``, ``seed``, ``rng_seed``, ``density``,
    ``raw_points`` (count before the subsample)."""
    if kind not in KINDS:
        raise ValueError(f"unknown capture kind {kind!r}; choose one of {', '.join(KINDS)}")
    if world is None:
        key = (int(seed), size, bool(variety), bool(tall_hedges))
        if key not in _WORLDS:
            _WORLDS.clear()
            _WORLDS[key] = build_world(seed, size, variety, tall_hedges=tall_hedges)
        world = _WORLDS[key]
    rng = np.random.default_rng([int(seed), int(rng_seed), KINDS.index(kind), 44])
    if kind == "spinning":
        out = spinning(world, rng, density, surfaces, materials)
    elif kind == "tls":
        out = tls(world, rng, density, surfaces, materials)
    elif kind == "mobile":
        out = mobile(world, rng, density, surfaces, materials)
    else:
        out = aerial(world, rng, density, surfaces, materials)
    n = len(out["label"])
    idx = np.arange(n)
    if n > max_points:
        idx = np.sort(rng.choice(n, max_points, replace=False))
    ring = out["ring"][idx] if "ring" in out else np.full(len(idx), 255, np.uint8)
    return {"xyz": out["xyz"][idx].astype(np.float32), "label": out["label"][idx].astype(np.uint8),
            "intensity": out["intensity"][idx].astype(np.float32), "origin": out["origin"],
            "sensor": out["sensor"][idx].astype(np.int64), "ring": ring, "meta": out["meta"], "kind": kind,
            "seed": int(seed), "rng_seed": int(rng_seed), "density": float(density), "raw_points": int(n)}


def class_counts(label: np.ndarray) -> dict[str, int]:
    """Point count per class name (255 -> "255") of a label array."""
    v, c = np.unique(label, return_counts=True)
    return {cs.name_of(int(a)): int(b) for a, b in zip(v, c)}


def _seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        if "-" in part:
            a, b = part.split("-")
            out += list(range(int(a), int(b) + 1))
        elif part:
            out.append(int(part))
    return out


def main(argv: list[str] | None = None) -> None:
    """``python -m twinkit_demo_site.captures --out DIR --seeds 100-139 --kinds spinning,tls,mobile,aerial``: one
    compressed npz per (seed, kind, variant) plus ``manifest.json``."""
    from twinkit.progress import track

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--seeds", default="100-109", help="site seeds, e.g. 100-139 or 100,105")
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--variants", type=int, default=1, help="captures per (seed, kind), each another pose and draw")
    ap.add_argument("--size", default="large", help="demo preset (small, default, large)")
    ap.add_argument("--density-min", type=float, default=0.3, help="density factors are drawn log-uniform in min..max")
    ap.add_argument("--density-max", type=float, default=3.0)
    ap.add_argument("--max-points", type=int, default=MAX_POINTS)
    ap.add_argument("--no-variety", action="store_true", help="the demo's own layout (no random layout knobs)")
    ap.add_argument("--surfaces", action="store_true", help="move returns into foliage, behind window panes and over "
                                                            "facade relief (surface_depth; the shipped model's spinning "
                                                            "sweeps have it, its other captures not)")
    ap.add_argument("--tall-hedges", action="store_true", help="front-garden hedges 0.6-3 m high (the shipped model's "
                                                               "spinning sweeps have them, its other captures not)")
    ap.add_argument("--materials", action="store_true", help="intensity from a reflectance per material (asphalt dark, "
                                                             "concrete paving lighter, grass and foliage bright; a "
                                                             "quarter of the sites with asphalt pavements; "
                                                             "sensor.draw_sensor; opt-in: docs/segmentation.md, m18)")
    a = ap.parse_args(argv)
    kinds = [k for k in a.kinds.split(",") if k]
    a.out.mkdir(parents=True, exist_ok=True)
    man_path = a.out / "manifest.json"
    manifest = json.loads(man_path.read_text()) if man_path.exists() else {"captures": []}
    done = {c["file"] for c in manifest["captures"]}
    jobs = [(s, k, v) for s in _seeds(a.seeds) for v in range(a.variants) for k in kinds]
    for s, k, v in track(jobs, total=len(jobs), desc="captures"):
        name = f"seed{s:04d}_{k}_v{v}.npz"
        if name in done:
            continue
        t0 = time.perf_counter()
        rs = v * 1000 + s
        dens = round(float(np.exp(np.random.default_rng([s, v, KINDS.index(k), 7]).uniform(
            np.log(a.density_min), np.log(a.density_max)))), 4)  # as the manifest records it, so that it reproduces
        c = simulate_capture(s, k, rs, density=dens, size=a.size, max_points=a.max_points, variety=not a.no_variety,
                                 surfaces=a.surfaces, tall_hedges=a.tall_hedges, materials=a.materials)
        np.savez_compressed(a.out / name, xyz=c["xyz"], label=c["label"], intensity=c["intensity"], origin=c["origin"],
                            sensor=c["sensor"].astype(np.uint32), ring=c["ring"])
        dt = time.perf_counter() - t0
        manifest["captures"].append({"file": name, "seed": s, "kind": k, "variant": v, "rng_seed": rs, "size": a.size,
                                     "variety": not a.no_variety, "surfaces": a.surfaces,
                                     "tall_hedges": a.tall_hedges, "materials": a.materials,
                                     "density": round(dens, 4), "points": int(len(c["label"])), "raw_points": c["raw_points"],
                                     "seconds": round(dt, 2), "counts": class_counts(c["label"]),
                                     "meta": {kk: (round(vv, 5) if isinstance(vv, float) else vv) for kk, vv in c["meta"].items()}})
        man_path.write_text(json.dumps(manifest, indent=1))
        print(f"{name}: {len(c['label'])} points ({c['raw_points']} raw), density {dens:.2f}, {dt:.1f} s", flush=True)


if __name__ == "__main__":
    main()

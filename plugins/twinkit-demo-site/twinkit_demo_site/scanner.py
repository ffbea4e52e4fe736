"""Mobile-mapping simulation: a car with two rotating profile scanners drives the lanes.

Each trajectory position fires one 360-degree profile per scanner head. The two
heads' scan planes contain the vertical and are turned +-45 degrees from the
driving direction (the "butterfly" layout of survey vans), so facades along and
across the street are both seen. Rays steeper than ~60 degrees downwards are
blocked by the van's roof. Hits give the label (hit face), colour (texture x
sun light x shadow), normal (hit face, turned towards the scanner) and intensity (the hit material's
near-infrared reflectance, not its colour: sensor.material_intensity); ranges
get Gaussian noise (clipped at 3 sigma) and returns thin out with range.
A pedestrian walking over the west crossing while the first pass goes by adds
"ghost" points (label 11, person) that exist in no other pass.

Points whose noisy position is nearer to a face of another label than the
face that was hit (a few millimetres from a label boundary) are dropped, so
every point's label is the label of its nearest ground-truth face.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twinkit_demo_site.layout import LABELS, Scene
from twinkit_demo_site.raycast import Tracer
from twinkit_demo_site.sensor import material_intensity, texture_modulation

PERSON_COLOURS = np.array([[0.15, 0.18, 0.35], [0.55, 0.12, 0.1], [0.2, 0.2, 0.2]], np.float32)


@dataclass
class ScanSettings:
    profile_spacing_m: float
    rays_per_profile: int
    scanner_height_m: float = 2.0
    speed_mps: float = 6.0
    noise_mm: float = 3.0
    max_range_m: float = 80.0
    shadows: bool = True
    weathered: bool = False  # colour the points with the tracer's weathering too (off: the plain atlas)


@dataclass
class ScanChunk:
    """One block of points. xyz (n, 3) float64 site frame; normals (n, 3) float32; rgb (n, 3) uint8;
    label (n,) uint8; scanner (n,) uint32 index into the scanner positions; intensity (n,) uint16."""

    xyz: np.ndarray
    normals: np.ndarray
    rgb: np.ndarray
    label: np.ndarray
    scanner: np.ndarray
    intensity: np.ndarray


def trajectory(scene: Scene, s: ScanSettings, rng: np.random.Generator) -> dict:
    """Scanner positions along the passes: xyz (k, 3), heading (k,), time_s (k,), pass (k,)."""
    pos, head, time, pas = [], [], [], []
    t0 = 0.0
    for pi, poly in enumerate(scene.scan_passes):
        seg = np.diff(poly, axis=0)
        lens = np.linalg.norm(seg, axis=1)
        total = lens.sum()
        n = int(total / s.profile_spacing_m)
        d = np.arange(n) * s.profile_spacing_m + rng.uniform(0, s.profile_spacing_m)
        cum = np.concatenate([[0], np.cumsum(lens)])
        k = np.clip(np.searchsorted(cum, d, side="right") - 1, 0, len(seg) - 1)
        f = (d - cum[k]) / lens[k]
        xy = poly[k] + seg[k] * f[:, None]
        # a slightly wavy, bumpy drive
        xy[:, :] += np.stack([-seg[k, 1], seg[k, 0]], 1) / lens[k, None] * (0.08 * np.sin(d / 7.0 + pi))[:, None]
        z = s.scanner_height_m + 0.01 * np.sin(d * 1.7) + 0.005 * rng.standard_normal(n)
        pos.append(np.column_stack([xy, z]))
        head.append(np.arctan2(seg[k, 1], seg[k, 0]))
        time.append(t0 + d / s.speed_mps)
        pas.append(np.full(n, pi))
        t0 = time[-1][-1] + 30.0
    return {"xyz": np.concatenate(pos), "heading": np.concatenate(head), "time_s": np.concatenate(time),
            "pass": np.concatenate(pas)}


def _person_hits(org, dirs, centre_xy, radius, height):
    """Ray / vertical cylinder (finite, with top cap ignored) intersection distance (inf = miss)."""
    ox = org[:, 0] - centre_xy[:, 0]
    oy = org[:, 1] - centre_xy[:, 1]
    a = dirs[:, 0] ** 2 + dirs[:, 1] ** 2
    b = 2 * (ox * dirs[:, 0] + oy * dirs[:, 1])
    c = ox ** 2 + oy ** 2 - radius ** 2
    disc = b * b - 4 * a * c
    t = np.full(len(org), np.inf)
    ok = (disc > 0) & (a > 1e-9)
    tt = (-b[ok] - np.sqrt(disc[ok])) / (2 * a[ok])
    z = org[ok, 2] + tt * dirs[ok, 2]
    good = (tt > 0) & (z > 0) & (z < height)
    idx = np.nonzero(ok)[0][good]
    t[idx] = tt[good]
    return t


def scan(scene: Scene, tracer: Tracer, s: ScanSettings, traj: dict, rng: np.random.Generator,
         chunk_profiles: int = 400, progress=None):
    """Yield :class:`ScanChunk` objects, one per block of ``chunk_profiles`` trajectory positions."""
    ped = scene.pedestrian
    P = len(traj["xyz"])
    # pedestrian timing: he steps onto the crossing when the first pass is 12 m before it
    m0 = traj["pass"] == ped["pass"]
    xs0 = traj["xyz"][m0, 0]
    t_cross = traj["time_s"][m0][np.argmin(np.abs(xs0 - (ped["x"] - 12.0)))]
    starts = list(range(0, P, chunk_profiles))
    mod = texture_modulation(tracer)
    it = progress(starts, total=len(starts), desc="scanning") if progress else starts
    for c0 in it:
        idx = np.arange(c0, min(P, c0 + chunk_profiles))
        org, dirs, sid = _profile_rays(s, traj, idx, rng)
        t, prim, bary = tracer.cast(org.astype(np.float32), dirs.astype(np.float32))
        t = t.astype(np.float64)
        hit = (prim >= 0) & (t < s.max_range_m)
        # returns thin out with range (weak far returns)
        u = rng.random(len(t))
        hit &= u < 1.0 - 0.55 * np.clip(t / s.max_range_m, 0, 1) ** 1.5
        ghost, t_person = _pedestrian_hits(ped, traj["time_s"][sid], t_cross, org, dirs, t, hit)
        sel = np.nonzero(hit | ghost)[0]
        g = ghost[sel]
        tr = np.where(g, t_person[sel], t[sel])
        noise = np.clip(rng.standard_normal(len(sel)), -3, 3) * (s.noise_mm / 1000.0)
        pts = org[sel] + dirs[sel] * (tr + noise)[:, None]
        # surface part
        ps = ~g
        prim_s = prim[sel][ps]
        nrm = np.empty((len(sel), 3), np.float32)
        col = np.empty((len(sel), 3), np.float32)
        lab = np.empty(len(sel), np.uint8)
        nrm[ps] = tracer.facing_normals(prim_s, dirs[sel][ps].astype(np.float32))
        exact = (org[sel][ps] + dirs[sel][ps] * t[sel][ps, None]).astype(np.float32)
        alb = tracer.albedo(prim_s, bary[sel][ps], exact if s.weathered else None)
        col[ps] = tracer.shade(exact, nrm[ps], alb, shadows=s.shadows)
        lab[ps] = tracer.face_labels[prim_s]
        if g.any():
            _ghost_points(ped, pts, dirs[sel], np.nonzero(g)[0], nrm, col, lab, rng)
        # drop surface points whose nearest face carries another label (mm from a label boundary)
        keep = np.ones(len(sel), bool)
        if ps.any():
            near = tracer.closest_faces(pts[ps])
            keep[np.nonzero(ps)[0]] = tracer.face_labels[near] == lab[ps]
        # a lidar's intensity is its surfaces' near-infrared reflectance, not their visible colour
        cos = np.abs(np.einsum("ij,ij->i", nrm, dirs[sel]))
        tex = np.ones(len(sel), np.float32)
        tex[ps] = mod[prim_s]
        intensity = material_intensity(lab, cos, tex, tr, s.max_range_m) * 65535
        col8 = np.clip(col * 255 + rng.uniform(-4, 4, col.shape) + 0.5, 0, 255).astype(np.uint8)
        k = keep
        yield ScanChunk(xyz=pts[k], normals=nrm[k], rgb=col8[k], label=lab[k], scanner=sid[sel][k].astype(np.uint32),
                        intensity=intensity[k].astype(np.uint16))


def _profile_rays(s: ScanSettings, traj: dict, idx: np.ndarray, rng: np.random.Generator):
    """The rays both heads fire at trajectory positions ``idx``: origins (k, 3) and unit directions (k, 3) float64,
    and the position index (k,) of each; one profile per head and position, with a random phase."""
    R = int(s.rays_per_profile)
    heads = (math.radians(45.0), math.radians(-45.0))
    xyz, head = traj["xyz"][idx], traj["heading"][idx]
    org_list, dir_list, sid_list = [], [], []
    for h_off in heads:
        # the scan plane contains z and w; its normal is the driving direction turned by h_off
        w_yaw = head + h_off + math.pi / 2
        w = np.stack([np.cos(w_yaw), np.sin(w_yaw), np.zeros_like(head)], 1)
        phase = rng.uniform(0, 2 * math.pi / R, len(idx))
        th = phase[:, None] + np.arange(R)[None, :] * (2 * math.pi / R)
        keep = np.sin(th) > -0.86  # the van's roof blocks steep downward rays
        ct, stt = np.cos(th), np.sin(th)
        d = w[:, None, :] * ct[..., None] + np.array([0, 0, 1.0]) * stt[..., None]
        d = d[keep]
        o = np.broadcast_to(xyz[:, None, :], (len(idx), R, 3))[keep]
        sid = np.broadcast_to(idx[:, None], (len(idx), R))[keep]
        org_list.append(o)
        dir_list.append(d)
        sid_list.append(sid)
    org = np.concatenate(org_list).astype(np.float64)
    dirs = np.concatenate(dir_list).astype(np.float64)
    sid = np.concatenate(sid_list)
    return org, dirs, sid


def _pedestrian_hits(ped: dict, ptime: np.ndarray, t_cross: float, org, dirs, t, hit):
    """Which rays (fired at times ``ptime``) hit the pedestrian walking over the crossing before the surface:
    ``ghost`` (k,) bool and the range to him ``t_person`` (k,) (inf elsewhere)."""
    walking = (ptime > t_cross) & (ptime < t_cross + 14.0 / ped["speed_mps"])
    ghost = np.zeros(len(t), bool)
    t_person = np.full(len(t), np.inf)
    if walking.any():
        w_idx = np.nonzero(walking)[0]
        cy = ped["y0"] + (ptime[w_idx] - t_cross) * ped["speed_mps"]
        cxy = np.stack([np.full(len(w_idx), ped["x"]), cy], 1)
        tp = _person_hits(org[w_idx], dirs[w_idx], cxy, ped["radius_m"], ped["height_m"])
        closer = tp < np.where(hit[w_idx], t[w_idx], np.inf)
        ghost[w_idx[closer]] = True
        t_person[w_idx[closer]] = tp[closer]
    return ghost, t_person


def _ghost_points(ped: dict, pts, dirs, gi, nrm, col, lab, rng: np.random.Generator) -> None:
    """Fill the normals, colours and label of the pedestrian's points ``gi`` (in place): horizontal normals facing
    the scanner, clothes coloured by height."""
    n3 = -dirs[gi].astype(np.float32)
    n3[:, 2] = 0
    n3 /= np.linalg.norm(n3, axis=1, keepdims=True) + 1e-9
    nrm[gi] = n3
    zrel = pts[gi, 2] / ped["height_m"]
    part = np.where(zrel > 0.85, 2, np.where(zrel > 0.5, 0, 1))
    col[gi] = PERSON_COLOURS[part] * (0.7 + 0.3 * rng.random((len(gi), 1))).astype(np.float32)
    lab[gi] = LABELS["person"]

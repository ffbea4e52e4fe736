"""The things placed on the demo site, each built into a MeshBuilder in the site frame (metres, z up):
buildings, fences, trees and bushes, street furniture (lamps, traffic lights, signs) and vehicles.

Every builder takes its base height ``z0`` (the sidewalk top or the road) and, where it is random, the
layout's generator ``rng`` (the call order fixes the site for a seed).
"""
from __future__ import annotations

import math

import numpy as np

from twinkit import cityscapes
from twinkit_demo_site.meshbuild import MeshBuilder

#: the CityScapes classes the demo site builds: name -> trainId (twinkit.cityscapes), in trainId order
LABELS = {name: cityscapes.ID[name] for name in (
    "road", "sidewalk", "building", "wall", "fence", "pole", "traffic light", "traffic sign", "vegetation",
    "terrain", "sky", "person", "car", "motorcycle", "bicycle")}
L = LABELS


def building(mb: MeshBuilder, x0, x1, y0, y1, z0, floors: int, variant: str, street_sides: set[str]) -> dict:
    fh = 3.2
    h = floors * fh
    sides = {  # name: (p0, eu, length)  (eu x z points outward)
        "-y": ([x0, y0, z0], [1, 0, 0], x1 - x0),
        "+x": ([x1, y0, z0], [0, 1, 0], y1 - y0),
        "+y": ([x1, y1, z0], [-1, 0, 0], x1 - x0),
        "-x": ([x0, y1, z0], [0, -1, 0], y1 - y0),
    }
    for name, (p0, eu, ln) in sides.items():
        bays = max(1, round(ln / 3.0))
        shop = name in street_sides

        def mat(i, j, shop=shop):
            if j == 0 and shop:
                return f"shop_{variant}"
            return f"facade_{variant}"

        mb.tiled_rect(p0, eu, [0, 0, 1], ln, h, "", L["building"], ln / bays, fh, material_fn=mat)
    # roof with a low parapet
    mb.tiled_rect([x0, y0, z0 + h], [1, 0, 0], [0, 1, 0], x1 - x0, y1 - y0, "roof", L["building"], 4.0, 4.0)
    return {"min": [x0, y0, z0], "max": [x1, y1, z0 + h], "floors": floors, "facade": variant}


def fence(mb: MeshBuilder, a, b, z0: float, height: float = 1.4) -> None:
    a, b = np.asarray(a, float), np.asarray(b, float)
    ln = float(np.linalg.norm(b - a))
    e = (b - a) / ln
    n = np.array([-e[1], e[0]])
    lab = L["fence"]

    def seg_box(p, q, w, zlo, zhi):
        lo = np.minimum(p, q) - w / 2
        hi = np.maximum(p, q) + w / 2
        mb.box([lo[0], lo[1], zlo], [hi[0], hi[1], zhi], lab, "fence")

    nposts = max(1, int(math.ceil(ln / 2.5)))
    for k in range(nposts + 1):
        p = a + e * ln * k / nposts
        seg_box(p, p, 0.07, z0, z0 + height + 0.05)
    seg_box(a, b, 0.045, z0 + height - 0.06, z0 + height - 0.015)
    seg_box(a, b, 0.045, z0 + 0.10, z0 + 0.145)
    nb = int(ln / 0.13)
    for k in range(1, nb):
        p = a + e * ln * k / nb
        if min(abs((ln * k / nb) - ln * kk / nposts) for kk in range(nposts + 1)) < 0.06:
            continue
        seg_box(p, p, 0.022, z0 + 0.145, z0 + height - 0.06)
    _ = n


def tree(mb: MeshBuilder, rng, x, y, z0, scale=1.0) -> None:
    r = rng.uniform(1.8, 2.6) * scale
    trunk_h = rng.uniform(2.5, 3.2)  # crowns start above head height
    cz = z0 + trunk_h + r * 0.9
    mb.cylinder([x, y, z0], [x, y, cz], 0.16 * scale, 0.11 * scale, L["vegetation"], "bark", segments=10, cap=False, v_period=4.0)
    mb.blob([x, y, cz], [r, r * rng.uniform(0.85, 1.1), r * 0.85], rng, L["vegetation"], "foliage", subdiv=3, roughness=0.15)


def bush(mb: MeshBuilder, rng, x, y, z0, height: float | None = None) -> None:
    """A bush about 0.6-1.1 m high, or one of a trimmed hedge's ``height`` (m, to its top)."""
    r = rng.uniform(0.55, 0.95)
    centre, axes = [x, y, z0 + r * 0.45], [r * 1.3, r, r * 0.7]
    if height:
        centre, axes = [x, y, z0 + 0.5 * height - 0.1], [r * 1.3, r, 0.5 * height + 0.1]
    mb.blob(centre, axes, rng, L["vegetation"], "hedge", subdiv=2, roughness=0.12, tex_size_m=1.2)


def lamp(mb: MeshBuilder, x, y, z0, towards) -> None:
    t = np.array([towards[0], towards[1], 0.0])
    top = np.array([x, y, z0 + 7.0])
    mb.cylinder([x, y, z0], top, 0.10, 0.06, L["pole"], "pole", segments=10, v_period=4.0)
    end = top + t * 1.6 + [0, 0, 0.2]
    mb.cylinder(top - [0, 0, 0.1], end, 0.045, 0.04, L["pole"], "pole", segments=8)
    c = end + t * 0.3
    yaw = math.atan2(t[1], t[0])
    mb.oriented_box(c, (0.7, 0.28, 0.14), yaw, L["pole"], "dark_metal", z0=c[2] - 0.1)


def traffic_light(mb: MeshBuilder, x, y, z0, facing) -> None:
    f = np.array([facing[0], facing[1]], float)
    mb.cylinder([x, y, z0], [x, y, z0 + 3.6], 0.075, 0.065, L["pole"], "pole", segments=10, v_period=4.0)
    c = np.array([x, y]) + f * (0.075 + 0.14)
    yaw = math.atan2(f[1], f[0])
    mats = {"front": "tl_front", "rear": "tl_housing", "left": "tl_housing", "right": "tl_housing", "top": "tl_housing"}
    # oriented_box 'front' is +length direction: length along facing
    mb.oriented_box(c, (0.26, 0.34, 0.95), yaw, L["traffic light"], mats, z0=z0 + 2.45)
    # a second, pedestrian head facing sideways (smaller)
    side = np.array([-f[1], f[0]])
    c2 = np.array([x, y]) + side * (0.075 + 0.12)
    mb.oriented_box(c2, (0.22, 0.26, 0.6), math.atan2(side[1], side[0]), L["traffic light"], mats, z0=z0 + 1.9)


SIGN_SHAPES = {
    "crossing": [(0, 0), (1, 0), (1, 1), (0, 1)],
    "no_entry": [(0.5 + 0.5 * math.cos(a), 0.5 + 0.5 * math.sin(a)) for a in np.linspace(0, 2 * np.pi, 17)[:-1]],
    "speed": [(0.5 + 0.5 * math.cos(a), 0.5 + 0.5 * math.sin(a)) for a in np.linspace(0, 2 * np.pi, 17)[:-1]],
    "stop": [(0.5 + 0.52 * math.cos(a), 0.5 + 0.52 * math.sin(a)) for a in np.linspace(np.pi / 8, 2 * np.pi + np.pi / 8, 9)[:-1]],
    "yield": [(0.0, 0.97), (0.5, 0.05), (1.0, 0.97)][::-1],
}


def sign(mb: MeshBuilder, x, y, z0, facing, kind: str, size=0.65) -> None:
    f = np.array([facing[0], facing[1], 0.0], float)
    top = z0 + 2.75
    mb.cylinder([x, y, z0], [x, y, top], 0.035, 0.035, L["pole"], "pole", segments=8)
    right = np.cross(-f, [0, 0, 1.0])
    centre = np.array([x, y, top - size / 2 - 0.02]) + f * (0.035 + 0.02)
    eu, ev = right * size, np.array([0, 0, size])
    shape = SIGN_SHAPES[kind]
    q = np.clip(np.array(shape), 0, 1)
    if kind == "yield":
        q = q[::-1]
    # keep the outline counter-clockwise seen from the front
    area = 0.5 * np.sum(q[:, 0] * np.roll(q[:, 1], -1) - np.roll(q[:, 0], -1) * q[:, 1])
    if area < 0:
        q = q[::-1]
    mb.prism(q, centre - eu / 2 - ev / 2, eu, ev, 0.02, L["traffic sign"], f"sign_{kind}", "sign_back")


def car(mb: MeshBuilder, rng, x, y, z0, yaw, paint: str) -> dict:
    Lc, Wc = rng.uniform(4.1, 4.6), rng.uniform(1.75, 1.85)
    c, s = math.cos(yaw), math.sin(yaw)
    fwd, left = np.array([c, s]), np.array([-s, c])
    p = f"car_{paint}"
    body = {"front": f"{p}_front", "rear": f"{p}_rear", "left": f"{p}_side", "right": f"{p}_side", "top": f"{p}_paint"}
    mb.oriented_box([x, y], (Lc, Wc, 0.62), yaw, L["car"], body, z0=z0 + 0.30)
    cab = {"front": f"{p}_window", "rear": f"{p}_window", "left": f"{p}_window", "right": f"{p}_window", "top": f"{p}_paint"}
    cc = np.array([x, y]) - fwd * Lc * 0.06
    mb.oriented_box(cc, (Lc * 0.55, Wc * 0.92, 0.55), yaw, L["car"], cab, z0=z0 + 0.92, top_scale=0.82)
    r = 0.33
    for a in (-1, 1):
        for b in (-1, 1):
            wc = np.array([x, y]) + fwd * a * (Lc / 2 - 0.8) + left * b * (Wc / 2 - 0.12)
            p0 = np.array([wc[0], wc[1], z0 + r]) - np.array([left[0], left[1], 0]) * 0.11
            p1 = p0 + np.array([left[0], left[1], 0]) * 0.22
            mb.cylinder(p0, p1, r, r, L["car"], "tire", segments=14)
    return {"center": [x, y], "yaw": yaw, "length": Lc, "width": Wc}


def bicycle(mb: MeshBuilder, x, y, z0, yaw) -> None:
    c, s = math.cos(yaw), math.sin(yaw)
    fwd, left = np.array([c, s, 0.0]), np.array([-s, c, 0.0])
    o = np.array([x, y, z0])

    def P(a, h, b=0.0):
        return o + fwd * a + left * b + np.array([0, 0, h])

    lab = L["bicycle"]
    for a in (-0.53, 0.53):
        mb.ring(P(a, 0.35), left, 0.33, 0.022, lab, "tire", segments=24)
        mb.cylinder(P(a, 0.35, -0.05), P(a, 0.35, 0.05), 0.03, 0.03, lab, "dark_metal", segments=6)
    tubes = [((-0.53, 0.35), (0.0, 0.3)), ((0.0, 0.3), (-0.12, 0.85)), ((-0.12, 0.85), (0.42, 0.85)),
             ((0.0, 0.3), (0.42, 0.8)), ((-0.53, 0.35), (-0.12, 0.85)), ((0.42, 0.85), (0.53, 0.35)),
             ((0.42, 0.85), (0.38, 1.02)), ((-0.12, 0.85), (-0.15, 0.98))]
    for (a0, h0), (a1, h1) in tubes:
        mb.cylinder(P(a0, h0), P(a1, h1), 0.02, 0.02, lab, "bike_frame", segments=6)
    mb.cylinder(P(0.38, 1.02, -0.28), P(0.38, 1.02, 0.28), 0.014, 0.014, lab, "dark_metal", segments=6)
    mb.oriented_box(P(-0.15, 0)[:2], (0.26, 0.12, 0.06), yaw, lab, "dark_metal", z0=z0 + 0.98)


def motorcycle(mb: MeshBuilder, x, y, z0, yaw) -> None:
    c, s = math.cos(yaw), math.sin(yaw)
    fwd, left = np.array([c, s, 0.0]), np.array([-s, c, 0.0])
    o = np.array([x, y, z0])
    lab = L["motorcycle"]

    def P(a, h, b=0.0):
        return o + fwd * a + left * b + np.array([0, 0, h])

    for a in (-0.72, 0.72):
        mb.ring(P(a, 0.31), left, 0.25, 0.07, lab, "tire", segments=20, tube_segments=8)
        mb.cylinder(P(a, 0.31, -0.06), P(a, 0.31, 0.06), 0.16, 0.16, lab, "dark_metal", segments=12)
    mb.oriented_box(P(0.0, 0)[:2], (0.75, 0.34, 0.32), yaw, lab, "dark_metal", z0=z0 + 0.30)  # engine
    mb.oriented_box(P(0.2, 0)[:2], (0.55, 0.36, 0.22), yaw, lab, "moto_body", z0=z0 + 0.68, top_scale=0.8)  # tank
    mb.oriented_box(P(-0.35, 0)[:2], (0.6, 0.3, 0.12), yaw, lab, "dark_metal", z0=z0 + 0.72)  # seat
    mb.oriented_box(P(-0.65, 0)[:2], (0.45, 0.22, 0.12), yaw, lab, "moto_body", z0=z0 + 0.62)  # tail
    mb.cylinder(P(0.72, 0.31), P(0.5, 1.0), 0.025, 0.025, lab, "pole", segments=6)  # fork
    mb.cylinder(P(0.5, 1.0, -0.35), P(0.5, 1.0, 0.35), 0.015, 0.015, lab, "dark_metal", segments=6)
    mb.cylinder(P(-0.72, 0.31), P(-0.1, 0.45), 0.03, 0.03, lab, "pole", segments=6)  # swing arm
    mb.cylinder(P(-0.2, 0.25, -0.2), P(-0.9, 0.45, -0.2), 0.045, 0.04, lab, "pole", segments=8)  # exhaust

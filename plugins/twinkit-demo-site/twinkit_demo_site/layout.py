"""The demo intersection: layout, ground truth geometry and labels.

Site frame: metres, x east, y north, z up, origin at the site base point (the
centre of the junction, road surface at z = 0).

Layout (right-hand traffic, as in Finland):
- main road along x: 2 lanes each way (3.25 m) plus a 2.2 m parking strip each
  side; sidewalks 3.5 m, raised by the curb height (10-15 cm).
- side street along y: 2 lanes; the north arm is one-way southbound, the south
  arm two-way. Zebra crossings on all four arms, stop lines before them.
- four blocks: NE and NW rows of buildings (NW with a wall), SW a walled yard
  and a building, SE a fenced park with trees and bushes. Street lamps,
  traffic lights on the four corners, traffic signs, street trees, parked cars,
  a motorcycle and a bicycle.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from twinkit import cityscapes
from twinkit.mesh import Mesh
from twinkit_demo_site.meshbuild import MeshBuilder
from twinkit_demo_site.textures import CAR_PAINTS, FACADES, Atlas

#: the CityScapes classes the demo site builds: name -> trainId (twinkit.cityscapes), in trainId order
LABELS = {name: cityscapes.ID[name] for name in (
    "road", "sidewalk", "building", "wall", "fence", "pole", "traffic light", "traffic sign", "vegetation",
    "terrain", "sky", "person", "car", "motorcycle", "bicycle")}
L = LABELS

GROUND_KINDS = {  # kind -> (material, label, raised)
    "asphalt": ("asphalt", cityscapes.ROAD, False),
    "marking": ("marking", cityscapes.ROAD, False),
    "paving": ("paving", cityscapes.SIDEWALK, True),
    "curb": ("granite", cityscapes.SIDEWALK, True),
    "grass": ("grass", cityscapes.TERRAIN, True),
}
KIND_NAMES = ["none", *GROUND_KINDS]
GROUND_PERIOD_M = 4.0


@dataclass
class Dims:
    half_m: float  # site half size
    lane_m: float = 3.25
    park_m: float = 2.2
    sidewalk_m: float = 3.5
    curb_m: float = 0.12

    @property
    def main_traffic(self) -> float:  # half width of the main road's traffic lanes
        return 2 * self.lane_m

    @property
    def rm(self) -> float:  # main road half width (curb to centre)
        return self.main_traffic + self.park_m

    @property
    def rs(self) -> float:  # side street half width
        return self.lane_m

    @property
    def bm(self) -> float:  # block edge (back of sidewalk), main road
        return self.rm + self.sidewalk_m

    @property
    def bs(self) -> float:
        return self.rs + self.sidewalk_m


@dataclass
class Scene:
    mesh: Mesh
    atlas: Atlas
    dims: Dims
    buildings: list[dict] = field(default_factory=list)  # {"min": [x,y,z], "max": [...]} solids
    solids: list[dict] = field(default_factory=list)  # every box solid (buildings, walls, car bodies)
    roads_truth: dict = field(default_factory=dict)
    osm: dict = field(default_factory=dict)  # nodes/ways in the true site frame
    scan_passes: list[np.ndarray] = field(default_factory=list)  # (k, 2) polylines driven by the scanner car
    walk_path: np.ndarray | None = None  # (k, 2) polyline walked for photos
    gcp_points: list[dict] = field(default_factory=list)  # {"id", "xyz", "what"}: natural ground-control points
    pedestrian: dict = field(default_factory=dict)
    counts: dict = field(default_factory=dict)


# ---------------------------------------------------------------- ground
def _ground(mb: MeshBuilder, rects: list[tuple[str, float, float, float, float]], d: Dims) -> None:
    """Rasterise painter-ordered rectangles on the rectilinear grid of their edges; emit cells and curb faces."""
    H = d.half_m
    per = GROUND_PERIOD_M
    xs = {-H, H}
    ys = {-H, H}
    for _k, x0, x1, y0, y1 in rects:
        for v in (x0, x1):
            if -H < v < H:
                xs.add(round(v, 4))
        for v in (y0, y1):
            if -H < v < H:
                ys.add(round(v, 4))
    k = np.arange(math.ceil(-H / per), math.floor(H / per) + 1) * per
    xs |= {float(v) for v in k if -H < v < H}
    ys |= {float(v) for v in k if -H < v < H}
    xs = np.array(sorted(xs))
    ys = np.array(sorted(ys))
    cx = (xs[:-1] + xs[1:]) / 2
    cy = (ys[:-1] + ys[1:]) / 2
    kind = np.zeros((len(cy), len(cx)), np.int64)  # [j (y), i (x)]
    for name, x0, x1, y0, y1 in rects:
        mi = (cx > x0) & (cx < x1)
        mj = (cy > y0) & (cy < y1)
        kind[np.ix_(mj, mi)] = KIND_NAMES.index(name)
    raised = np.array([False] + [GROUND_KINDS[n][2] for n in KIND_NAMES[1:]])
    z = np.where(raised[kind], d.curb_m, 0.0)
    J, I = np.nonzero(kind)
    # horizontal cells, grouped by kind
    from twinkit_demo_site.meshbuild import MAX_ASPECT

    wx = (xs[1:] - xs[:-1])[I]
    wy = (ys[1:] - ys[:-1])[J]
    thin = (wx > MAX_ASPECT * wy) | (wy > MAX_ASPECT * wx)
    for j, i in zip(J[thin], I[thin]):  # sliver cells: cut by MeshBuilder.quad
        mat, lab, _ = GROUND_KINDS[KIND_NAMES[kind[j, i]]]
        x0, x1, y0, y1 = xs[i], xs[i + 1], ys[j], ys[j + 1]
        kx, ky = math.floor((x0 + x1) / 2 / per), math.floor((y0 + y1) / 2 / per)
        mb.quad([x0, y0, z[j, i]], [1, 0, 0], [0, 1, 0], x1 - x0, y1 - y0, mat, int(lab),
                (x0 / per - kx, y0 / per - ky), (x1 / per - kx, y1 / per - ky))
    J, I = J[~thin], I[~thin]
    for kid in np.unique(kind[J, I]):
        sel = kind[J, I] == kid
        j, i = J[sel], I[sel]
        x0, x1, y0, y1 = xs[i], xs[i + 1], ys[j], ys[j + 1]
        zz = z[j, i]
        n = len(i)
        verts = np.stack([
            np.stack([x0, y0, zz], 1), np.stack([x1, y0, zz], 1), np.stack([x1, y1, zz], 1), np.stack([x0, y1, zz], 1)
        ], 1).reshape(-1, 3)
        kx = np.floor(((x0 + x1) / 2) / per)
        ky = np.floor(((y0 + y1) / 2) / per)
        s0, s1 = x0 / per - kx, x1 / per - kx
        t0, t1 = y0 / per - ky, y1 / per - ky
        st = np.stack([np.stack([s0, t0], 1), np.stack([s1, t0], 1), np.stack([s1, t1], 1), np.stack([s0, t1], 1)], 1).reshape(-1, 2)
        base = np.arange(n)[:, None] * 4
        faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], 1).reshape(-1, 3)
        mat, lab, _ = GROUND_KINDS[KIND_NAMES[kid]]
        mb.add(verts, st, faces, mat, lab)
    # vertical curb faces between neighbours of different height (both cells present)
    lab_of = np.array([0] + [GROUND_KINDS[n][1] for n in KIND_NAMES[1:]])
    quads = []  # (p0, p1 bottom edge, zlo, zhi, label)
    for axis in (0, 1):
        if axis == 0:  # neighbours along x
            a, b = kind[:, :-1], kind[:, 1:]
            za, zb = z[:, :-1], z[:, 1:]
        else:
            a, b = kind[:-1, :], kind[1:, :]
            za, zb = z[:-1, :], z[1:, :]
        m = (a > 0) & (b > 0) & (np.abs(za - zb) > 1e-9)
        for j, i in zip(*np.nonzero(m)):
            hi_is_a = za[j, i] > zb[j, i]
            lab = lab_of[a[j, i] if hi_is_a else b[j, i]]
            if axis == 0:
                xe = xs[i + 1]
                p, q = np.array([xe, ys[j]]), np.array([xe, ys[j + 1]])
                # face must look towards the lower cell
                if not hi_is_a:
                    p, q = q, p
                else:
                    pass
            else:
                ye = ys[j + 1]
                p, q = np.array([xs[i + 1], ye]), np.array([xs[i], ye])
                if not hi_is_a:
                    p, q = q, p
            quads.append((p, q, 0.0, d.curb_m, lab))
    for p, q, z0, z1, lab in quads:
        eu = np.array([q[0] - p[0], q[1] - p[1], 0.0])
        ln = float(np.linalg.norm(eu))
        mb.quad([p[0], p[1], z0], eu / ln, [0, 0, 1.0], ln, z1 - z0, "granite", int(lab),
                (0.0, 0.0), (min(ln / per, 1.0), (z1 - z0) / per))


def _dashes(x_from: float, x_to: float, dash: float = 3.0, gap: float = 3.0):
    out = []
    x = x_from
    while x + dash <= x_to:
        out.append((x, x + dash))
        x += dash + gap
    return out


# ---------------------------------------------------------------- objects
def _building(mb: MeshBuilder, x0, x1, y0, y1, z0, floors: int, variant: str, street_sides: set[str]) -> dict:
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


def _fence(mb: MeshBuilder, a, b, z0: float, height: float = 1.4) -> None:
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


def _tree(mb: MeshBuilder, rng, x, y, z0, scale=1.0) -> None:
    r = rng.uniform(1.8, 2.6) * scale
    trunk_h = rng.uniform(2.5, 3.2)  # crowns start above head height
    cz = z0 + trunk_h + r * 0.9
    mb.cylinder([x, y, z0], [x, y, cz], 0.16 * scale, 0.11 * scale, L["vegetation"], "bark", segments=10, cap=False, v_period=4.0)
    mb.blob([x, y, cz], [r, r * rng.uniform(0.85, 1.1), r * 0.85], rng, L["vegetation"], "foliage", subdiv=3, roughness=0.15)


def _bush(mb: MeshBuilder, rng, x, y, z0) -> None:
    r = rng.uniform(0.55, 0.95)
    mb.blob([x, y, z0 + r * 0.45], [r * 1.3, r, r * 0.7], rng, L["vegetation"], "hedge", subdiv=2, roughness=0.12, tex_size_m=1.2)


def _lamp(mb: MeshBuilder, x, y, z0, towards) -> None:
    t = np.array([towards[0], towards[1], 0.0])
    top = np.array([x, y, z0 + 7.0])
    mb.cylinder([x, y, z0], top, 0.10, 0.06, L["pole"], "pole", segments=10, v_period=4.0)
    end = top + t * 1.6 + [0, 0, 0.2]
    mb.cylinder(top - [0, 0, 0.1], end, 0.045, 0.04, L["pole"], "pole", segments=8)
    c = end + t * 0.3
    yaw = math.atan2(t[1], t[0])
    mb.oriented_box(c, (0.7, 0.28, 0.14), yaw, L["pole"], "dark_metal", z0=c[2] - 0.1)


def _traffic_light(mb: MeshBuilder, x, y, z0, facing) -> None:
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


def _sign(mb: MeshBuilder, x, y, z0, facing, kind: str, size=0.65) -> None:
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


def _car(mb: MeshBuilder, rng, x, y, z0, yaw, paint: str) -> dict:
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


def _bicycle(mb: MeshBuilder, x, y, z0, yaw) -> None:
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


def _motorcycle(mb: MeshBuilder, x, y, z0, yaw) -> None:
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


# ---------------------------------------------------------------- the whole site
def build_scene(half_m: float, seed: int, atlas: Atlas) -> Scene:
    rng = np.random.default_rng([seed, 1])
    d = Dims(half_m=half_m, curb_m=round(float(rng.uniform(0.10, 0.15)), 3))
    H, rm, rs, bm, bs, cz = d.half_m, d.rm, d.rs, d.bm, d.bs, d.curb_m
    mb = MeshBuilder(atlas)
    scene = Scene(mesh=None, atlas=atlas, dims=d)  # type: ignore[arg-type]
    rects: list[tuple[str, float, float, float, float]] = []
    R = rects.append
    BIG = H + 1
    R(("grass", -BIG, BIG, -BIG, BIG))
    R(("asphalt", -BIG, BIG, -rm, rm))
    R(("asphalt", -rs, rs, -BIG, BIG))
    for sy in (-1, 1):
        R(("paving", -BIG, BIG, *sorted((sy * rm, sy * bm))))
        R(("curb", -BIG, BIG, *sorted((sy * rm, sy * (rm + 0.15)))))
    for sx in (-1, 1):
        R(("paving", *sorted((sx * rs, sx * bs)), -BIG, BIG))
        R(("curb", *sorted((sx * rs, sx * (rs + 0.15))), -BIG, BIG))
    R(("asphalt", -BIG, BIG, -rm, rm))  # road wins over the side-street sidewalks
    R(("asphalt", -rs, rs, -BIG, BIG))
    # zebra crossings
    zx0, zx1 = rs + 0.5, rs + 3.5  # across the main road, on both arms
    gcps = []  # natural ground-control points: the outer corners of each zebra's first and last stripe
    for sx in (-1, 1):
        y = -rm + 0.25
        stripes = []
        while y + 0.5 <= rm - 0.2:
            R(("marking", *sorted((sx * zx0, sx * zx1)), y, y + 0.5))
            stripes.append(y)
            y += 1.0
        gcps += [((sx * xx, yy), f"{'east' if sx > 0 else 'west'} zebra corner")
                 for yy in (stripes[0], stripes[-1] + 0.5) for xx in (zx0, zx1)]
    zy0, zy1 = rm + 0.5, rm + 3.5
    for sy in (-1, 1):
        x = -rs + 0.25
        stripes = []
        while x + 0.5 <= rs - 0.2:
            R(("marking", x, x + 0.5, *sorted((sy * zy0, sy * zy1))))
            stripes.append(x)
            x += 1.0
        gcps += [((xx, sy * yy), f"{'north' if sy > 0 else 'south'} zebra corner")
                 for xx in (stripes[0], stripes[-1] + 0.5) for yy in (zy0, zy1)]
    # (road level: the painted corners a surveyor measures and a user clicks in the photos)
    gcp_points = [{"id": f"Z{k + 1:02d}", "xyz": [float(x), float(y), 0.0], "what": w}
                  for k, ((x, y), w) in enumerate(gcps)]
    # stop lines (traffic towards the junction)
    sl_x = zx1 + 1.0
    R(("marking", sl_x, sl_x + 0.3, 0.0, d.main_traffic))            # east arm, westbound
    R(("marking", -sl_x - 0.3, -sl_x, -d.main_traffic, 0.0))          # west arm, eastbound
    sl_y = zy1 + 1.0
    R(("marking", -rs, rs, sl_y, sl_y + 0.3))                          # north arm, one-way southbound
    R(("marking", 0.0, rs, -sl_y - 0.3, -sl_y))                        # south arm, northbound lane
    # lane lines
    lw = 0.12
    x_start = sl_x + 0.3
    for sx in (-1, 1):
        for a, b in _dashes(x_start + 0.5, H + 3):
            for yl in (-d.lane_m, d.lane_m):
                R(("marking", *sorted((sx * a, sx * b)), yl - lw / 2, yl + lw / 2))
        # centre line: solid for 12 m, then dashed
        R(("marking", *sorted((sx * x_start, sx * (x_start + 12))), -lw / 2, lw / 2))
        for a, b in _dashes(x_start + 15, H + 3):
            R(("marking", *sorted((sx * a, sx * b)), -lw / 2, lw / 2))
        # parking strip edge lines
        for sy in (-1, 1):
            R(("marking", *sorted((sx * x_start, sx * (H + 1))), *sorted((sy * (d.main_traffic - 0.05), sy * (d.main_traffic + 0.05)))))
    y_start = sl_y + 0.3
    for a, b in _dashes(y_start + 0.5, H + 3):
        R(("marking", -lw / 2, lw / 2, a, b))             # north arm lane divider
    R(("marking", -lw / 2, lw / 2, -(y_start + 10), -y_start))
    for a, b in _dashes(y_start + 13, H + 3):
        R(("marking", -lw / 2, lw / 2, -b, -a))           # south arm centre line

    # ------------------------------------------------ blocks
    buildings: list[dict] = []
    walls: list[tuple] = []
    fences: list[tuple] = []
    trees: list[tuple] = []
    bushes: list[tuple] = []
    facade_names = list(FACADES)

    def row(sx, sy, x_from, x_to, depth_lo=10.5, depth_hi=13.0):
        """Buildings along the main-road frontage of block (sx, sy) between |x| = x_from..x_to."""
        x = x_from
        first = True
        while True:
            w = float(rng.uniform(11.0, 20.0))
            if x + w > x_to:
                w = x_to - x
                if w < 8.0:
                    break
            depth = float(rng.uniform(depth_lo, depth_hi))
            floors = int(rng.integers(3, 7))
            xa, xb = sorted((sx * x, sx * (x + w)))
            ya, yb = sorted((sy * bm, sy * (bm + depth)))
            street = {"-y" if sy > 0 else "+y"}
            if first and abs(x - bs) < 1e-6:
                street.add("-x" if sx > 0 else "+x")
            b = _building(mb, xa, xb, ya, yb, cz, floors, facade_names[int(rng.integers(len(facade_names)))], street)
            buildings.append(b)
            R(("none", xa, xb, ya, yb))
            x += w + float(rng.uniform(2.0, 3.5))
            first = False
            if x >= x_to - 8.0:
                break
        return buildings[-1]["max"][1] if sy > 0 else -buildings[-1]["min"][1]

    def side_row(sx, sy, y_from, y_to):
        """Buildings facing the side street in block (sx, sy) between |y| = y_from..y_to."""
        y = y_from
        while y_to - y >= 10.0:
            w = min(float(rng.uniform(11.0, 20.0)), y_to - y)
            if y_to - y - w < 8.0:
                w = y_to - y
            depth = float(rng.uniform(10.5, 13.0))
            floors = int(rng.integers(3, 7))
            xa, xb = sorted((sx * bs, sx * (bs + depth)))
            ya, yb = sorted((sy * y, sy * (y + w)))
            b = _building(mb, xa, xb, ya, yb, cz, floors, facade_names[int(rng.integers(len(facade_names)))],
                          {"-x" if sx > 0 else "+x"})
            buildings.append(b)
            R(("none", xa, xb, ya, yb))
            y += w + float(rng.uniform(2.0, 3.5))

    # NE: a row of buildings from the corner, more along the side street on big sites
    row(1, 1, bs, H - 0.5)
    depth_ne = max(b["max"][1] for b in buildings)
    side_row(1, 1, depth_ne + 3.0, H - 0.5)
    # NW: row from the corner; behind it buildings (big sites) or a wall along the side street
    n_before = len(buildings)
    row(-1, 1, bs, H - 0.5)
    depth_nw = max(b["max"][1] for b in buildings[n_before:])
    if H - 0.5 - (depth_nw + 3.0) >= 10.0:
        side_row(-1, 1, depth_nw + 3.0, H - 0.5)
    elif H - depth_nw > 4.0:
        walls.append((-bs - 0.3, -bs, depth_nw + 2.0, H - 0.3, 2.0))
    # SW: walled yard at the corner, then buildings
    yard_x = bs + 8.0
    wall_end = min(H - 0.3, bm + 18.0)
    walls.append((-bs - 0.25, -bs, -wall_end, -bm, 1.9))
    walls.append((-yard_x, -bs - 0.25, -bm - 0.25, -bm, 1.9))
    row(-1, -1, yard_x + 1.0, H - 0.5)
    side_row(-1, -1, wall_end + 3.0, H - 0.5)
    bushes += [(-bs - 2.0, -bm - 2.5), (-bs - 4.5, -bm - 1.6)]
    trees.append((-bs - 4.0, -bm - 5.5, 0.9))
    # SE: fenced park with trees and bushes
    fences.append(((bs + 0.15, -bm - 0.15), (H - 0.3, -bm - 0.15)))
    fences.append(((bs + 0.15, -(H - 0.3)), (bs + 0.15, -bm - 0.15)))
    tries = 0
    park_trees = []
    while tries < 400 and len(park_trees) < max(3, int((H - bs) * (H - bm) / 60)):
        tries += 1
        px, py = rng.uniform(bs + 3.5, H - 2.5), -rng.uniform(bm + 3.5, H - 2.5)
        if all(math.hypot(px - qx, py - qy) > 5.0 for qx, qy in park_trees):
            park_trees.append((px, py))
    trees += [(x, y, 1.0) for x, y in park_trees]
    xb_ = bs + 1.2
    while xb_ < H - 1.5:
        if rng.random() < 0.75:
            bushes.append((xb_, -bm - 1.1))
        xb_ += rng.uniform(1.6, 2.6)
    # street trees in grass pits on the south sidewalk in front of the park
    xt = bs + 7.5
    while xt < H - 2.0:
        R(("grass", xt - 0.7, xt + 0.7, -bm + 0.6, -bm + 2.0))
        trees.append((xt, -bm + 1.3, 0.8))
        xt += 9.0

    for (xa, xb, ya, yb, h) in walls:
        mb.box([xa, ya, cz], [xb, yb, cz + h], L["wall"], "concrete_wall", period=3.0)
        R(("none", xa, xb, ya, yb))
    for a, b in fences:
        _fence(mb, a, b, cz)
    for x, y, sc in trees:
        _tree(mb, rng, x, y, cz, sc)
    for x, y in bushes:
        _bush(mb, rng, x, y, cz)

    # ------------------------------------------------ street furniture
    lamp_y = rm + 0.55
    xl = 10.0
    while xl < H - 2.0:
        for sx in (-1, 1):
            _lamp(mb, sx * xl, lamp_y, cz, (0, -1))
        xl += 14.0
    xl = 17.0
    while xl < H - 2.0:
        _lamp(mb, -xl, -(rm + 0.35), cz, (0, 1))
        xl += 14.0
    c0 = 0.55
    _traffic_light(mb, rs + c0, rm + c0, cz, (1, 0))      # westbound approach (east arm)
    _traffic_light(mb, -rs - c0, -rm - c0, cz, (-1, 0))   # eastbound approach (west arm)
    _traffic_light(mb, -rs - c0, rm + c0, cz, (0, 1))     # southbound approach (north arm)
    _traffic_light(mb, rs + c0, -rm - c0, cz, (0, -1))    # northbound approach (south arm)
    _sign(mb, zx1 + 0.4, rm + 0.45, cz, (1, 0), "crossing")
    _sign(mb, -zx1 - 0.4, -rm - 0.45, cz, (-1, 0), "crossing")
    _sign(mb, -rs - 0.45, zy1 + 0.4, cz, (0, 1), "crossing")
    _sign(mb, rs + 0.45, -zy1 - 0.4, cz, (0, -1), "crossing")
    _sign(mb, rs + 0.45, zy0 - 0.1, cz, (0, -1), "no_entry")
    _sign(mb, rs + 0.45, -sl_y - 2.5, cz, (0, -1), "stop")
    _sign(mb, -(H - 5.0), -rm - 0.45, cz, (-1, 0), "speed")
    _sign(mb, -rs - 0.45, -sl_y - 2.5, cz, (0, 1), "yield")
    if H - 5.0 > 20:
        _sign(mb, H - 5.0, rm + 0.45, cz, (1, 0), "speed")

    # ------------------------------------------------ vehicles
    paints = list(CAR_PAINTS)
    cars = []
    slots = []
    xs_ = x_start + 4.0
    while xs_ + 2.4 < H - 0.5:
        for sx in (-1, 1):
            for sy in (-1, 1):
                slots.append((sx * xs_, sy, sx))
        xs_ += 6.2
    moto_slot = int(rng.integers(len(slots)))
    ypark = d.main_traffic + d.park_m / 2
    for k, (x, sy, _sx) in enumerate(slots):
        yaw = 0.0 if sy < 0 else math.pi
        if k == moto_slot:
            _motorcycle(mb, x, sy * ypark, 0.0, yaw + 0.25)
            continue
        if rng.random() < 0.65:
            cars.append(_car(mb, rng, x + rng.uniform(-0.4, 0.4), sy * (ypark + rng.uniform(-0.1, 0.1)), 0.0, yaw,
                             paints[int(rng.integers(len(paints)))]))
    # a car waiting at the north arm's stop line
    cars.append(_car(mb, rng, -d.lane_m / 2, sl_y + 0.3 + 0.6 + 2.3, 0.0, -math.pi / 2, paints[int(rng.integers(len(paints)))]))
    _bicycle(mb, bs + 6.0, bm - 0.6, cz, 0.0)

    _ground(mb, rects, d)
    scene.mesh = mb.finish()
    scene.buildings = buildings
    scene.solids = buildings + [{"min": [w[0], w[2], cz], "max": [w[1], w[3], cz + w[4]]} for w in walls]

    # ------------------------------------------------ truth for roads
    lane_lines = []
    for yl, dirn in ((-d.lane_m * 1.5, 1), (-d.lane_m * 0.5, 1), (d.lane_m * 0.5, -1), (d.lane_m * 1.5, -1)):
        xs_line = [-H, H] if dirn > 0 else [H, -H]
        lane_lines.append({"road": "main", "direction": "east" if dirn > 0 else "west",
                           "points": [[xs_line[0], yl, 0.0], [xs_line[1], yl, 0.0]]})
    for xl_ in (-d.lane_m / 2, d.lane_m / 2):
        lane_lines.append({"road": "side_north", "direction": "south", "points": [[xl_, H, 0.0], [xl_, rm, 0.0]]})
    lane_lines.append({"road": "side_south", "direction": "south", "points": [[-d.lane_m / 2, -rm, 0.0], [-d.lane_m / 2, -H, 0.0]]})
    lane_lines.append({"road": "side_south", "direction": "north", "points": [[d.lane_m / 2, -H, 0.0], [d.lane_m / 2, -rm, 0.0]]})
    scene.roads_truth = {
        "frame": "site local (metres, x east, y north, z up; origin = base point)",
        "roads": [
            {"name": "main", "centerline": [[-H, 0.0, 0.0], [H, 0.0, 0.0]], "width_m": 2 * rm,
             "lanes": 4, "oneway": False, "parking_strip_m": d.park_m,
             "polygon": [[-H, -rm], [H, -rm], [H, rm], [-H, rm]]},
            {"name": "side_north", "centerline": [[0.0, H, 0.0], [0.0, rm, 0.0]], "width_m": 2 * rs, "lanes": 2, "oneway": True,
             "polygon": [[-rs, rm], [rs, rm], [rs, H], [-rs, H]]},
            {"name": "side_south", "centerline": [[0.0, -rm, 0.0], [0.0, -H, 0.0]], "width_m": 2 * rs, "lanes": 2, "oneway": False,
             "polygon": [[-rs, -H], [rs, -H], [rs, -rm], [-rs, -rm]]},
        ],
        "junction": {"polygon": [[-rs, -rm], [rs, -rm], [rs, rm], [-rs, rm]], "traffic_signals": True},
        "lanes": lane_lines,
        "crossings": [
            {"road": "main", "polygon": [[zx0, -rm], [zx1, -rm], [zx1, rm], [zx0, rm]]},
            {"road": "main", "polygon": [[-zx1, -rm], [-zx0, -rm], [-zx0, rm], [-zx1, rm]]},
            {"road": "side_north", "polygon": [[-rs, zy0], [rs, zy0], [rs, zy1], [-rs, zy1]]},
            {"road": "side_south", "polygon": [[-rs, -zy1], [rs, -zy1], [rs, -zy0], [-rs, -zy0]]},
        ],
        "sidewalk_width_m": d.sidewalk_m,
        "curb_height_m": d.curb_m,
    }
    zxm, zym = (zx0 + zx1) / 2, (zy0 + zy1) / 2
    scene.osm = {
        "nodes": {  # id -> (x, y, tags)
            1: (-H, 0.0, {}), 2: (-zxm, 0.0, {"highway": "crossing", "crossing": "zebra", "crossing:markings": "zebra"}),
            3: (0.0, 0.0, {"highway": "traffic_signals"}),
            4: (zxm, 0.0, {"highway": "crossing", "crossing": "zebra", "crossing:markings": "zebra"}), 5: (H, 0.0, {}),
            6: (0.0, H, {}), 7: (0.0, zym, {"highway": "crossing", "crossing": "zebra", "crossing:markings": "zebra"}),
            8: (0.0, -zym, {"highway": "crossing", "crossing": "zebra", "crossing:markings": "zebra"}), 9: (0.0, -H, {}),
        },
        "ways": [
            (101, [1, 2, 3, 4, 5], {"highway": "secondary", "name": "Demokatu", "lanes": "4", "oneway": "no",
                                    "sidewalk": "both", "parking:both": "lane", "maxspeed": "40", "surface": "asphalt"}),
            (102, [6, 7, 3], {"highway": "residential", "name": "Testikuja", "lanes": "2", "oneway": "yes",
                              "sidewalk": "both", "maxspeed": "30", "surface": "asphalt"}),
            (103, [3, 8, 9], {"highway": "residential", "name": "Testikuja", "lanes": "2", "oneway": "no",
                              "lanes:forward": "1", "lanes:backward": "1", "sidewalk": "both", "maxspeed": "30", "surface": "asphalt"}),
        ],
    }
    # scanner car passes (lane centres, 1 m inside the site edge)
    e = H - 1.0
    scene.scan_passes = [
        np.array([[-e, -d.lane_m / 2], [e, -d.lane_m / 2]]),
        np.array([[e, d.lane_m / 2], [-e, d.lane_m / 2]]),
        np.array([[-d.lane_m / 2, e], [-d.lane_m / 2, -e]]),
        np.array([[d.lane_m / 2, -e], [d.lane_m / 2, -d.lane_m * 1.5], [e, -d.lane_m * 1.5]]),
    ]
    # photo walk: a loop over the four crossings, plus the main sidewalks on bigger sites
    swm, sws = (rm + bm) / 2, (rs + bs) / 2
    zx = (zx0 + zx1) / 2
    loop = [(zx, -swm), (zx, swm), (-sws, zym), (-zx, swm), (-zx, -swm), (sws, -zym), (zx, -swm)]
    scene.walk_path = np.array(loop, float)
    scene.gcp_points = gcp_points
    # bigger presets: out and back along every main-road sidewalk (crossing the main road on the zebras)
    ys_ = -rm - 0.85  # south sidewalk, clear of the street trees and lamps
    scene.walk_extra = np.array([
        (zx, ys_), (H - 4, ys_), (zx + 0.4, ys_), (zx + 0.4, swm), (H - 4, swm), (zx, swm), (-zx, swm),
        (-(H - 4), swm), (-zx - 0.4, swm), (-zx - 0.4, ys_), (-(H - 4), ys_), (-zx, ys_),
    ], float)
    # a pedestrian walking over the west crossing while the first scanner pass goes by
    scene.pedestrian = {"x": -zx, "y0": -rm + 0.4, "speed_mps": 1.3, "pass": 0, "radius_m": 0.23, "height_m": 1.75}
    scene.counts = {"buildings": len(buildings), "cars": len(cars), "trees": len(trees), "bushes": len(bushes),
                    "walls": len(walls), "fences": len(fences), "faces": int(len(scene.mesh.faces)),
                    "vertices": int(len(scene.mesh.vertices))}
    return scene

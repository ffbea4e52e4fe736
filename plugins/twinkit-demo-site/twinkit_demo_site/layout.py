"""The demo intersection: layout, ground truth geometry and labels.

Site frame: metres, x east, y north, z up, origin at the site base point (the
centre of the junction, road surface at z = 0).

Layout (right-hand traffic, as in Finland):
- main road along x: 2 lanes each way (3.25 m) plus a 2.2 m parking strip each
  side; sidewalks 3.5 m, raised by the curb height (10-15 cm).
- side street along y: 2 lanes; the north arm is one-way southbound, the south
  arm two-way. Zebra crossings on all four arms, stop lines before them.
- four blocks: NE and NW rows of buildings (NW with a wall), SW a walled yard and a building, SE a fenced
  park with trees and bushes. Street lamps, traffic lights on the four corners, traffic signs, street trees,
  parked cars, a motorcycle and a bicycle.

The ground (rectangles to cells and curb faces) is built by ground.py, the objects by objects.py; the road truth
and OSM extract by street_truth.py.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from twinkit.mesh import Mesh
from twinkit_demo_site import objects as ob
from twinkit_demo_site.ground import paint_ground
from twinkit_demo_site.meshbuild import MeshBuilder
from twinkit_demo_site.objects import LABELS, L  # noqa: F401  (LABELS: the site's classes, imported from here too)
from twinkit_demo_site.street_truth import osm_extract, roads_truth
from twinkit_demo_site.textures import CAR_PAINTS, FACADES, Atlas
from twinkit_demo_site.variety import Variety, random_variety  # noqa: F401  (random_variety: imported from here too)

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


def _dashes(x_from: float, x_to: float, dash: float = 3.0, gap: float = 3.0):
    out = []
    x = x_from
    while x + dash <= x_to:
        out.append((x, x + dash))
        x += dash + gap
    return out


# ---------------------------------------------------------------- road surface and marks
@dataclass
class Marks:
    """Where the junction's painted marks are (site frame, metres)."""
    zx0: float  # the zebras across the main road span |x| = zx0 .. zx1
    zx1: float
    zy0: float  # the zebras across the side street span |y| = zy0 .. zy1
    zy1: float
    sl_x: float  # stop lines before the main road's zebras start at |x| = sl_x
    sl_y: float  # and the side street's at |y| = sl_y
    x_start: float  # the main road's lane lines start at |x| = x_start
    gcp_points: list[dict]  # the zebras' outer stripe corners, {"id", "xyz", "what"}


def _surfaces(d: Dims, R, verge_m: float = 0.0) -> None:
    """Grass everywhere, the two roads' asphalt, the raised sidewalks with their curb strips, grass verges
    ``verge_m`` wide between curb and sidewalk outside the junction when asked (painter order)."""
    H, rm, rs, bm, bs = d.half_m, d.rm, d.rs, d.bm, d.bs
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
    if verge_m > 0:
        for s in (-1, 1):
            for t in (-1, 1):
                R(("grass", *sorted((s * bs, s * BIG)), *sorted((t * (rm + 0.15), t * (rm + 0.15 + verge_m)))))
                R(("grass", *sorted((t * (rs + 0.15), t * (rs + 0.15 + verge_m))), *sorted((s * bm, s * BIG))))
    R(("asphalt", -BIG, BIG, -rm, rm))  # road wins over the side-street sidewalks
    R(("asphalt", -rs, rs, -BIG, BIG))


def _zebras(d: Dims, R) -> tuple[float, float, float, float, list[dict]]:
    """Zebra crossings on all four arms: (zx0, zx1, zy0, zy1, gcp_points), the ground-control points being the outer
    corners of each zebra's first and last stripe at road level (what a surveyor measures and a user clicks)."""
    rm, rs = d.rm, d.rs
    zx0, zx1 = rs + 0.5, rs + 3.5  # across the main road, on both arms
    gcps = []
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
    gcp_points = [{"id": f"Z{k + 1:02d}", "xyz": [float(x), float(y), 0.0], "what": w}
                  for k, ((x, y), w) in enumerate(gcps)]
    return zx0, zx1, zy0, zy1, gcp_points


def _road_marks(d: Dims, R) -> Marks:
    """Paint the zebras, the stop lines (traffic towards the junction) and the lane lines."""
    H, rs = d.half_m, d.rs
    zx0, zx1, zy0, zy1, gcp_points = _zebras(d, R)
    sl_x = zx1 + 1.0
    R(("marking", sl_x, sl_x + 0.3, 0.0, d.main_traffic))            # east arm, westbound
    R(("marking", -sl_x - 0.3, -sl_x, -d.main_traffic, 0.0))          # west arm, eastbound
    sl_y = zy1 + 1.0
    R(("marking", -rs, rs, sl_y, sl_y + 0.3))                          # north arm, one-way southbound
    R(("marking", 0.0, rs, -sl_y - 0.3, -sl_y))                        # south arm, northbound lane
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
    return Marks(zx0, zx1, zy0, zy1, sl_x, sl_y, x_start, gcp_points)


# ---------------------------------------------------------------- blocks
@dataclass
class Blocks:
    """What stands in the four blocks: building solids (as objects.building returns them), walls
    (xa, xb, ya, yb, height), fences ((x, y), (x, y)), trees (x, y, scale) and bushes (x, y) or, in a hedge of a
    given height, (x, y, height)."""
    buildings: list[dict] = field(default_factory=list)
    walls: list[tuple] = field(default_factory=list)
    fences: list[tuple] = field(default_factory=list)
    trees: list[tuple] = field(default_factory=list)
    bushes: list[tuple] = field(default_factory=list)


def _row(mb: MeshBuilder, rng, d: Dims, R, buildings: list[dict], sx, sy, x_from, x_to, depth_lo=10.5, depth_hi=13.0,
         floor_range=(3, 7), setback=0.0):
    """Buildings along the main-road frontage of block (sx, sy) between |x| = x_from..x_to; returns the last's depth."""
    facade_names = list(FACADES)
    x = x_from
    first = True
    while True:
        w = float(rng.uniform(11.0, 20.0))
        if x + w > x_to:
            w = x_to - x
            if w < 8.0:
                break
        depth = float(rng.uniform(depth_lo, depth_hi))
        floors = int(rng.integers(*floor_range))
        xa, xb = sorted((sx * x, sx * (x + w)))
        ya, yb = sorted((sy * (d.bm + setback), sy * (d.bm + setback + depth)))
        street = {"-y" if sy > 0 else "+y"}
        if first and abs(x - d.bs) < 1e-6:
            street.add("-x" if sx > 0 else "+x")
        b = ob.building(mb, xa, xb, ya, yb, d.curb_m, floors, facade_names[int(rng.integers(len(facade_names)))], street)
        buildings.append(b)
        R(("none", xa, xb, ya, yb))
        x += w + float(rng.uniform(2.0, 3.5))
        first = False
        if x >= x_to - 8.0:
            break
    return buildings[-1]["max"][1] if sy > 0 else -buildings[-1]["min"][1]


def _side_row(mb: MeshBuilder, rng, d: Dims, R, buildings: list[dict], sx, sy, y_from, y_to,
              floor_range=(3, 7), setback=0.0) -> None:
    """Buildings facing the side street in block (sx, sy) between |y| = y_from..y_to."""
    facade_names = list(FACADES)
    y = y_from
    while y_to - y >= 10.0:
        w = min(float(rng.uniform(11.0, 20.0)), y_to - y)
        if y_to - y - w < 8.0:
            w = y_to - y
        depth = float(rng.uniform(10.5, 13.0))
        floors = int(rng.integers(*floor_range))
        xa, xb = sorted((sx * (d.bs + setback), sx * (d.bs + setback + depth)))
        ya, yb = sorted((sy * y, sy * (y + w)))
        b = ob.building(mb, xa, xb, ya, yb, d.curb_m, floors, facade_names[int(rng.integers(len(facade_names)))],
                        {"-x" if sx > 0 else "+x"})
        buildings.append(b)
        R(("none", xa, xb, ya, yb))
        y += w + float(rng.uniform(2.0, 3.5))


def _blocks(mb: MeshBuilder, rng, d: Dims, R, fl=(3, 7), sb=0.0) -> Blocks:
    """The buildings of the NE, NW and SW blocks (built now), the SW yard's walls and plants and the SE park."""
    H, bm, bs = d.half_m, d.bm, d.bs
    bl = Blocks()
    buildings = bl.buildings
    # NE: a row of buildings from the corner, more along the side street on big sites
    _row(mb, rng, d, R, buildings, 1, 1, bs, H - 0.5, floor_range=fl, setback=sb)
    depth_ne = max(b["max"][1] for b in buildings)
    _side_row(mb, rng, d, R, buildings, 1, 1, depth_ne + 3.0, H - 0.5, floor_range=fl, setback=sb)
    # NW: row from the corner; behind it buildings (big sites) or a wall along the side street
    n_before = len(buildings)
    _row(mb, rng, d, R, buildings, -1, 1, bs, H - 0.5, floor_range=fl, setback=sb)
    depth_nw = max(b["max"][1] for b in buildings[n_before:])
    if H - 0.5 - (depth_nw + 3.0) >= 10.0:
        _side_row(mb, rng, d, R, buildings, -1, 1, depth_nw + 3.0, H - 0.5, floor_range=fl, setback=sb)
    elif H - depth_nw > 4.0:
        bl.walls.append((-bs - 0.3, -bs, depth_nw + 2.0, H - 0.3, 2.0))
    # SW: walled yard at the corner, then buildings
    yard_x = bs + 8.0
    wall_end = min(H - 0.3, bm + 18.0)
    bl.walls.append((-bs - 0.25, -bs, -wall_end, -bm, 1.9))
    bl.walls.append((-yard_x, -bs - 0.25, -bm - 0.25, -bm, 1.9))
    _row(mb, rng, d, R, buildings, -1, -1, yard_x + 1.0, H - 0.5, floor_range=fl, setback=sb)
    _side_row(mb, rng, d, R, buildings, -1, -1, wall_end + 3.0, H - 0.5, floor_range=fl, setback=sb)
    bl.bushes += [(-bs - 2.0, -bm - 2.5), (-bs - 4.5, -bm - 1.6)]
    bl.trees.append((-bs - 4.0, -bm - 5.5, 0.9))
    _park(rng, d, R, bl)
    return bl


def _park(rng, d: Dims, R, bl: Blocks) -> None:
    """SE: a fenced park with trees and bushes, and street trees in grass pits on the sidewalk in front of it."""
    H, bm, bs = d.half_m, d.bm, d.bs
    bl.fences.append(((bs + 0.15, -bm - 0.15), (H - 0.3, -bm - 0.15)))
    bl.fences.append(((bs + 0.15, -(H - 0.3)), (bs + 0.15, -bm - 0.15)))
    tries = 0
    park_trees = []
    while tries < 400 and len(park_trees) < max(3, int((H - bs) * (H - bm) / 60)):
        tries += 1
        px, py = rng.uniform(bs + 3.5, H - 2.5), -rng.uniform(bm + 3.5, H - 2.5)
        if all(math.hypot(px - qx, py - qy) > 5.0 for qx, qy in park_trees):
            park_trees.append((px, py))
    bl.trees += [(x, y, 1.0) for x, y in park_trees]
    xb_ = bs + 1.2
    while xb_ < H - 1.5:
        if rng.random() < 0.75:
            bl.bushes.append((xb_, -bm - 1.1))
        xb_ += rng.uniform(1.6, 2.6)
    xt = bs + 7.5
    while xt < H - 2.0:
        R(("grass", xt - 0.7, xt + 0.7, -bm + 0.6, -bm + 2.0))
        bl.trees.append((xt, -bm + 1.3, 0.8))
        xt += 9.0


def _street_trees(rng, d: Dims, m: Marks, R, bl: Blocks, p: float) -> None:
    """Street trees in grass pits (chance ``p`` per ~11 m slot) on the main road's north and south-west sidewalks and
    along the side streets, clear of the junction's lamps, signs and lights."""
    H, rm, rs = d.half_m, d.rm, d.rs
    lamps_n = [10.0 + 14.0 * k for k in range(int(H / 14) + 2)]
    lamps_s = [17.0 + 14.0 * k for k in range(int(H / 14) + 2)]
    spots = []
    for sx, sy, lamps in ((1, 1, lamps_n), (-1, 1, lamps_n), (-1, -1, lamps_s)):
        x = m.zx1 + 3.5
        while x < H - 2.5:
            if min(abs(x - v) for v in lamps) > 2.5 and abs(x - (H - 5.0)) > 2.0:
                spots.append((sx * x, sy * (rm + 1.5)))
            x += 11.0
    for sx in (-1, 1):
        for sy in (-1, 1):
            y = m.zy1 + 3.5
            while y < H - 2.5:
                spots.append((sx * (rs + 1.5), sy * y))
                y += 11.0
    for x, y in spots:
        if rng.random() < p:
            R(("grass", x - 0.7, x + 0.7, y - 0.7, y + 0.7))
            bl.trees.append((x, y, float(rng.uniform(0.7, 1.0))))


def _gardens(rng, d: Dims, bl: Blocks, setback: float, p: float, hedge_m: float = 0.0) -> None:
    """Hedges (rows of bushes; ``hedge_m`` high, 0 = bushes of their own size) along the front gardens of the
    buildings set ``setback`` metres back from the sidewalk, each with chance ``p``, and a tree in a garden deeper
    than 4 m with chance ``p`` / 2."""
    for b in bl.buildings:
        (x0, y0, _), (x1, y1, _) = b["min"], b["max"]
        for lo_edge, hi_edge, back, along_x in ((y0, y1, d.bm, True), (x0, x1, d.bs, False)):
            for sgn, face in ((1, lo_edge), (-1, hi_edge)):
                if abs(sgn * face - (back + setback)) > 1e-6:
                    continue  # this side does not face a sidewalk across a garden
                a0, a1 = (x0, x1) if along_x else (y0, y1)
                c = sgn * (back + 0.6)
                if rng.random() < p:
                    for u in np.arange(a0 + 0.8, a1 - 0.5, 1.3):
                        xy = (u, c) if along_x else (c, u)
                        bl.bushes.append((*xy, hedge_m) if hedge_m > 0 else xy)
                if setback > 4.0 and rng.random() < p / 2:
                    m = sgn * (back + setback / 2)
                    u = float(rng.uniform(a0 + 2, a1 - 2))
                    bl.trees.append((u, m, float(rng.uniform(0.6, 0.9))) if along_x else (m, u, float(rng.uniform(0.6, 0.9))))


def _build_block_things(mb: MeshBuilder, rng, d: Dims, R, bl: Blocks, tree_scale: float = 1.0) -> None:
    """Build the walls (their footprint left bare of ground), fences, trees and bushes, in that order."""
    cz = d.curb_m
    for (xa, xb, ya, yb, h) in bl.walls:
        mb.box([xa, ya, cz], [xb, yb, cz + h], L["wall"], "concrete_wall", period=3.0)
        R(("none", xa, xb, ya, yb))
    for a, b in bl.fences:
        ob.fence(mb, a, b, cz)
    for x, y, sc in bl.trees:
        ob.tree(mb, rng, x, y, cz, sc * tree_scale)
    for bush in bl.bushes:
        ob.bush(mb, rng, bush[0], bush[1], cz, height=bush[2] if len(bush) > 2 else None)


# ---------------------------------------------------------------- street furniture and vehicles
def _street_furniture(mb: MeshBuilder, d: Dims, m: Marks) -> None:
    """Street lamps along the main road, traffic lights on the four corners and the traffic signs."""
    H, rm, rs, cz = d.half_m, d.rm, d.rs, d.curb_m
    lamp_y = rm + 0.55
    xl = 10.0
    while xl < H - 2.0:
        for sx in (-1, 1):
            ob.lamp(mb, sx * xl, lamp_y, cz, (0, -1))
        xl += 14.0
    xl = 17.0
    while xl < H - 2.0:
        ob.lamp(mb, -xl, -(rm + 0.35), cz, (0, 1))
        xl += 14.0
    c0 = 0.55
    ob.traffic_light(mb, rs + c0, rm + c0, cz, (1, 0))      # westbound approach (east arm)
    ob.traffic_light(mb, -rs - c0, -rm - c0, cz, (-1, 0))   # eastbound approach (west arm)
    ob.traffic_light(mb, -rs - c0, rm + c0, cz, (0, 1))     # southbound approach (north arm)
    ob.traffic_light(mb, rs + c0, -rm - c0, cz, (0, -1))    # northbound approach (south arm)
    ob.sign(mb, m.zx1 + 0.4, rm + 0.45, cz, (1, 0), "crossing")
    ob.sign(mb, -m.zx1 - 0.4, -rm - 0.45, cz, (-1, 0), "crossing")
    ob.sign(mb, -rs - 0.45, m.zy1 + 0.4, cz, (0, 1), "crossing")
    ob.sign(mb, rs + 0.45, -m.zy1 - 0.4, cz, (0, -1), "crossing")
    ob.sign(mb, rs + 0.45, m.zy0 - 0.1, cz, (0, -1), "no_entry")
    ob.sign(mb, rs + 0.45, -m.sl_y - 2.5, cz, (0, -1), "stop")
    ob.sign(mb, -(H - 5.0), -rm - 0.45, cz, (-1, 0), "speed")
    ob.sign(mb, -rs - 0.45, -m.sl_y - 2.5, cz, (0, 1), "yield")
    if H - 5.0 > 20:
        ob.sign(mb, H - 5.0, rm + 0.45, cz, (1, 0), "speed")


def _vehicles(mb: MeshBuilder, rng, d: Dims, m: Marks, park_p: float = 0.65) -> list[dict]:
    """Parked cars and a motorcycle, a car at the north arm's stop line, a bicycle; returns the cars' records."""
    H = d.half_m
    paints = list(CAR_PAINTS)
    cars = []
    slots = []
    xs_ = m.x_start + 4.0
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
            ob.motorcycle(mb, x, sy * ypark, 0.0, yaw + 0.25)
            continue
        if rng.random() < park_p:
            cars.append(ob.car(mb, rng, x + rng.uniform(-0.4, 0.4), sy * (ypark + rng.uniform(-0.1, 0.1)), 0.0, yaw,
                               paints[int(rng.integers(len(paints)))]))
    cars.append(ob.car(mb, rng, -d.lane_m / 2, m.sl_y + 0.3 + 0.6 + 2.3, 0.0, -math.pi / 2,
                       paints[int(rng.integers(len(paints)))]))
    ob.bicycle(mb, d.bs + 6.0, d.bm - 0.6, d.curb_m, 0.0)
    return cars


# ---------------------------------------------------------------- truth and routes
def _routes(scene: Scene, d: Dims, m: Marks) -> None:
    """The scanner car's passes, the photo walks and the pedestrian crossing during the first pass."""
    H, rm, rs, bm, bs = d.half_m, d.rm, d.rs, d.bm, d.bs
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
    zx = (m.zx0 + m.zx1) / 2
    zym = (m.zy0 + m.zy1) / 2
    loop = [(zx, -swm), (zx, swm), (-sws, zym), (-zx, swm), (-zx, -swm), (sws, -zym), (zx, -swm)]
    scene.walk_path = np.array(loop, float)
    # bigger presets: out and back along every main-road sidewalk (crossing the main road on the zebras)
    ys_ = -rm - 0.85  # south sidewalk, clear of the street trees and lamps
    scene.walk_extra = np.array([
        (zx, ys_), (H - 4, ys_), (zx + 0.4, ys_), (zx + 0.4, swm), (H - 4, swm), (zx, swm), (-zx, swm),
        (-(H - 4), swm), (-zx - 0.4, swm), (-zx - 0.4, ys_), (-(H - 4), ys_), (-zx, ys_),
    ], float)
    # a pedestrian walking over the west crossing while the first scanner pass goes by
    scene.pedestrian = {"x": -zx, "y0": -rm + 0.4, "speed_mps": 1.3, "pass": 0, "radius_m": 0.23, "height_m": 1.75}


# ---------------------------------------------------------------- the whole site
def build_scene(half_m: float, seed: int, atlas: Atlas, variety: Variety | None = None) -> Scene:
    """The demo intersection of half size ``half_m`` (metres) for ``seed``: its textured, labelled mesh and truths.

    One generator drives every random choice, in the order below, so a seed gives the same site byte for byte.
    ``variety`` (training data only) changes the layout's knobs; None or the default :class:`Variety` builds the demo."""
    v = variety or Variety()
    rng = np.random.default_rng([seed, 1])
    widths = {k: getattr(v, k) for k in ("lane_m", "park_m", "sidewalk_m") if getattr(v, k) is not None}
    d = Dims(half_m=half_m, curb_m=round(float(rng.uniform(0.10, 0.15)), 3), **widths)
    mb = MeshBuilder(atlas)
    scene = Scene(mesh=None, atlas=atlas, dims=d)  # type: ignore[arg-type]
    rects: list[tuple[str, float, float, float, float]] = []  # painter-ordered ground rectangles
    R = rects.append
    _surfaces(d, R, v.verge_m)
    marks = _road_marks(d, R)
    blocks = _blocks(mb, rng, d, R, v.floors, v.setback_m)
    if v.street_trees > 0:
        _street_trees(np.random.default_rng([seed, 9]), d, marks, R, blocks, v.street_trees)
    if v.setback_m > 0 and v.hedges > 0:
        _gardens(np.random.default_rng([seed, 12]), d, blocks, v.setback_m, v.hedges, v.hedge_m)
    _build_block_things(mb, rng, d, R, blocks, v.tree_scale)
    _street_furniture(mb, d, marks)
    cars = _vehicles(mb, rng, d, marks, v.park_p)
    paint_ground(mb, rects, d)
    scene.mesh = mb.finish()
    cz = d.curb_m
    scene.buildings = blocks.buildings
    scene.solids = blocks.buildings + [{"min": [w[0], w[2], cz], "max": [w[1], w[3], cz + w[4]]} for w in blocks.walls]
    scene.roads_truth = roads_truth(d, marks)
    scene.osm = osm_extract(d, marks)
    _routes(scene, d, marks)
    scene.gcp_points = marks.gcp_points
    scene.counts = {"buildings": len(blocks.buildings), "cars": len(cars), "trees": len(blocks.trees),
                    "bushes": len(blocks.bushes), "walls": len(blocks.walls), "fences": len(blocks.fences),
                    "faces": int(len(scene.mesh.faces)), "vertices": int(len(scene.mesh.vertices))}
    return scene

"""View samplers (component kind ``view_sampler``) and the scene they sample.

A view is a plain dict (what ``views.json`` holds)::

    {"id": "auto_street_0007", "sampler": "auto_street", "position": [x, y, z],
     "heading_deg": 45.0, "pitch_deg": -5.0, "hfov_deg": 75.0, "width": 1024, "height": 512}

heading: degrees counter-clockwise from +x (east) in the site frame; pitch: degrees above
the horizon. Every sampler object has ``sample(scene, ctx) -> list[dict]``.
"""
from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import List

import numpy as np

from twinkit.errors import InputError
from twinkit.ranges import param


@dataclass
class CameraParams:
    width_px: int = param(1024, ge=16, le=16384, help="Width of each rendered view (px).")
    height_px: int = param(512, ge=16, le=16384, help="Height of each rendered view (px).")
    hfov_deg: float = param(75.0, gt=0, lt=180, help="Horizontal field of view of each view (degrees).")
    pitch_deg: float = param(-8.0, ge=-90, le=90, help="Camera pitch (degrees; negative looks down).")


class Scene:
    """What samplers may look at: the mesh, a ray caster, the site, optional road / point files."""

    def __init__(self, vertices, faces, normals, site=None, roads_osm: Path | None = None,
                 street_points: Path | None = None):
        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.int64)
        self.normals = np.asarray(normals, dtype=np.float64)
        self.site = dict(site or {})
        self.roads_osm = roads_osm
        self.street_points = street_points
        self.capture: str | None = None  # aerial | mobile | terrestrial (twinkit.surface.density), when known
        self.lo = self.vertices.min(axis=0)
        self.hi = self.vertices.max(axis=0)
        self._rc = None

    @property
    def raycaster(self):
        if self._rc is None:
            import open3d as o3d

            mesh = o3d.t.geometry.TriangleMesh()
            mesh.vertex.positions = o3d.core.Tensor(self.vertices.astype(np.float32))
            mesh.triangle.indices = o3d.core.Tensor(self.faces.astype(np.int32))
            self._rc = o3d.t.geometry.RaycastingScene()
            self._rc.add_triangles(mesh)
        return self._rc

    def cast(self, origins: np.ndarray, dirs: np.ndarray):
        """(t_hit (inf = miss), unit normal of the hit triangle (n, 3))."""
        import open3d as o3d

        rays = np.concatenate([origins, dirs], axis=1).astype(np.float32)
        ans = self.raycaster.cast_rays(o3d.core.Tensor(rays))
        return ans["t_hit"].numpy().astype(np.float64), ans["primitive_normals"].numpy().astype(np.float64)

    def ground_below(self, xy: np.ndarray):
        """Topmost surface under each (x, y): (z (nan = none), upward normal z component)."""
        top = self.hi[2] + 10.0
        o = np.column_stack([xy, np.full(len(xy), top)])
        d = np.tile([0.0, 0.0, -1.0], (len(xy), 1))
        t, n = self.cast(o, d)
        z = np.where(np.isfinite(t), top - t, np.nan)
        return z, np.abs(n[:, 2])

    def clearance(self, points: np.ndarray, n_dirs: int = 8, up: bool = True):
        """Smallest free distance from each point along ``n_dirs`` horizontal rays (and up)."""
        dists = []
        for i in range(n_dirs):
            a = 2 * np.pi * i / n_dirs
            d = np.tile([np.cos(a), np.sin(a), 0.0], (len(points), 1))
            dists.append(self.cast(points, d)[0])
        horiz = np.min(np.stack(dists), axis=0) if dists else np.full(len(points), np.inf)
        upd = self.cast(points, np.tile([0.0, 0.0, 1.0], (len(points), 1)))[0] if up else np.full(len(points), np.inf)
        return horiz, upd


def _views_at(points, heights, headings: int, cam: CameraParams, sampler: str, start: int = 0) -> list[dict]:
    views = []
    i = start
    for p in np.asarray(points, dtype=np.float64).reshape(-1, 3):
        for h in heights:
            for k in range(int(headings)):
                views.append({
                    "id": f"{sampler}_{i:05d}", "sampler": sampler,
                    "position": [round(float(p[0]), 4), round(float(p[1]), 4), round(float(p[2] + h), 4)],
                    "heading_deg": round(360.0 * k / headings, 4), "pitch_deg": float(cam.pitch_deg),
                    "hfov_deg": float(cam.hfov_deg), "width": int(cam.width_px), "height": int(cam.height_px),
                })
                i += 1
    return views


def _thin(points: np.ndarray, min_dist: float) -> np.ndarray:
    """Greedy subset with at least ``min_dist`` between kept points (in input order)."""
    if len(points) == 0 or min_dist <= 0:
        return points
    from scipy.spatial import cKDTree

    tree = cKDTree(points[:, :2])
    taken = np.zeros(len(points), bool)
    alive = np.ones(len(points), bool)
    for i in range(len(points)):
        if not alive[i]:
            continue
        taken[i] = True
        alive[tree.query_ball_point(points[i, :2], min_dist)] = False
    return points[taken]


# ----------------------------------------------------------------------------- uniform
@dataclass
class UniformParams(CameraParams):
    spacing_m: float = param(4.0, gt=0,
                             help="Spacing (m) of the grid of camera positions over the mesh's bounding box.")
    heights_m: List[float] = param(default_factory=lambda: [2.0], gt=0,
                                   help="Camera heights (m) above the lowest ground level (the 2nd percentile of "
                                        "vertex z).")
    headings: int = param(8, ge=1, le=360,
                          help="Viewing directions at each position, evenly spread around the circle.")
    margin_m: float = param(2.0, ge=0, help="Keep camera positions this far (m) inside the mesh's bounding box.")


class UniformSampler:
    """Grid over the mesh's bounding box every ``spacing_m``, at ``heights_m`` above the ground level
    (2nd percentile of vertex z), ``headings`` directions each (the thesis's uniform sampling)."""

    def __init__(self, params: UniformParams):
        self.p = params

    def sample(self, scene: Scene, ctx=None) -> list[dict]:
        p = self.p
        ground = float(np.percentile(scene.vertices[:, 2], 2))
        xs = np.arange(scene.lo[0] + p.margin_m, scene.hi[0] - p.margin_m + 1e-9, p.spacing_m)
        ys = np.arange(scene.lo[1] + p.margin_m, scene.hi[1] - p.margin_m + 1e-9, p.spacing_m)
        gx, gy = np.meshgrid(xs, ys)
        pts = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, ground)])
        return _views_at(pts, p.heights_m, p.headings, p, "uniform")


# ----------------------------------------------------------------------------- random
@dataclass
class RandomParams(CameraParams):
    n_views: int = param(300, ge=1, help="Number of random views.")
    offset_min_m: float = param(2.0, ge=0,
                                help="Each camera stands between offset_min_m and offset_max_m (m) off a random "
                                     "vertex along its normal, looking back at it.")
    offset_max_m: float = param(6.0, gt=0,
                                help="Upper end (m) of the random distance from the vertex (see offset_min_m).")
    seed: int = param(0, ge=0, help="Random seed (the same seed gives the same views).")


class RandomSampler:
    """A random vertex, the camera moved ``offset`` metres along its normal, looking back at it."""

    def __init__(self, params: RandomParams):
        self.p = params

    def sample(self, scene: Scene, ctx=None) -> list[dict]:
        p = self.p
        rng = np.random.default_rng(p.seed)
        idx = rng.integers(0, len(scene.vertices), size=p.n_views)
        off = rng.uniform(p.offset_min_m, p.offset_max_m, size=p.n_views)
        n = scene.normals[idx]
        pos = scene.vertices[idx] + n * off[:, None]
        look = -n
        views = []
        for i in range(p.n_views):
            dx, dy, dz = look[i]
            horiz = math.hypot(dx, dy)
            heading = math.degrees(math.atan2(dy, dx)) if horiz > 1e-3 else float(rng.uniform(0, 360))
            pitch = math.degrees(math.atan2(dz, horiz))
            pitch = max(-89.0, min(89.0, pitch))
            views.append({
                "id": f"random_{i:05d}", "sampler": "random",
                "position": [round(float(v), 4) for v in pos[i]],
                "heading_deg": round(heading, 4), "pitch_deg": round(pitch, 4),
                "hfov_deg": float(p.hfov_deg), "width": int(p.width_px), "height": int(p.height_px),
            })
        return views


# ----------------------------------------------------------------------------- street points (file)
@dataclass
class StreetPointsParams(CameraParams):
    points_file: str = param("", path=True,
                             help='A CloudCompare point list ("x y z" per line) of camera positions; empty = the '
                                  "step's street_points.txt.")
    heights_m: List[float] = param(default_factory=lambda: [1.5, 3.0, 4.5], gt=0,
                                   help="Camera heights (m) above each listed point.")
    headings: int = param(8, ge=1, le=360,
                          help="Viewing directions at each position, evenly spread around the circle.")


def read_point_list(path: Path) -> np.ndarray:
    """CloudCompare point-list text: one point per line, first three numbers x y z
    (commas, semicolons or spaces; lines starting with # or // and blank lines skipped)."""
    pts = []
    for no, line in enumerate(Path(path).read_text().splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#") or line.startswith("//"):
            continue
        nums = [t for t in re.split(r"[\s,;]+", line) if t]
        try:
            vals = [float(t) for t in nums[:3]]
        except ValueError:
            if not pts:  # a header line
                continue
            raise InputError(f"{path}:{no}: expected 'x y z', got {line!r}") from None
        if len(vals) < 3:
            raise InputError(f"{path}:{no}: expected 'x y z', got {line!r}")
        pts.append(vals)
    if not pts:
        raise InputError(f"{path}: no points; write one 'x y z' line per street point (site frame, metres)")
    return np.asarray(pts, dtype=np.float64)


class StreetPointsSampler:
    """User-picked street points (file), cameras at 1.5 / 3 / 4.5 m, 8 headings 45 degrees apart."""

    def __init__(self, params: StreetPointsParams):
        self.p = params

    def sample(self, scene: Scene, ctx=None) -> list[dict]:
        path = Path(self.p.points_file) if self.p.points_file else scene.street_points
        if path is None or not Path(path).is_file():
            raise InputError(
                f"view_sampler=street_points needs a point list: set view_sampler.points_file=<file> or provide "
                f"street_points.txt (CloudCompare: pick points on the road, 'Save' as ASCII x y z); got {path}"
            )
        pts = read_point_list(Path(path))
        return _views_at(pts, self.p.heights_m, self.p.headings, self.p, "street")


def cap_views(views: list[dict], max_views: int) -> list[dict]:
    """At most ``max_views`` views, the most informative first: whole camera positions (a position's
    heights and headings see different things; evenly thinning the list dropped whole headings), the
    positions taken in farthest-point order (each next one the farthest from those already kept, so the
    kept ones spread over the whole site), then in their original order. A budget below one position's
    views keeps that position's views evenly thinned."""
    if max_views <= 0 or len(views) <= max_views:
        return list(views)
    keys: dict = {}
    for i, v in enumerate(views):
        keys.setdefault((v.get("sampler"), round(v["position"][0], 2), round(v["position"][1], 2)), []).append(i)
    groups = list(keys.values())
    xy = np.array([views[g[0]]["position"][:2] for g in groups], dtype=np.float64)
    order = [int(np.argmin(np.linalg.norm(xy - xy.mean(axis=0), axis=1)))]  # start at the centre
    d = np.linalg.norm(xy - xy[order[0]], axis=1)
    chosen, n = [], 0
    while True:
        g = groups[order[-1]]
        if n + len(g) > max_views:
            if not chosen:  # one position is over the budget: thin it evenly
                keep = np.linspace(0, len(g) - 1, max_views).round().astype(int)
                chosen = [g[k] for k in keep]
            break
        chosen += g
        n += len(g)
        if len(order) == len(groups):
            break
        nxt = int(np.argmax(d))
        order.append(nxt)
        d = np.minimum(d, np.linalg.norm(xy - xy[nxt], axis=1))
    return [views[i] for i in sorted(chosen)]


# ----------------------------------------------------------------------------- automatic street points
@dataclass
class AutoStreetParams(CameraParams):
    spacing_m: float = param(6.0, gt=0,
                             help="Distance (m) between camera positions along the roads, or on the ground grid "
                                  "without roads.")
    heights_m: List[float] = param(default_factory=lambda: [1.5, 3.0, 4.5], gt=0,
                                   help="Camera heights (m) above the street at each position.")
    headings: int = param(8, ge=1, le=360,
                          help="Viewing directions at each position, evenly spread around the circle.")
    use_roads: bool = param(True,
                            help="Place cameras along the road network (roads.osm) when the run has one; otherwise "
                                 "on a grid over the ground.")
    min_clearance_m: float = param(1.0, ge=0,
                                   help="Free space (m) a camera position needs around it (tested with horizontal "
                                        "rays at 1.5 m).")
    min_headroom_m: float = param(5.0, ge=0,
                                  help="Nothing (trees, roofs) may hang over a camera position within this height "
                                       "(m).")
    max_ground_step_m: float = param(0.35, ge=0,
                                     help="Ground higher than the lowest ground level + this (m) is not street.")
    aerial_heights_m: List[float] = param(default_factory=lambda: [3.0, 6.0, 10.0], gt=0,
                                          help="Camera heights (m) for an aerial capture (few points on walls, see "
                                               "twinkit.surface.density), used instead of heights_m: higher, "
                                               "steeper views see roofs and ground rather than the walls Poisson "
                                               "drew between them.")
    aerial_pitch_deg: float = param(-20.0, ge=-90, le=90,
                                    help="Camera pitch (degrees) for an aerial capture, used instead of pitch_deg.")


def osm_roads_local(path: Path, site: dict) -> list[np.ndarray]:
    """Polylines (x, y) in the site frame of the drivable OSM ways in ``path``."""
    from pyproj import Transformer

    crs = site.get("crs")
    bp = site.get("base_point") or {}
    if not crs or "lat" not in bp:
        return []
    root = ET.parse(path).getroot()
    nodes = {n.get("id"): (float(n.get("lon")), float(n.get("lat"))) for n in root.iter("node")}
    tr = Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    bx, by = tr.transform(float(bp["lon"]), float(bp["lat"]))
    skip = {"footway", "path", "cycleway", "steps", "pedestrian", "crossing", "bridleway", "corridor"}
    lines = []
    for way in root.iter("way"):
        tags = {t.get("k"): t.get("v") for t in way.iter("tag")}
        if "highway" not in tags or tags["highway"] in skip:
            continue
        ll = np.array([nodes[nd.get("ref")] for nd in way.iter("nd") if nd.get("ref") in nodes])
        if len(ll) < 2:
            continue
        x, y = tr.transform(ll[:, 0], ll[:, 1])
        lines.append(np.column_stack([np.asarray(x) - bx, np.asarray(y) - by]))
    return lines


def _resample(line: np.ndarray, step: float) -> np.ndarray:
    seg = np.linalg.norm(np.diff(line, axis=0), axis=1)
    s = np.concatenate([[0], np.cumsum(seg)])
    if s[-1] <= 0:
        return line[:1]
    t = np.arange(step / 2, s[-1], step)
    return np.column_stack([np.interp(t, s, line[:, 0]), np.interp(t, s, line[:, 1])])


class AutoStreetSampler:
    """Street points with no manual step: along the road network (roads.osm) when available,
    else on the reconstructed ground (low, upward-facing, open areas of the mesh)."""

    def __init__(self, params: AutoStreetParams):
        self.p = params

    def candidates(self, scene: Scene, log=None) -> tuple[np.ndarray, str]:
        p = self.p
        source = "ground"
        xy = np.zeros((0, 2))
        if p.use_roads and scene.roads_osm is not None and Path(scene.roads_osm).is_file():
            try:
                lines = osm_roads_local(Path(scene.roads_osm), scene.site)
            except Exception as exc:  # a broken OSM file: fall back to the ground, say so
                if log:
                    log.warning("roads.osm not usable (%s); sampling street points from the ground", exc)
                lines = []
            if lines:
                xy = np.concatenate([_resample(l, p.spacing_m) for l in lines])
                inside = np.all((xy >= scene.lo[:2] + 1.0) & (xy <= scene.hi[:2] - 1.0), axis=1)
                xy = xy[inside]
                source = "roads"
        if len(xy) == 0:
            xs = np.arange(scene.lo[0] + p.spacing_m / 2, scene.hi[0], p.spacing_m)
            ys = np.arange(scene.lo[1] + p.spacing_m / 2, scene.hi[1], p.spacing_m)
            gx, gy = np.meshgrid(xs, ys)
            xy = np.column_stack([gx.ravel(), gy.ravel()])
            source = "ground"
        z, nz = scene.ground_below(xy)
        ok = np.isfinite(z) & (nz > 0.85)
        if ok.any():
            level = float(np.percentile(z[ok], 10))
            ok &= z <= level + p.max_ground_step_m
        pts = np.column_stack([xy, np.nan_to_num(z)])[ok]
        if len(pts):
            horiz, up = scene.clearance(pts + [0, 0, 1.5])
            free = (horiz >= p.min_clearance_m) & (up >= p.min_headroom_m)
            pts = pts[free]
        pts = _thin(pts, 0.75 * p.spacing_m)
        return pts, source

    def sample(self, scene: Scene, ctx=None) -> list[dict]:
        log = getattr(ctx, "log", None)
        pts, source = self.candidates(scene, log)
        if len(pts) == 0 and source == "roads":
            self.p.use_roads = False
            pts, source = self.candidates(scene, log)
        heights, cam = self.p.heights_m, self.p
        if getattr(scene, "capture", None) == "aerial":
            import dataclasses

            heights, cam = self.p.aerial_heights_m, dataclasses.replace(self.p, pitch_deg=self.p.aerial_pitch_deg)
            if log:
                log.info("auto_street: an aerial capture: cameras at %s m, pitch %g deg",
                         ", ".join(f"{h:g}" for h in heights), cam.pitch_deg)
        if log:
            log.info("auto_street: %d street points from the %s", len(pts), source)
        views = _views_at(pts, heights, self.p.headings, cam, "auto_street")
        for v in views:
            v["source"] = source
        return views


# ----------------------------------------------------------------------------- combined
@dataclass
class CombinedParams:
    use: List[str] = param(default_factory=lambda: ["auto_street", "uniform", "random"], free=True,
                           help="The samplers whose views are combined (of auto_street, street_points, "
                                "uniform, random).")
    auto_street: AutoStreetParams = param(default_factory=AutoStreetParams, free=True,
                                          help="Options of the auto_street sampler when it is in use.")
    street_points: StreetPointsParams = param(default_factory=StreetPointsParams, free=True,
                                              help="Options of the street_points sampler when it is in use.")
    uniform: UniformParams = param(default_factory=UniformParams, free=True,
                                   help="Options of the uniform sampler when it is in use.")
    random: RandomParams = param(default_factory=RandomParams, free=True,
                                 help="Options of the random sampler when it is in use.")


SAMPLERS = {
    "auto_street": (AutoStreetSampler, AutoStreetParams),
    "street_points": (StreetPointsSampler, StreetPointsParams),
    "uniform": (UniformSampler, UniformParams),
    "random": (RandomSampler, RandomParams),
}


class CombinedSampler:
    """The union of several samplers' views (the thesis's "combined" configurations)."""

    def __init__(self, params: CombinedParams):
        self.p = params
        for name in params.use:
            if name not in SAMPLERS:
                raise InputError(f"view_sampler=combined: unknown sampler {name!r} in 'use' (choose from {sorted(SAMPLERS)})")

    def sample(self, scene: Scene, ctx=None) -> list[dict]:
        views = []
        for name in self.p.use:
            cls, _ = SAMPLERS[name]
            views += cls(getattr(self.p, name)).sample(scene, ctx)
        return views


def build(kind: str):
    def make(params=None):
        if kind == "combined":
            return CombinedSampler(params or CombinedParams())
        cls, pcls = SAMPLERS[kind]
        return cls(params or pcls())

    make.__doc__ = {
        "auto_street": "Automatic street points from the road network (roads.osm) or the ground; 3 heights x 8 headings (default)",
        "street_points": "User-picked street points from a CloudCompare point list; 1.5/3/4.5 m x 8 headings",
        "uniform": "Grid over the site every spacing_m at fixed heights, 8 headings",
        "random": "Random vertex + offset along its normal, looking back at it",
        "combined": "Union of several samplers (use: [auto_street, uniform, random])",
    }[kind]
    return make


def view_matrices(view: dict):
    from twinkit_segmentation.render import look_matrix, projection_matrix

    return (look_matrix(view["position"], view["heading_deg"], view["pitch_deg"]),
            projection_matrix(view["hfov_deg"], view["width"], view["height"]))

"""The ``drop_test`` step: does the static mesh hold up a car and a walker everywhere the map sends them?

The way a simulator sees the ground: vertical rays on a grid (``spacing_m``, 10 cm) over every driving,
parking and sidewalk lane of the OpenDRIVE map (:class:`twinkit.street.lanes.LaneMap`: carla.Map, offline), inside
the scanned site (the cloud's footprint, :class:`twinkit.surface.watertight.Footprint`). A ray passes when
the static mesh (after ``lift_movables``: what CARLA gets as its map) crosses it within ``tol_m`` of the
lane's height. A lane's height is the map's road elevation plus the lane's own ``<height>`` records, if
any; a sidewalk lane without one (netconvert writes none) is expected at the height of the pavement beside
the road, up to ``curb_max_m`` above the road (a kerb), and passes when the mesh is within ``tol_m`` of
any height in that band.

Three kinds of lane, each with its own target: **driving** (what CARLA drives on: ``Map.cpp``
``ForEachDrivableLaneImpl`` walks driving, bidirectional and ramp lanes), **parking** (cars stand there and
CARLA never drives there; its outer edge runs along the kerb), **sidewalk**. A lane of no width (a lane
narrowed away at a map end, ``twinkit_roads.ground_ends.trim_outer_lanes``) carries nothing and gets no ray.

Writes ``drop_test.json`` (per lane kind: rays, hits, the share, the misses grouped in clusters with
their positions) and ``drop_test.png`` (misses in orange over the mesh seen from above, with the open
border at ground level). A share below ``min_driving_pct`` / ``min_parking_pct`` / ``min_sidewalk_pct`` is
logged as a warning and marked ``"ok": false`` in the metrics and the report; a hole wider than
``max_hole_m`` under any kind fails its ground (a degraded run).
"""
from __future__ import annotations

import functools
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from twinkit import InputError, StepContext
from twinkit.ranges import param
from twinkit.surface.watertight import ground_share


@dataclass
class DropTestParams:
    """Vertical rays over the lanes: does the static mesh hold up cars and walkers?"""

    spacing_m: float = param(0.10, gt=0, help="Ray grid along and across each lane, m.")
    tol_m: float = param(0.05, gt=0, help="A ray passes when the surface is this close to the lane's height, m.")
    curb_max_m: float = param(0.30, ge=0, help="A sidewalk without <height> records may lie up to this above the "
                              "road (a kerb), m.")
    min_driving_pct: float = param(99.9, ge=0, le=100, help="Below this share of hits on driving lanes: a warning "
                                   "and ok = false, %.")
    min_sidewalk_pct: float = param(99.5, ge=0, le=100, help="The same on sidewalk lanes, %.")
    min_parking_pct: float = param(99.5, ge=0, le=100, help="The same on parking lanes (cars stand there, CARLA "
                                   "drives none of them; their outer edge runs along the kerb), %.")
    footprint_margin_m: float = param(1.0, ge=0, help="Rays this close to the scan's edge are not counted (the "
                                      "site ends there), m.")
    fill_limit_m: float = param(8.0, ge=0, help="Unscanned gaps narrower than this count as inside the site (the "
                                "ground fill's limit), m.")
    fall_m: float = param(0.5, gt=0, help="A missed ray with no surface this close to the lane falls through (a "
                          "hole); otherwise it is off height, m.")
    max_hole_m: float = param(0.25, ge=0, help="Any hole wider than this (the falling rays' extent across their main "
                              "direction + one spacing: a slit's width, not its length) fails the lane whatever the "
                              "share: it swallows a tyre's contact patch (about 0.2 m) or a shoe, m.")
    local_window_m: float = param(0.5, ge=0, help="The surface's continuity: a ray holds when the surface under it "
                                  "lies within tol_m of its mean height over this window (a crack, a step, a bump "
                                  "fail; a camber does not); 0: off (the lane height alone decides), m.")


DRIVING = ("driving", "bidirectional", "stop", "entry", "exit", "onramp", "offramp")
PARKING = ("parking",)
SIDEWALK = ("sidewalk",)
#: the lane kinds the drop test measures apart, each with its lane types
KINDS = {"driving": DRIVING, "parking": PARKING, "sidewalk": SIDEWALK}


def lane_rays(xodr_text: str, spacing_m: float = 0.1, edges: bool = False):
    """Ray positions over the lanes, site frame: {kind: (k, 3)} (x, y, lane z) for each kind of :data:`KINDS`;
    with ``edges`` also {kind: (k,)} each ray's distance to its lane's nearer border (m).

    Every lane every ``spacing_m`` (:meth:`LaneMap.lanes`: the driving lanes and the lanes reached sideways
    from them); across a lane, rays every ``spacing_m`` from border to border (half a step in from each); a
    lane of no width gets none."""
    from twinkit.street.lanes import LaneMap

    lanes = LaneMap(xodr_text, "drop_test").lanes(spacing_m)
    out: dict[str, list] = {k: [] for k in KINDS}
    edge: dict[str, list] = {k: [] for k in KINDS}
    kinds = np.full(len(lanes), "", dtype=object)
    for k, types in KINDS.items():
        kinds[lanes.is_type(*types) & (lanes.width > 1e-6)] = k
    nrm = lanes.normal
    for i in np.flatnonzero(kinds != ""):
        h = float(lanes.width[i]) / 2
        k = max(1, int(np.floor(2 * h / spacing_m)))
        off = (np.arange(k) + 0.5) * (2 * h / k) - h
        x, y, z = lanes.xyz[i]
        out[str(kinds[i])].append(np.c_[x + off * nrm[i, 0], y + off * nrm[i, 1], np.full(k, z)])
        edge[str(kinds[i])].append(h - np.abs(off))
    rays = {k: (np.vstack(v) if v else np.zeros((0, 3))) for k, v in out.items()}
    if not edges:
        return rays
    return rays, {k: (np.concatenate(v) if v else np.zeros(0)) for k, v in edge.items()}


def _clusters(xy: np.ndarray, gap_m: float) -> list[dict]:
    """Misses grouped by proximity: centre, count, extent (the longest side of their box) and width (their extent
    across their main direction: a slit along a kerb is long and narrow; a wheel or a foot drops into a hole as
    wide as itself, not as long)."""
    if len(xy) == 0:
        return []
    from twinkit.surface.linked import linked_groups

    n, lab = linked_groups(xy, gap_m)
    out = []
    for c in range(n):
        p = xy[lab == c]
        width = 0.0
        if len(p) > 2:
            q = p - p.mean(axis=0)
            width = float(np.ptp(q @ np.linalg.svd(q, full_matrices=False)[2][1]))
        out.append({"x": round(float(p[:, 0].mean()), 2), "y": round(float(p[:, 1].mean()), 2), "rays": int(len(p)),
                    "extent_m": round(float(np.ptp(p, axis=0).max()) if len(p) > 1 else 0.0, 2),
                    "width_m": round(width, 2)})
    return sorted(out, key=lambda d: -d["rays"])


def surface_under(scene, rays: np.ndarray, fall_m: float) -> np.ndarray:
    """(k,) the height of the top surface within ``fall_m`` above or below each ray's (x, y, z); nan where
    there is none (the ray falls through)."""
    import open3d as o3d

    out = np.full(len(rays), np.nan)
    if not len(rays):
        return out
    q = np.zeros((len(rays), 6), np.float32)
    q[:, :2] = rays[:, :2]
    q[:, 2] = rays[:, 2] + fall_m
    q[:, 5] = -1.0
    t = scene.cast_rays(o3d.core.Tensor(q))["t_hit"].numpy()
    ok = t <= 2 * fall_m
    out[ok] = rays[ok, 2] + fall_m - t[ok]
    return out


def continuous(rays: np.ndarray, surf: np.ndarray, spacing_m: float, window_m: float, tol_m: float) -> np.ndarray:
    """(k,) bool: the surface under each ray lies within ``tol_m`` of the surface's mean height over a
    ``window_m`` square around it (rays binned on a ``spacing_m`` grid; rays that fall through count as
    empty). A wheel rolls over a camber or a gentle slope; it catches on a crack, a step or a bump."""
    from scipy import ndimage

    ok = np.isfinite(surf)
    if not ok.any():
        return ok
    lo = rays[:, :2].min(axis=0)
    ij = np.floor((rays[:, :2] - lo) / spacing_m).astype(int)
    shape = tuple(ij.max(axis=0) + 1)
    tot = np.zeros(shape)
    cnt = np.zeros(shape)
    np.add.at(tot, (ij[ok, 0], ij[ok, 1]), surf[ok])
    np.add.at(cnt, (ij[ok, 0], ij[ok, 1]), 1.0)
    k = max(1, int(round(window_m / spacing_m)) | 1)
    tot = ndimage.uniform_filter(tot, size=k, mode="constant")
    cnt = ndimage.uniform_filter(cnt, size=k, mode="constant")
    mean = np.where(cnt > 0, tot / np.maximum(cnt, 1e-12), np.nan)[ij[:, 0], ij[:, 1]]
    return ok & (np.abs(surf - mean) <= tol_m)


#: a failing ray this close to its lane's border counts as at the lane's edge (``failing`` in drop_test.json), m
LANE_EDGE_M = 0.4


def failing_causes(fail: np.ndarray, falls: np.ndarray, r: np.ndarray, edge: np.ndarray | None,
                   open_ground=None) -> dict:
    """Why the rays that fail the gate fail (``fail``, ``falls`` (n,) bool over the rays ``r`` (n, 3)): they fall
    through ground the scan never measured (``open_ground()``, built only when a failing ray falls through: a
    :class:`twinkit.surface.watertight.OpenGround`; the lane leaves the capture), through a hole of the mesh, or
    meet a step or a bump; and how many of them lie within :data:`LANE_EDGE_M` of their lane's border (``edge``,
    m: a lane wider than the surface it is on)."""
    fall = fail & falls
    never = np.zeros(len(r), bool)
    if open_ground is not None and fall.any():
        never[fall] = open_ground().at(r[fall, :2])
    out = {"rays": int(fail.sum()), "fall_unscanned": int(never.sum()), "fall_hole": int((fall & ~never).sum()),
           "step_or_bump": int((fail & ~falls).sum())}
    if edge is not None:
        out["at_lane_edge"] = int((fail & (edge < LANE_EDGE_M)).sum())
    return out


def check_lane(kind: str, r: np.ndarray, need: float, mesh, scene, params: DropTestParams,
               edge: np.ndarray | None = None, open_ground=None) -> tuple[dict, list, np.ndarray]:
    """One lane type's rays against the mesh: the ``drop_test.json`` record of that lane type, its holes, its misses.

    ``r``: (n, 3) float rays inside the site (x, y, the lane's height; site frame, m); ``need``: the target
    share, %; ``mesh``: the static mesh (``vertices``, ``faces``) and ``scene`` its BVH. The record holds the
    hits, the share, the falls through, the kerb-line misses, the continuity share, the miss clusters and
    why the rays that fail the gate fail (``failing``: :func:`failing_causes`, with ``edge`` each ray's
    distance to its lane's border and ``open_ground`` a function giving the ground the scan never measured); the
    holes are the clusters of rays that fall through (``_clusters`` records); the misses the (m, 3) rays that
    miss.
    """
    from twinkit.surface.watertight import drop_test

    if kind == "sidewalk":
        # no <height> in the map: the pavement may sit up to curb_max_m above the road
        band = np.arange(0.0, params.curb_max_m + 1e-9, params.tol_m)
        hit = np.zeros(len(r), bool)
        for dz in band:
            todo = ~hit
            hit[todo] = drop_test(mesh.vertices, mesh.faces, r[todo] + [0, 0, dz], params.tol_m, scene=scene)
    else:
        hit = drop_test(mesh.vertices, mesh.faces, r, params.tol_m, scene=scene)
    n = int(len(r))
    pct = round(100.0 * float(hit.mean()), 3) if n else None
    # a miss either falls through (no surface within fall_m of the lane: a hole) or finds the surface at
    # another height (a kerb face under the lane's edge, a bump): told apart for the reader
    falls = np.zeros(len(r), bool)
    if (~hit).any():
        falls[~hit] = ~drop_test(mesh.vertices, mesh.faces, r[~hit], params.fall_m, scene=scene)
    kerb = kerb_line(r, hit, falls, mesh, scene, params)
    holes = _clusters(r[falls, :2], 3 * params.spacing_m)
    widest = max((h["width_m"] + params.spacing_m for h in holes), default=0.0)
    nk = n - int(kerb.sum())
    pct_ground = round(100.0 * float(hit.sum()) / nk, 3) if nk else None
    # a parking lane's outer edge runs over the kerb's foot by design (its tyres stand off the kerb): its share
    # against the target is counted off the kerb line; driving and sidewalk lanes count every ray
    measured = "hit_pct_off_kerb_line" if kind == "parking" and pct_ground is not None else "hit_pct"
    share = pct_ground if measured == "hit_pct_off_kerb_line" else pct
    ok = (share is None or share >= need) and widest <= params.max_hole_m
    # the surface's continuity (the ground a wheel rolls on, whatever the lane's one height says)
    pct_cont = None
    held = hit | kerb  # the rays the gate's figure counts as holding: found off the kerb line...
    if n and params.local_window_m > 0:
        cont = continuous(r, surface_under(scene, r, params.fall_m), params.spacing_m, params.local_window_m,
                          params.tol_m)
        pct_cont = round(100.0 * float((cont | hit).mean()), 3)
        if pct_ground is None or pct_cont >= pct_ground:
            held = cont | hit  # ...or on a continuous surface, whichever figure is the gate's
    best = max([x for x in (pct_ground, pct_cont) if x is not None], default=None)
    lane = {"rays": n, "hits": int(hit.sum()), "hit_pct": pct, "target_pct": need, "target_on": measured, "ok": ok,
            "kerb_line": int(kerb.sum()),
            "kerb_line_pct": round(100.0 * float(kerb.mean()), 3) if n else None,
            "hit_pct_off_kerb_line": pct_ground,
            "continuous_pct": pct_cont,
            "ground_ok": (best is None or best >= need) and widest <= params.max_hole_m,
            "fall_through": int(falls.sum()),
            "fall_through_pct": round(100.0 * float(falls.mean()), 3) if n else None,
            "miss_clusters": _clusters(r[~hit, :2], 3 * params.spacing_m)[:50],
            "fall_through_clusters": holes[:50], "widest_hole_m": round(widest, 3),
            "failing": failing_causes(~held, falls, r, edge, open_ground)}
    return lane, holes, r[~hit]


def kerb_line(r: np.ndarray, hit: np.ndarray, falls: np.ndarray, mesh, scene, params: DropTestParams) -> np.ndarray:
    """(n,) bool: the misses on a kerb line among rays ``r`` (n, 3), given their ``hit`` and ``falls`` (n,) bool.

    A miss on a kerb line: the surface there stands a kerb above the lane, and the lane's height is found
    within one ray spacing beside it (the lane's edge runs a few cm over the kerb: where the map meets the
    scan, not a gap in the ground).
    """
    from twinkit.surface.watertight import drop_test

    kerb = np.zeros(len(r), bool)
    off = ~hit & ~falls
    if off.any():
        ro = r[off]
        up = drop_test(mesh.vertices, mesh.faces, ro + [0, 0, (params.curb_max_m + params.tol_m) / 2],
                       (params.curb_max_m + params.tol_m) / 2, scene=scene)
        beside = np.zeros(len(ro), bool)
        for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            todo = up & ~beside
            beside[todo] = drop_test(mesh.vertices, mesh.faces,
                                     ro[todo] + [dx * params.spacing_m, dy * params.spacing_m, 0], params.tol_m,
                                     scene=scene)
        kerb[np.flatnonzero(off)[up & beside]] = True
    return kerb


def log_lane(log, kind: str, lane: dict, holes: list, params: DropTestParams, png_name: str) -> None:
    """Log one lane type's result: a hole too wide, a share below its target, or the share."""
    n, pct, need = lane["rays"], lane["hit_pct"], lane["target_pct"]
    widest = max((h["width_m"] + params.spacing_m for h in holes), default=0.0)
    if n and widest > params.max_hole_m:
        wh = max(holes, key=lambda h: h["width_m"])
        log.warning("drop test: a hole %.2f m wide (%.2f m long) at (%.1f, %.1f) under a %s lane (more than %.2f m: "
                    "a wheel or a foot drops in)", widest, wh["extent_m"] + params.spacing_m, wh["x"], wh["y"], kind,
                    params.max_hole_m)
    if n and not lane["ok"] and lane[lane["target_on"]] < need:
        log.warning("drop test: %.2f %% of %d rays over %s lanes find the ground (target %.1f %%; %.3f %% "
                    "fall through, %.3f %% meet a kerb beside the lane's height (the lane's edge over the "
                    "kerb), the others the surface at another height); largest gap at (%.1f, %.1f), see %s",
                    pct, n, kind, need, lane["fall_through_pct"], lane["kerb_line_pct"],
                    lane["miss_clusters"][0]["x"], lane["miss_clusters"][0]["y"], png_name)
    elif n:
        log.info("drop test: %.2f %% of %d rays over %s lanes find the ground", pct, n, kind)
    elif kind == "parking":
        log.info("drop test: no parking lane of the map lies inside the scanned site")
    else:
        log.warning("drop test: no %s lane of the map lies inside the scanned site", kind)


def degraded_lanes(res: dict, params: DropTestParams, png_name: str, from_scan: bool) -> list[tuple[str, str]]:
    """(what, hint) for each lane type whose ground fails: a wheel or a foot drops in, not fit to drive on.

    Misses on a kerb line are the map's lane edge over the scanned kerb: a warning, not a failed ground.
    """
    out = []
    for kind, lane in res["lanes"].items():
        if lane["rays"] and not lane["ground_ok"]:
            hole = lane["widest_hole_m"] > params.max_hole_m
            misses_n = lane["rays"] - lane["hits"]
            at_height = misses_n - lane["fall_through"]  # the ground is there, at another height than the lane
            hint = f"misses in orange in {png_name}"
            if hole:
                hint += "; the clean step fills scan gaps up to steps.clean.fill_ground_max_gap_m"
            if misses_n and at_height > 0.5 * misses_n:
                hint += (f"; {100 * at_height / misses_n:.0f} % of the misses find the ground at another height than "
                         "the lane (a cambered or rough road, a lane over a kerb or an object)")
            why = lane.get("failing") or {}
            if why.get("rays") and why["fall_unscanned"] > 0.5 * why["rays"]:
                hint += "; most of them run off the captured ground: crop the map to the capture, or capture further"
            elif why.get("rays") and why.get("at_lane_edge", 0) > 0.5 * why["rays"]:
                hint += "; most of them lie at a lane's edge: the lanes are wider than the surface they lie on there"
            if from_scan:
                hint += ("; the lanes were derived from the scan (road_source=scan): see scan_roads.png, or give an "
                         "OSM extract (site.inputs.osm) for the map")
            best = ground_share(lane)
            best = lane["hit_pct"] if best is None else best
            out.append((f"drop test over {kind} lanes: {lane['hit_pct']:.2f} % of {lane['rays']} rays find the "
                        f"ground within {params.tol_m:g} m of the lane's height, {best:.2f} % off the kerb line or on "
                        f"a continuous surface (target {lane['target_pct']} %)"
                        + (f", and a hole {lane['widest_hole_m']:.2f} m wide (more than {params.max_hole_m} m)"
                           if hole else "") + _causes(why), hint))
    return out


def _causes(why: dict) -> str:
    """The message's account of the failing rays (``failing_causes``), or nothing without any."""
    if not why.get("rays"):
        return ""
    edge = f"; {why['at_lane_edge']} of them within {LANE_EDGE_M} m of a lane's edge" if "at_lane_edge" in why else ""
    return (f" (of the {why['rays']} rays that fail: {why['fall_unscanned']} fall through ground the scan never "
            f"measured, {why['fall_hole']} through holes in the mesh, {why['step_or_bump']} meet a step or a bump"
            f"{edge})")


def border_over_lanes(vertices: np.ndarray, ein: np.ndarray, drv: np.ndarray, spacing_m: float) -> dict:
    """The open border over the driving lanes: its length, its chains and where they are (longest first).

    ``ein``: (e, 2) int open border edges inside the site (any height within 0.5 m of the ground) into
    ``vertices`` (v, 3) float; ``drv``: (n, 3) driving-lane rays inside the site. An edge counts when its
    middle has a ray within ``spacing_m``; chains of them are loops a wheel can catch on.
    """
    over_m, over_chains = 0.0, 0
    over_at: list[dict] = []
    if len(drv) and len(ein):
        from scipy.spatial import cKDTree

        mid = vertices[ein].mean(axis=1)
        dd, _ = cKDTree(drv[:, :2]).query(mid[:, :2], workers=-1)
        over = dd <= spacing_m
        if over.any():
            from twinkit.surface.watertight import chains_of

            seg = np.linalg.norm(vertices[ein[over, 0]] - vertices[ein[over, 1]], axis=1)
            over_m = float(seg.sum())
            ch = chains_of(ein[over])
            over_chains = int(len(np.unique(ch)))
            for c in np.unique(ch):  # where they are (the longest first), for the log and the picture's reader
                k = ch == c
                p = mid[over][k]
                over_at.append({"x": round(float(p[:, 0].mean()), 2), "y": round(float(p[:, 1].mean()), 2),
                                "length_m": round(float(seg[k].sum()), 2),
                                "z_min": round(float(p[:, 2].min()), 3), "z_max": round(float(p[:, 2].max()), 3)})
    return {"open_border_over_driving_lanes_m": round(over_m, 2), "open_chains_over_driving_lanes": over_chains,
            "open_chains_over_driving_lanes_at": sorted(over_at, key=lambda c: -c["length_m"])[:20]}


def drop_test_step(params: DropTestParams, ctx: StepContext, *, in_textured_mesh_obj: Path, in_aligned_xodr: Path,
                   in_points_ply: Path, out_drop_test_json: Path, out_drop_test_png: Path) -> dict:
    """Vertical rays on a 10 cm grid over every driving, parking and sidewalk lane: share that finds the ground."""
    from twinkit import artefacts as A
    from twinkit.geo.xodr import from_scan
    from twinkit.jsonio import write_json
    from twinkit.surface.closest import Surface
    from twinkit.surface.watertight import Footprint, OpenGround, at_ground_level, draw_border, ground_border

    params = params or DropTestParams()
    t0 = time.perf_counter()
    mesh = A.read_textured_obj(in_textured_mesh_obj)
    cloud = A.read_points(in_points_ply)
    text = A.read_opendrive(in_aligned_xodr)
    scan_lanes = from_scan(text)
    try:
        rays, edges = lane_rays(text, params.spacing_m, edges=True)
    except Exception as exc:
        raise InputError(f"{in_aligned_xodr}: carla.Map could not read it ({exc}); re-run the road steps") from None
    fp = Footprint.from_points(cloud.vertices, fill_limit_m=params.fill_limit_m, margin_m=params.footprint_margin_m)
    scene = Surface(mesh.vertices, mesh.faces).scene  # one BVH for every set of rays below
    # where the capture ends: rasterised once, and only when a failing ray falls through (0.9 s on the demo)
    never = functools.cache(lambda: OpenGround.of_mesh(mesh.vertices, mesh.faces, params.fill_limit_m))
    res: dict = {"spacing_m": params.spacing_m, "tol_m": params.tol_m, "lanes": {}}
    png, misses = Path(out_drop_test_png).name, []
    for kind, need in (("driving", params.min_driving_pct), ("parking", params.min_parking_pct),
                       ("sidewalk", params.min_sidewalk_pct)):
        keep = fp.inside(rays[kind]) if len(rays[kind]) else np.zeros(0, bool)
        res["lanes"][kind], holes, miss = check_lane(kind, rays[kind][keep], need, mesh, scene, params,
                                                     edges[kind][keep], never)
        misses.append(miss)
        log_lane(ctx.log, kind, res["lanes"][kind], holes, params, png)
    res["ok"] = bool(all(lane["ok"] for lane in res["lanes"].values()))
    failed = degraded_lanes(res, params, png, scan_lanes)
    for kind, lane in res["lanes"].items():
        if not lane["rays"]:
            continue
        what, hint = next(((w, h) for w, h in failed if f" over {kind} lanes:" in w), (None, None))
        ctx.gate(f"ground {kind}", ground_share(lane), lane["target_pct"], ">=", "%", why="rays that find the ground (off the "
                 "kerb line) or a continuous surface: a car or a walker stands there", hint=hint, reason=what)
        ctx.gate(f"widest hole {kind}", lane["widest_hole_m"], params.max_hole_m, "<=", "m",
                 why="a wider hole swallows a tyre's contact patch or a shoe", hint=hint, reason=what)
    gv = at_ground_level(mesh.vertices, cloud.vertices, cloud.normals)
    border = ground_border(mesh.vertices, mesh.faces, fp, gv)
    edges = border.pop("_edges")
    res["open_border_at_ground_level"] = border
    drv = rays["driving"][fp.inside(rays["driving"])] if len(rays["driving"]) else rays["driving"]
    res.update(border_over_lanes(mesh.vertices, edges["inside"], drv, params.spacing_m))
    d, pk, s = res["lanes"]["driving"], res["lanes"]["parking"], res["lanes"]["sidewalk"]
    draw_border(out_drop_test_png, mesh.vertices, mesh.faces, edges, ground_face=gv[mesh.faces].all(axis=1),
                misses=np.vstack(misses) if misses else None,
                title=f"drop test: driving {d['hit_pct']} %, parking {pk['hit_pct']} %, sidewalk {s['hit_pct']} % of "
                      f"rays hit; misses orange, open border red")
    res["seconds"] = round(time.perf_counter() - t0, 2)
    write_json(out_drop_test_json, res)
    return {"ok": res["ok"], "driving_hit_pct": d["hit_pct"], "sidewalk_hit_pct": s["hit_pct"],
            "parking_hit_pct": pk["hit_pct"], "parking_rays": pk["rays"], "parking_widest_hole_m": pk["widest_hole_m"],
            "sidewalk_widest_hole_m": s["widest_hole_m"], "driving_widest_hole_m": d["widest_hole_m"],
            "driving_fall_through_pct": d["fall_through_pct"], "sidewalk_fall_through_pct": s["fall_through_pct"],
            "driving_kerb_line_pct": d["kerb_line_pct"], "driving_hit_pct_off_kerb_line": d["hit_pct_off_kerb_line"],
            "driving_continuous_pct": d["continuous_pct"], "sidewalk_continuous_pct": s["continuous_pct"],
            "driving_rays": d["rays"], "sidewalk_rays": s["rays"],
            "open_border_inside_m": border["inside_m"],
            "open_border_over_driving_lanes_m": res["open_border_over_driving_lanes_m"],
            "open_chains_over_driving_lanes": res["open_chains_over_driving_lanes"], "seconds": res["seconds"]}

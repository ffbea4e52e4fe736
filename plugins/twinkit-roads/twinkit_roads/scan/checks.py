"""The derived network against the scan: lanes that leave scanned ground are cut, narrowed, moved or their
junctions taken apart (``trim_unsupported`` before netconvert, ``check_lanes`` on netconvert's map)."""
from __future__ import annotations

import dataclasses

import numpy as np

from .geometry import lanes_reach, normals, true_runs
from .model import Network, NoRoads, ScanSourceParams

#: sidewalk lanes are checked in this many bands from the kerb outwards (``check_sidewalks``)
SIDEWALK_COLUMNS = 7


def trim_unsupported(net: Network, v, f, p: ScanSourceParams, tol_m: float = 0.3, min_support: float = 0.8,
                     scene=None) -> dict:
    """A derived lane must lie on scanned ground. Along each road, the share of its carriageway's cross
    section (7 samples, 0.3 m in from each edge) where a vertical ray meets the surface within ``tol_m`` of
    the road's height there; from a road's free end (not a junction) the road is cut back while that share is under
    ``min_support`` (a road that bends where the scan ends and runs on into a wall, Lille); inside a road, 2 or
    more unsupported shape points in a row (a few metres under a roof or over a gap, IGN) split it into two
    roads with new ends; a piece shorter than ``min_road_length_m`` is dropped, and so are the nodes it leaves
    alone. Returns what was cut."""
    import open3d as o3d

    from twinkit.surface.closest import Surface

    if scene is None:
        scene = Surface(np.asarray(v, np.float64), np.asarray(f)).scene
    bad: dict[int, np.ndarray] = {}
    for k, arm in enumerate(net.arms):
        if arm.z is None or len(arm.xy) < 3:
            continue
        nrm = normals(arm.xy)
        half = max(arm.width_m / 2 - 0.3, 0.0)
        across = np.linspace(-half, half, 7)
        q = arm.xy[:, None, :] + across[None, :, None] * nrm[:, None, :]
        rays = np.zeros((q.shape[0] * q.shape[1], 6), np.float32)
        rays[:, :2] = q.reshape(-1, 2)
        rays[:, 2] = np.repeat(arm.z, q.shape[1]) + tol_m
        rays[:, 5] = -1.0
        t = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()  # the surface within tol_m of the road's height
        frac = (t <= 2 * tol_m).reshape(q.shape[:2]).mean(axis=1)
        bad[k] = frac < min_support
    out = cut_arms(net, bad, p)
    net.stats["unsupported"] = out
    if not net.arms:
        raise NoRoads("none of the roads derived from the scan lies on scanned ground (their lanes run over walls, "
                      "roofs or gaps)", derived=True)
    return out


def cut_arms(net: Network, bad: dict[int, np.ndarray], p: ScanSourceParams, keep_junction_ends: bool = True) -> dict:
    """Cut the arms (index -> per-shape-point bool, True where the road is not on the scan): from a free end
    the road is cut back over its bad points (from a junction too unless ``keep_junction_ends``: the road
    then leaves the junction and ends where it is on the scan again); inside, 2 or more bad points in a row
    split it into two roads with new ends; a piece shorter than ``min_road_length_m`` is dropped, and so are
    the nodes left alone."""
    cut_m, dropped = 0.0, 0
    keep = []
    for k, arm in enumerate(net.arms):
        b = bad.get(k)
        if b is None or not b.any():
            keep.append(arm)
            continue
        n = len(b)
        keep_pt = np.ones(n, bool)
        for i, j in true_runs(b):  # runs of unsupported shape points
            at_a, at_b = i == 0, j == n
            if at_a and at_b:
                keep_pt[:] = False
            elif at_a:  # a junction end stays (the junction needs it) when keep_junction_ends
                keep_pt[i:j] = keep_junction_ends and net.nodes[arm.a]["kind"] != "end"
            elif at_b:
                keep_pt[i:j] = keep_junction_ends and net.nodes[arm.b]["kind"] != "end"
            elif j - i >= 2:  # inside the road: 2+ points (a few metres) under a roof or over a gap split it
                keep_pt[i:j] = False
        if keep_pt.all():
            keep.append(arm)
            continue
        full = float(np.hypot(*np.diff(arm.xy, axis=0).T).sum())
        kept_len = 0.0
        for i, j in true_runs(keep_pt):
            seg = arm.xy[i:j]
            length = float(np.hypot(*np.diff(seg, axis=0).T).sum()) if len(seg) > 1 else 0.0
            if length >= p.min_road_length_m and len(seg) >= 3:
                piece = dataclasses.replace(arm, xy=seg, **{k: getattr(arm, k)[i:j] for k in ("z", "z_left", "z_right")
                                                            if getattr(arm, k) is not None})
                for end_idx, attr in ((i, "a"), (j - 1, "b")):
                    if (attr == "a" and i == 0) or (attr == "b" and j == n):
                        continue  # the road's own node
                    nid = max(net.nodes) + 1
                    net.nodes[nid] = {"xy": arm.xy[end_idx], "z": float(arm.z[end_idx]) if arm.z is not None else 0.0,
                                      "kind": "end"}
                    setattr(piece, attr, nid)
                keep.append(piece)
                kept_len += length
            else:
                dropped += 1 if (i == 0 and j == n) else 0
        if kept_len == 0.0:
            dropped += 1
        cut_m += full - kept_len
    net.arms = keep
    used = {n for arm in keep for n in (arm.a, arm.b)}
    net.nodes = {k: nd for k, nd in net.nodes.items() if k in used}
    return {"cut_m": round(cut_m, 1), "dropped_roads": dropped}


def lane_heights(xodr_text: str, v, f, tol_m: float = 0.3, spacing_m: float = 1.0, above_m: float = 1.0,
                 below_m: float = 3.0, covered_m: float = 15.0, scene=None, step_m: float = 0.0,
                 edge_in_m: float = 0.05, clear_m: float = 0.0, parked: np.ndarray | None = None,
                 unscanned=None) -> dict:
    """Do the driving lanes carla.Map reads from the OpenDRIVE lie on the scanned surface at their heights?
    Samples every ``spacing_m`` along each driving lane, 7 across it (the outermost ``edge_in_m`` inside its
    borders). A sample is **on** when the surface
    lies within ``tol_m`` of the lane's height; **off** when it lies elsewhere: up to ``below_m`` under the
    lane (the lane floats over a bank or a yard), up to ``above_m`` over it (the lane is buried in a
    slope), or not at all under a roof up to ``covered_m`` over the lane (it runs into a house); a hole in the
    mesh is left to the drop test, unless ``unscanned`` (a :class:`twinkit.surface.watertight.OpenGround`)
    marks it as ground the scan never measured (a sweep's far range, beyond the scan's edge): then it is off.
    With ``step_m`` > 0, a sample is also off when the surface
    between it and the lane's middle steps by more than ``step_m`` from one sample to the next (the lane's
    edge over a low wall or a yard above the street: within ``tol_m``, yet no road). With ``clear_m`` > 0, a
    sample with any surface over it less than ``clear_m`` above the lane is off too, ground or not (a hedge,
    a wall's top, a low roof: a car drives into it). ``parked`` (per face, bool): faces of parked vehicles;
    a sample whose top or overhead surface is one is judged by the ground alone (no step, clearance or
    buried test: the car is taken out later, not a wall). Returns the samples' x, y, whether on and
    off, whether off for want of any scanned surface (``bare``), the junction (its OpenDRIVE name,
    netconvert's node id) of those inside one ('' elsewhere), and each sample's OpenDRIVE road, its s along it
    and its lane's centre (x, y)."""
    import open3d as o3d

    from twinkit.street.lanes import LaneMap
    from twinkit.surface.closest import Surface

    wp = LaneMap(xodr_text, "scan_lane_heights").waypoints(spacing_m)
    wp = wp.take(wp.is_type("driving"))
    if not len(wp):
        return {"xy": np.zeros((0, 2)), "on": np.zeros(0, bool), "off": np.zeros(0, bool), "bare": np.zeros(0, bool),
                "junction": np.zeros(0, str), "road": np.zeros(0, int), "s": np.zeros(0), "centre": np.zeros((0, 2))}
    across = np.linspace(-0.5, 0.5, 7)  # border to border, the outermost edge_in_m in (where a tyre's edge runs)
    off = across[None, :] * np.maximum(wp.width - 2 * edge_in_m, 0.0)[:, None]  # (waypoints, 7)
    r = np.stack([wp.xyz[:, :1] + off * wp.right[:, :1], wp.xyz[:, 1:2] + off * wp.right[:, 1:2],
                  np.broadcast_to(wp.xyz[:, 2:], off.shape)], -1).reshape(-1, 3)
    names = _junction_names(xodr_text)
    junc = np.repeat([names.get(int(j), str(int(j))) if j >= 0 else "" for j in wp.junction], len(across))
    if scene is None:
        scene = Surface(np.asarray(v, np.float64), np.asarray(f)).scene

    def cast(z0, dz):  # distance to the first surface under (dz -1) or over (dz 1) z0 (inf: none); is it parked
        q = np.zeros((len(r), 6), np.float32)
        q[:, :2] = r[:, :2]
        q[:, 2] = z0
        q[:, 5] = dz
        hit = scene.cast_rays(o3d.core.Tensor(q))
        t, pid = hit["t_hit"].numpy(), hit["primitive_ids"].numpy()
        car = np.zeros(len(r), bool) if parked is None else np.isfinite(t) & parked[np.minimum(pid, len(parked) - 1)]
        return t, car

    t_mid = cast(r[:, 2] + tol_m, -1.0)[0]
    on = t_mid <= 2 * tol_m
    below = t_mid <= tol_m + below_m
    t_top, car_top = cast(r[:, 2] + above_m, -1.0)  # the top surface, from above_m over the lane
    above = (t_top <= above_m - tol_m) & ~car_top
    t_up, car_up = cast(r[:, 2] + tol_m, 1.0)  # a roof over a lane with no ground under it: it runs into a house
    covered = (t_up <= covered_m) & ~car_up
    off = ~on & (below | above | covered)
    if clear_m > 0:
        low = (t_up <= clear_m - tol_m) & ~car_up
        off |= low
        on &= ~low
    if step_m > 0:
        top = np.where((t_top <= above_m + below_m) & ~car_top, r[:, 2] + above_m - t_top, np.nan)
        stepped = steps_across(top, len(across), step_m)
        off |= stepped
        on &= ~stepped
    bare = np.zeros(len(r), bool)
    if unscanned is not None:
        bare = ~on & ~off & unscanned.at(r[:, :2])
        off |= bare
    k = len(across)
    return {"xy": r[:, :2], "on": on, "off": off, "bare": bare, "junction": junc, "road": np.repeat(wp.road, k),
            "s": np.repeat(wp.s, k), "centre": np.repeat(wp.xyz[:, :2], k, axis=0)}


def bare_turns(lh: dict, min_samples: int, which: str = "bare") -> list[tuple[int, np.ndarray, np.ndarray]]:
    """The junctions' turns (connecting roads, in ``lane_heights``' samples ``lh``) with at least ``min_samples``
    samples over ground the scan never measured (``which`` "bare"; "off": off the scanned surface for any reason,
    a raised verge or a kerb at a corner included), when another turn of the same junction starts where it does
    (the lane keeps a way on): (node id, where the turn starts, where it ends), the lane centres at its first and
    last sample. None with ``min_samples`` 0."""
    jn, bare, road = lh["junction"], lh[which], lh["road"]
    inside = jn != ""
    if min_samples <= 0 or not (inside & bare).any():
        return []
    turns = {}
    for rid in np.unique(road[inside]):
        m = inside & (road == rid)
        s, c = lh["s"][m], lh["centre"][m]
        turns[int(rid)] = (str(jn[m][0]), int(bare[m].sum()), c[np.argmin(s)], c[np.argmax(s)])
    out = []
    for rid, (name, n_bare, a, b) in turns.items():
        if n_bare < min_samples or not name[1:].isdigit():
            continue
        if any(r != rid and nm == name and np.hypot(*(a2 - a)) < 1.0 for r, (nm, _, a2, _) in turns.items()):
            out.append((int(name[1:]), a, b))
    return out


def new_turns(turns: list, known: list) -> list:
    """The turns ((node id, start, end), as ``bare_turns`` gives them) not in ``known`` nor earlier in ``turns``:
    the same junction's node, starting and ending within a metre of one there."""
    out: list = []
    for t in turns:
        if not any(t[0] == u[0] and np.hypot(*(t[1] - u[1])) < 1.0 and np.hypot(*(t[2] - u[2])) < 1.0
                   for u in [*known, *out]):
            out.append(t)
    return out


def _junction_names(xodr_text: str) -> dict[int, str]:
    """OpenDRIVE junction id -> its name (netconvert's node id), either attribute order."""
    import re

    names = {int(i): nm for nm, i in re.findall(r'<junction\s+name="([^"]*)"\s+id="(-?\d+)"', xodr_text)}
    names.update({int(i): nm for i, nm in re.findall(r'<junction\s+id="(-?\d+)"\s+name="([^"]*)"', xodr_text)})
    return names


def parked_faces(f, labels, curbs: bool) -> np.ndarray | None:
    """Faces of parked vehicles (2 or more vertices labelled car, truck, bus, train, motorcycle or bicycle), for
    the lane check; None without labels or from the air (``curbs`` false: a car is a low lump without walls there,
    which lift_movables rarely takes out, so it stays an obstacle)."""
    from twinkit.cityscapes import COARSE

    if labels is None or not curbs:
        return None
    return np.isin(labels[f], COARSE["vehicle"]).sum(axis=1) >= 2


def steps_across(top: np.ndarray, k: int, step_m: float) -> np.ndarray:
    """(n,) bool for lane samples laid out ``k`` across per cross-section (consecutive entries of ``top``, the
    height of the top surface under each, nan where there is none): the surface changes by more than
    ``step_m`` from one sample to the next between this sample and the lane's middle one. Where a sample has
    no surface (an open hole, left to the drop test), no step is counted on either side of it."""
    z = top.reshape(-1, k)
    mid = k // 2
    out = np.zeros(z.shape, bool)
    with np.errstate(invalid="ignore"):
        right = np.abs(np.diff(z[:, mid:], axis=1)) > step_m  # mid -> k-1
        left = np.abs(np.diff(z[:, mid::-1], axis=1)) > step_m  # mid -> 0
    out[:, mid + 1:] = np.logical_or.accumulate(right, axis=1)
    out[:, mid - 1::-1] = np.logical_or.accumulate(left, axis=1)
    return out.ravel()


def check_lanes(net: Network, xodr_text: str, v, f, p: ScanSourceParams, scene=None,
                parked: np.ndarray | None = None, unscanned=None) -> dict:
    """The map netconvert built from the derived network, against the scan (``lane_heights``): per road,
    the shape points whose driving lanes are off the surface on more than ``1 - min_lane_support`` of their
    samples; per junction, the same share over its connecting lanes. Returns ``{"bad_points": {arm index:
    bool array}, "bad_junctions": {node id: share on}, "on_share": share of all samples on}``. ``parked``: the
    faces of parked vehicles (``parked_faces``), judged by the ground under them; ``unscanned``: the ground the
    scan never measured (``OpenGround``), off the scan (``bare_samples`` counts those samples)."""

    lh = lane_heights(xodr_text, v, f, tol_m=p.lane_tol_m, scene=scene, step_m=p.lane_step_m, clear_m=p.lane_clear_m,
                      parked=parked, unscanned=unscanned)
    on, off, jn, xy = lh["on"], lh["off"], lh["junction"], lh["xy"]
    res = {"bad_points": {}, "bad_junctions": {}, "narrow": {}, "nudge": {}, "samples": int(len(on)),
           "bare_samples": int(lh["bare"].sum()),
           "bad_turns": new_turns(bare_turns(lh, p.turn_unscanned_samples) + bare_turns(lh, p.turn_off_samples, "off"),
                                  []),  # a turn over ground never measured is off the surface too: listed once
           "on_share": round(float(on.sum() / max((on | off).sum(), 1)), 4)}
    judged = on | off
    for nid in net.nodes:
        s = (jn == f"n{nid}") & judged
        if s.sum() >= 10:
            share = float(on[s].mean())
            if share < p.min_lane_support:
                res["bad_junctions"][nid] = round(share, 3)
    road = (jn == "") & judged
    if not road.any() or not net.arms:
        return res
    owner = np.concatenate([np.full(len(a.xy), k) for k, a in enumerate(net.arms)])
    index = np.concatenate([np.arange(len(a.xy)) for a in net.arms])
    half = np.concatenate([np.full(len(a.xy), a.width_m / 2 + 1.0) for a in net.arms])
    d, i, arm_of, lateral = nearest_axis(net, xy[road])
    near = d <= half[i]
    src = np.flatnonzero(road)[near]
    i, arm_of, lateral = i[near], arm_of[near], lateral[near]
    n_on = np.bincount(i, weights=on[src].astype(float), minlength=len(owner))
    n_all = np.bincount(i, minlength=len(owner)).astype(float)
    bad_pt = (n_all >= 5) & (n_on < p.min_lane_support * n_all)
    n_bare = np.bincount(i, weights=lh["bare"][src].astype(float), minlength=len(owner))
    bare_pt = (n_all >= 5) & (n_bare > p.end_unscanned_share * n_all)
    bad_pt |= (n_all >= 5) & (n_bare > p.inner_unscanned_share * n_all)
    sparse_pt = n_all < 5
    for k, arm in enumerate(net.arms):
        order = np.argsort(index[owner == k])
        b = bad_pt[owner == k][order]
        _cut_bare_ends(b, bare_pt[owner == k][order], sparse_pt[owner == k][order],
                       [net.nodes.get(arm.a, {}).get("kind") == "end", net.nodes.get(arm.b, {}).get("kind") == "end"])
        if b.any():
            res["bad_points"][k] = b
    # each side's outermost edge_band_m: off the scan along the road while the rest of that side is on (the
    # lanes wider than the paved band: a path between grass, a lane edge on a wall's foot) -> narrower
    if p.edge_band_m <= 0:
        return res
    # ground the scan never measured cuts a road (above) but moves no edge: a mesh's open border beside a lane is
    # no obstacle to move away from, and a narrowed road moves its lanes towards the other side's kerb
    edge_off = (off & ~lh["bare"])[src]
    res["narrow"] = _narrow_sides(net, p, lateral, edge_off, arm_of)
    res["nudge"] = _nudge_stretches(net, p, lateral, edge_off, arm_of, i, res["narrow"])
    return res


def _cut_bare_ends(bad: np.ndarray, bare: np.ndarray, sparse: np.ndarray, free: list[bool]) -> None:
    """Mark in ``bad`` (per shape point, in place) the shape points from each ``free`` end (start, end) up to the
    last one whose lanes lie over ground the scan never measured (``bare``), walking on over points with too few
    samples to judge (``sparse``): a road's free end lies where the capture or its carriageway ends, and a lane
    there is either whole on the scanned ground or it is cut back to where it is."""
    n = len(bad)
    for at_start, is_free in zip((True, False), free):
        if not is_free:
            continue
        seq = range(n) if at_start else range(n - 1, -1, -1)
        last = None
        for j in seq:
            if bare[j]:
                last = j
            elif not sparse[j]:
                break
        if last is not None:
            if at_start:
                bad[:last + 1] = True
            else:
                bad[last:] = True


def nearest_axis(net: Network, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Points (k, 2) against the network's axes: the distance to the nearest axis point, its index over all the
    arms' points in order, the arm it belongs to, and the point's offset to the left of that road's direction."""
    from scipy.spatial import cKDTree

    axis = np.concatenate([a.xy for a in net.arms])
    owner = np.concatenate([np.full(len(a.xy), k) for k, a in enumerate(net.arms)])
    nrm = np.concatenate([normals(a.xy) for a in net.arms])
    d, i = cKDTree(axis).query(xy)
    return d, i, owner[i], ((xy - axis[i]) * nrm[i]).sum(axis=1)


def _narrow_sides(net: Network, p: ScanSourceParams, lateral, off_s, arm_s) -> dict[int, list[int]]:
    """Arm index -> the sides (+1 left, -1 right) whose outermost ``edge_band_m`` is off the scan along the road
    while the rest of that side is on. ``lateral`` (k,) m left of the axis, ``off_s`` (k,) bool and ``arm_s``
    (k,) the arm of each road sample near an axis."""
    bad_share = 1.0 - p.min_lane_support
    narrow = {}
    for k, arm in enumerate(net.arms):
        reach = lanes_reach(arm, p)
        sides = []
        for sgn, walk in ((1, arm.sidewalk_left_m), (-1, arm.sidewalk_right_m)):
            if walk > 0:  # a sidewalk lane lies beyond: that edge is a kerb, drawn from the scan's curbs
                continue
            side = (arm_s == k) & (sgn * lateral > 0)
            outer = side & (sgn * lateral > reach - p.edge_band_m)
            inner = side & ~outer
            if (outer.sum() >= 10 and off_s[outer].mean() > bad_share
                    and (inner.sum() < 10 or off_s[inner].mean() <= bad_share)):
                sides.append(sgn)
        if sides:
            narrow[k] = sides
    return narrow


def _nudge_stretches(net: Network, p: ScanSourceParams, lateral, off_s, arm_s, i, narrow: dict) -> dict:
    """Arm index -> per shape point +1 (move left), -1 (right) or 0: where only a stretch of one side is off (a
    hedge, a wall's corner beside the road for a few metres) while the other side's edge there is on, that
    stretch moves away from it. ``i`` (k,) the axis point (over all arms) nearest each road sample."""
    bad_share = 1.0 - p.min_lane_support
    nudge = {}
    start = np.cumsum([0] + [len(a.xy) for a in net.arms])
    for k, arm in enumerate(net.arms):
        if k in narrow or arm.sidewalk_left_m > 0 or arm.sidewalk_right_m > 0:
            continue
        reach = lanes_reach(arm, p)
        n = len(arm.xy)
        share = {}
        for sgn in (1, -1):
            sel = (arm_s == k) & (sgn * lateral > reach - p.edge_band_m)
            j = i[sel] - start[k]
            win = np.ones(5)  # about 10 m of road (shape points every sample_m)
            tot = np.convolve(np.bincount(j, minlength=n).astype(float), win, "same")
            bad = np.convolve(np.bincount(j, weights=off_s[sel].astype(float), minlength=n), win, "same")
            share[sgn] = np.where(tot >= 4, bad / np.maximum(tot, 1.0), 0.0) > bad_share
        move = share[-1].astype(float) - share[1].astype(float)  # +1: to the left (the right edge is off)
        if move.any():
            nudge[k] = move
    return nudge


def nudge_arms(net: Network, nudge: dict[int, np.ndarray], p: ScanSourceParams) -> int:
    """Move stretches of roads sideways by half ``edge_band_m`` (per shape point: +1 to the left of the road's
    direction, -1 to the right), tapered over the neighbouring points; ends at a junction stay. Returns
    how many roads moved."""
    moved = 0
    for k, mv in nudge.items():
        arm = net.arms[k]
        m = np.clip(np.convolve(mv, [0.5, 1.0, 0.5], "same"), -1.0, 1.0)
        for end, nid in ((0, arm.a), (-1, arm.b)):
            if net.nodes.get(nid, {}).get("kind") == "junction":
                m[end] = 0.0
        if not m.any():
            continue
        arm.xy = arm.xy + 0.5 * p.edge_band_m * m[:, None] * normals(arm.xy)
        moved += 1
    return moved


def check_sidewalks(net: Network, xodr_text: str, p: ScanSourceParams, scene) -> list[dict]:
    """The sidewalk lanes of netconvert's map (outside junctions) against the scan: each lane is cut into
    ``SIDEWALK_COLUMNS`` bands from the kerb outwards, sampled every metre; a sample is on when a surface lies
    from ``WALK_MAX_M`` over the lane's height (the pavement a kerb above the road) down to ``lane_tol_m`` under
    it. The bands from the kerb out that are on over at least ``min_lane_support`` of their samples are kept:
    a sidewalk whose outer part runs past the scan's edge is narrowed to them, one whose kerb band is not on
    (the pavement scanned along part of the road only) or that would be narrower than ``min_sidewalk_m`` is
    dropped (CARLA's walkers would fall through where there is no ground). Returns one row per changed side:
    ``{"road", "side", "from_m", "to_m", "kerb_band_on"}``."""
    import open3d as o3d

    from twinkit.street.lanes import LaneMap

    from .network import WALK_MAX_M

    if not net.arms or not any(a.sidewalk_left_m > 0 or a.sidewalk_right_m > 0 for a in net.arms):
        return []
    sw = LaneMap(xodr_text, "scan_sidewalks").lanes(1.0)
    sw = sw.take(sw.is_type("sidewalk") & (sw.junction < 0))
    if not len(sw):
        return []
    k = SIDEWALK_COLUMNS
    across = (np.arange(k) + 0.5) / k - 0.5  # band centres, border to border
    pts = (sw.xyz[:, None, :2] + (across[None, :] * sw.width[:, None])[..., None] * sw.normal[:, None, :]).reshape(-1, 2)
    z = np.repeat(sw.xyz[:, 2], k)
    q = np.zeros((len(pts), 6), np.float32)
    q[:, :2], q[:, 2], q[:, 5] = pts, z + WALK_MAX_M, -1.0
    on = scene.cast_rays(o3d.core.Tensor(q))["t_hit"].numpy() <= WALK_MAX_M + p.lane_tol_m
    _, _, arm_of, lateral = nearest_axis(net, pts)
    rows = []
    for j, arm in enumerate(net.arms):
        for sgn, name in ((1, "left"), (-1, "right")):
            width = arm.sidewalk_left_m if sgn > 0 else arm.sidewalk_right_m
            if width <= 0:
                continue
            beyond = sgn * lateral - arm.width_m / 2  # m past the carriageway's edge
            mine = (arm_of == j) & (beyond > -0.5) & (beyond < width + 0.5)
            if mine.sum() < 3 * k:
                continue
            band = np.clip((beyond[mine] / width * k).astype(int), 0, k - 1)
            count = np.bincount(band, minlength=k)
            share = np.bincount(band, weights=on[mine], minlength=k) / np.maximum(count, 1)
            held = (share >= p.min_lane_support) | (count == 0)  # a band without samples is not judged
            kept = int(np.argmin(np.r_[held, False]))  # the bands that hold, from the kerb out
            new = round(width * kept / k, 2)
            if kept == k:
                continue
            if new < p.min_sidewalk_m:
                new = 0.0
            setattr(arm, f"sidewalk_{name}_m", new)
            rows.append({"road": j, "side": name, "from_m": round(width, 2), "to_m": new,
                         "kerb_band_on": round(float(share[0]), 3)})
    return rows


def narrow_arms(net: Network, narrow: dict[int, list[int]], p: ScanSourceParams) -> int:
    """Take ``edge_band_m`` off the given sides (+1 left, -1 right) of the arms: the carriageway width shrinks
    and the axis moves half that away from each trimmed side (not below ``min_road_width_m``). Returns
    how many roads changed."""
    changed = 0
    for k, sides in narrow.items():
        arm = net.arms[k]
        width = arm.width_m - p.edge_band_m * len(sides)
        if width < p.min_road_width_m:
            continue
        arm.xy = arm.xy - 0.5 * p.edge_band_m * sum(sides) * normals(arm.xy)
        arm.width_m = width
        changed += 1
    return changed


def detach_junctions(net: Network, nodes: list[int], p: ScanSourceParams) -> int:
    """Take junctions out of the network: each road that met one is cut back to outside it (the junction's
    reach: half its widest road's width plus 2 m from its point, about where netconvert's junction shape ends)
    and ends there. Returns the roads dropped."""
    dropped = 0
    for nid in nodes:
        nd = net.nodes.get(nid)
        if nd is None:
            continue
        mine = [a for a in net.arms if nid in (a.a, a.b)]
        reach = 0.5 * max((a.width_m for a in mine), default=0.0) + 2.0
        out = []
        for arm in net.arms:  # (arms compared by identity: a dataclass of arrays has no usable ==)
            if nid not in (arm.a, arm.b):
                out.append(arm)
                continue
            far = np.flatnonzero(np.hypot(*(arm.xy - np.asarray(nd["xy"])).T) > reach)
            if arm.a == arm.b or not len(far):
                dropped += 1
                continue
            i, j = (far[0], len(arm.xy)) if arm.a == nid else (0, far[-1] + 1)
            seg = arm.xy[i:j]
            if len(seg) < 3 or float(np.hypot(*np.diff(seg, axis=0).T).sum()) < p.min_road_length_m:
                dropped += 1
                continue
            piece = dataclasses.replace(arm, xy=seg, **{a: getattr(arm, a)[i:j] for a in ("z", "z_left", "z_right")
                                                        if getattr(arm, a) is not None})
            new = max(net.nodes) + 1
            end_i = 0 if arm.a == nid else len(seg) - 1
            net.nodes[new] = {"xy": seg[end_i], "z": float(piece.z[end_i]) if piece.z is not None else 0.0,
                              "kind": "end", "signals": False}
            setattr(piece, "a" if arm.a == nid else "b", new)
            out.append(piece)
        net.arms = out
        net.nodes.pop(nid, None)
    used = {n for arm in net.arms for n in (arm.a, arm.b)}
    net.nodes = {k: nd for k, nd in net.nodes.items() if k in used}
    return dropped

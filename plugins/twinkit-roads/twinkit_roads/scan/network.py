"""The road network of a labelled mesh: axes from the carriageway's skeleton, centred between the edges,
junction points where they meet; then sidewalk widths, heights and signalised junctions."""
from __future__ import annotations

import time

import numpy as np

from twinkit.cityscapes import SIDEWALK, TRAFFIC_LIGHT

from ..mesh2d import level_faces
from .geometry import fit_axis, junction_point, lane_layout, normals, ray_lengths, resample, smooth, unit
from .masks import carriageway_mask, grey_ground, level_raster, rasterize_faces
from .model import Arm, Network, NoRoads, ScanSourceParams
from .skeleton import skeleton_graph, thin


def derive_network(v: np.ndarray, f: np.ndarray, labels: np.ndarray | None, p: ScanSourceParams,
                   log=None, *, curbs: bool = True, rgb: np.ndarray | None = None,
                   points_xy: np.ndarray | None = None) -> Network:
    """The road network of a labelled mesh (site frame): junctions, ends and the arms between them.
    ``v`` (n, 3) float vertices, ``f`` (m, 3) int triangles, ``labels`` (n,) CityScapes ids or None; ``curbs``
    false: the carriageway is grey measured ground (``rgb`` (n, 3) uint8, ``points_xy`` (k, 2) the cloud)."""
    t0 = time.perf_counter()
    grid, mask, how, level = _carriageway(v, f, labels, p, curbs, rgb, points_xy)
    node_xy, edges, n_skeleton_nodes = _skeleton_edges(mask, grid)
    edges = _prune_spurs(edges, len(node_xy), p)
    mask, bridges = bridge_gaps(mask, edges, len(node_xy), grid, v, f, p)
    if bridges:
        if log is not None:
            log.info("road_source=scan: %d gap(s) in the carriageway bridged where a road points at more of it "
                     "over level scanned ground (%s m; scan_roads.json bridges, green in scan_roads.png)",
                     len(bridges), ", ".join(f"{b['gap_m']:.1f}" for b in bridges))
        node_xy, edges, n_skeleton_nodes = _skeleton_edges(mask, grid)
        edges = _prune_spurs(edges, len(node_xy), p)
    if not edges:
        raise NoRoads(f"the carriageway ({how}, {mask.sum() * grid.res ** 2:.0f} m^2) has no road axis")
    edges, half, junctions = _merge_junctions(edges, node_xy)
    raw_arms = [a for a in (_centre_arm(e, h, junctions, mask, grid, p) for e, h in zip(edges, half)) if a]
    if not raw_arms:
        raise NoRoads(f"the carriageway ({how}) holds no road at least {p.min_road_width_m} m wide and "
                      f"{p.min_road_length_m} m long")
    nodes, arms = _nodes_and_arms(raw_arms, _junction_points(raw_arms, junctions), mask, grid, p)
    stats = {"carriageway_from": how, "carriageway_m2": round(float(mask.sum() * grid.res ** 2), 1),
             "skeleton_nodes": n_skeleton_nodes, "bridges": bridges, "derive_s": round(time.perf_counter() - t0, 3)}
    net = Network(nodes, arms, mask, grid, None, stats)
    net.level_faces = level
    return net


def _carriageway(v, f, labels, p: ScanSourceParams, curbs: bool, rgb, points_xy):
    """The raster grid, the carriageway mask, how it was found and the carriageway level's faces; NoRoads
    when less than one road's worth of carriageway."""
    from ..mesh2d import Grid

    grid = Grid.around(v[:, :2], p.raster_m)
    if curbs or labels is None:
        level = level_faces(v, f, p.curb_tol_m)
    else:  # no curbs: the carriageway's own faces give its heights (a lane on an embankment is no low level)
        level = grey_ground(v, f, labels, rgb, p)[0]
    mask, how = carriageway_mask(v, f, labels, grid, p, level, curbs=curbs, rgb=rgb, points_xy=points_xy)
    if not (curbs or labels is None) and len(level):
        # the heights come from the carriageway's own faces: not from grey specks beside it
        inside = grid.sample(mask.astype(np.uint8), v[f[level]].mean(1)[:, :2]) > 0
        if inside.any():
            level = level[inside]
    if mask.sum() * grid.res ** 2 < p.min_road_width_m * p.min_road_length_m:
        raise NoRoads(f"no carriageway in the scan ({how}): {mask.sum() * grid.res ** 2:.0f} m^2 of road surface")
    return grid, mask, how, level


def _skeleton_edges(mask: np.ndarray, grid):
    """The mask's skeleton graph in the site frame: node points, edges ``(a, b, xy (k, 2), half width (k,))``
    (the half width is the distance to the mask's edge, m) and the skeleton's node count."""
    from scipy import ndimage

    dt = ndimage.distance_transform_edt(mask) * grid.res
    node_pix, edges = skeleton_graph(thin(mask))

    def px_to_xy(rc):
        rc = np.asarray(rc, float)
        return np.stack([grid.x0 + (rc[:, 1] + 0.5) * grid.res, grid.y0 - (rc[:, 0] + 0.5) * grid.res], 1)

    node_xy = [px_to_xy(pix).mean(0) for pix in node_pix]
    return node_xy, [(a, b, px_to_xy(pth), dt[pth[:, 0], pth[:, 1]]) for a, b, pth in edges], len(node_pix)


def bridge_gaps(mask: np.ndarray, edges: list, n_nodes: int, grid, v, f, p: ScanSourceParams) -> tuple[np.ndarray, list]:
    """The carriageway mask with its gaps bridged: where a road (an edge at least ``min_road_length_m`` long) ends
    freely and, straight on, more carriageway begins within ``bridge_m``, the gap is painted in as wide as the road
    when the mesh has up-facing ground all along it, all but ``bridge_step_share`` of it no farther than
    ``bridge_max_step_m`` from the straight line between the carriageway's heights at both ends (a wall, a planted
    island or a hole is no bridge; a sweep's mesh is too rough to tell a kerb). Returns the mask and the bridges
    (``{"from": [x, y], "to": [x, y], "gap_m": m}``)."""
    from scipy import ndimage

    from ..mesh2d import face_normals_z

    up = np.flatnonzero(face_normals_z(v, f) > 0.9)
    if p.bridge_m <= 0 or not edges or not len(up):
        return mask, []
    ground = rasterize_faces(v, f, up, grid)
    z = level_raster(v, f, up, grid)  # the up-facing surface's height, nearest-filled
    deg = _degrees(edges, n_nodes)
    out, bridges = mask.copy(), []
    step = grid.res / 2
    for a, b, xy, hw in edges:
        if len(xy) < 4 or float(np.hypot(*np.diff(xy, axis=0).T).sum()) < p.min_road_length_m:
            continue
        half = max(float(np.median(hw)), p.min_road_width_m / 2)
        k = min(len(xy) - 1, max(2, int(round(5.0 / grid.res))))
        for node, end, back in ((a, xy[0], xy[k]), (b, xy[-1], xy[-1 - k])):
            if deg[node] != 1:
                continue
            d = unit(end - back)
            t_out = float(ray_lengths(mask, grid, end[None], d[None], 60.0, step)[0])
            gap = float(ray_lengths(~mask, grid, (end + d * t_out)[None], d[None], p.bridge_m, step)[0])
            ahead = (end + d * (t_out + gap + step))[None]
            if gap >= p.bridge_m or not grid.sample(mask.astype(np.uint8), ahead)[0]:
                continue  # no carriageway ahead (the mask's or the grid's end): the road ends here
            t1 = t_out + gap + 1.0
            ts = np.arange(0.0, t1 + step, step)
            ss = np.arange(-half, half + step, step)
            nrm = np.array([-d[1], d[0]])
            pts = end[None, None, :] + ts[:, None, None] * d + ss[None, :, None] * nrm
            off = ~(grid.sample(mask.astype(np.uint8), pts) > 0)
            on_ground = grid.sample(ground.astype(np.uint8), pts) > 0
            if not off.any() or on_ground[off].mean() < 0.9:
                continue
            zz = grid.sample(z, pts)
            z0, z1 = float(np.nanmedian(zz[0])), float(np.nanmedian(zz[-1]))
            line = z0 + (z1 - z0) * (ts / t1)[:, None]
            dev = np.abs(zz - line)[off]
            if np.mean(~(dev <= p.bridge_max_step_m)) > p.bridge_step_share:
                continue
            px = np.floor(grid.to_px(pts.reshape(-1, 2))).astype(int)
            ok = (px[:, 0] >= 0) & (px[:, 0] < grid.w) & (px[:, 1] >= 0) & (px[:, 1] < grid.h)
            out[px[ok, 1], px[ok, 0]] = True
            bridges.append({"from": [round(float(c), 2) for c in end + d * t_out],
                            "to": [round(float(c), 2) for c in end + d * (t_out + gap)], "gap_m": round(gap, 2)})
    if bridges:
        r = max(1, int(round(0.5 / grid.res)))
        out = ndimage.binary_fill_holes(ndimage.binary_closing(out, np.ones((2 * r + 1, 2 * r + 1), bool)) | out)
    return out, bridges


def _degrees(edges, n: int) -> np.ndarray:
    deg = np.zeros(n, int)
    for a, b, _, _ in edges:
        deg[a] += 1
        deg[b] += 1
    return deg


def _prune_spurs(edges: list, n_nodes: int, p: ScanSourceParams) -> list:
    """Spurs pruned: an edge with a free end (degree-1 node) shorter than the half width where it leaves the
    network, plus min_road_length_m; tiny loops around a hole too; edges merged through degree-2 nodes; until
    stable."""
    for _ in range(10):
        deg = _degrees(edges, n_nodes)
        keep = []
        changed = False
        for e in edges:
            a, b, xy, hw = e
            length = float(np.hypot(*np.diff(xy, axis=0).T).sum())
            free = (deg[a] == 1) != (deg[b] == 1)
            if free and length < float(hw.max()) + p.min_road_length_m and (deg[a] > 2 or deg[b] > 2):
                changed = True
                continue
            if a == b and length < 4 * float(hw.max()):  # tiny loops around a hole
                changed = True
                continue
            keep.append(e)
        edges = keep
        edges, merged = _merge_through_degree_two(edges, n_nodes)
        if not (changed or merged):
            break
    return edges


def _merge_through_degree_two(edges: list, n_nodes: int) -> tuple[list, bool]:
    """Edges meeting at a node of degree 2 joined into one; whether any was."""
    changed = False
    deg = _degrees(edges, n_nodes)
    for n in np.flatnonzero(deg == 2):
        ix = [i for i, e in enumerate(edges) if e[0] == n or e[1] == n]
        if len(ix) != 2 or ix[0] == ix[1]:
            continue
        e1, e2 = edges[ix[0]], edges[ix[1]]
        if e1[0] == e1[1] or e2[0] == e2[1]:
            continue
        x1 = e1 if e1[1] == n else (e1[1], e1[0], e1[2][::-1], e1[3][::-1])
        x2 = e2 if e2[0] == n else (e2[1], e2[0], e2[2][::-1], e2[3][::-1])
        merged = (x1[0], x2[1], np.concatenate([x1[2], x2[2][1:]]), np.concatenate([x1[3], x2[3][1:]]))
        edges = [e for i, e in enumerate(edges) if i not in ix] + [merged]
        changed = True
    return edges, changed


def _merge_junctions(edges: list, node_xy: list):
    """The typical half width of each edge (its middle part), junction sizes, and junction nodes linked by
    an edge shorter than their size merged into one. Returns the remaining edges, their half widths and the
    junctions: ``{"gid": node -> group, "r": group -> radius, "c": group -> centre, "deg": group -> degree}``."""
    half = []
    for a, b, xy, hw in edges:
        k = len(hw)
        mid = hw[k // 4: max(k // 4 + 1, 3 * k // 4)]
        half.append(float(np.median(mid)))
    deg = _degrees(edges, len(node_xy))
    radius = np.zeros(len(node_xy))
    for (a, b, _, _), h in zip(edges, half):
        radius[a] = max(radius[a], h)
        radius[b] = max(radius[b], h)
    parent = list(range(len(node_xy)))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    short = []
    for i, (a, b, xy, hw) in enumerate(edges):
        length = float(np.hypot(*np.diff(xy, axis=0).T).sum())
        if a != b and deg[a] >= 3 and deg[b] >= 3 and length < 1.5 * (radius[a] + radius[b]):
            parent[find(a)] = find(b)
            short.append(i)
    edges = [e for i, e in enumerate(edges) if i not in short]
    half = [h for i, h in enumerate(half) if i not in short]
    groups: dict[int, list[int]] = {}
    for i in range(len(node_xy)):
        groups.setdefault(find(i), []).append(i)
    gid = {i: find(i) for i in range(len(node_xy))}
    deg2: dict[int, int] = {}
    for a, b, _, _ in edges:
        deg2[gid[a]] = deg2.get(gid[a], 0) + 1
        deg2[gid[b]] = deg2.get(gid[b], 0) + 1
    return edges, half, {"gid": gid, "r": {g: max(radius[i] for i in members) for g, members in groups.items()},
                         "c": {g: np.mean([node_xy[i] for i in members], 0) for g, members in groups.items()},
                         "deg": deg2}


STEP_M = 1.0  # spacing of an arm's axis points while it is centred


def _centre_arm(edge, h: float, junctions: dict, mask, grid, p: ScanSourceParams) -> dict | None:
    """One arm: its axis smoothed away from junctions, extended to the carriageway's end at a free end,
    centred between the edges (a high percentile of each side's edge distance along a window) and fitted.
    None when too short or narrow."""
    a, b, xy, hw = edge
    ga, gb = junctions["gid"][a], junctions["gid"][b]
    deg2 = junctions["deg"]
    step = STEP_M
    xy = resample(xy, step)
    if len(xy) < 3:
        return None
    trim = np.ones(len(xy), bool)
    for g in (ga, gb):
        if deg2.get(g, 0) >= 3:
            r = 1.15 * junctions["r"][g] + 2.0
            trim &= np.hypot(*(xy - junctions["c"][g]).T) > r
    if trim.sum() < max(3, int(p.min_road_length_m / 2 / step)):
        return None
    first, last = np.flatnonzero(trim)[[0, -1]]
    win = max(3, int(round(p.edge_window_m / 2 / step)))
    core = smooth(xy[first:last + 1], win)
    core = _extend_free_ends(core, (ga, gb), deg2, mask, grid, step)
    nrm = normals(core)
    left = ray_lengths(mask, grid, core, nrm, 40.0, grid.res / 4)
    right = ray_lengths(mask, grid, core, -nrm, 40.0, grid.res / 4)
    w = max(3, int(round(p.edge_window_m / step)))
    pad = w // 2
    lpad = np.pad(left, pad, mode="edge")
    rpad = np.pad(right, pad, mode="edge")
    lw = np.array([np.percentile(lpad[i:i + w], p.edge_percentile) for i in range(len(core))])
    rw = np.array([np.percentile(rpad[i:i + w], p.edge_percentile) for i in range(len(core))])
    centre = core + nrm * ((lw - rw) / 2)[:, None]
    centre = fit_axis(centre, win)
    # the mask is on average half a pixel wider on each side (rasterize_faces); the rays overshoot by
    # half their step: measured on the synthetic cross, half a pixel too wide in all
    width = float(np.median(lw + rw)) - grid.res / 2
    if width < p.min_road_width_m:
        return None
    return {"ga": ga, "gb": gb, "core": centre, "width": width, "nrm": normals(centre)}


def _extend_free_ends(core: np.ndarray, ends: tuple, deg2: dict, mask, grid, step: float) -> np.ndarray:
    """A skeleton stops about a half width before a free end (where the scan ends): the axis continued
    straight up to the end of the carriageway, so the edges are measured there too."""
    for g, at_start in ((ends[0], True), (ends[1], False)):
        if deg2.get(g, 0) >= 3 or len(core) < 3:
            continue
        e = core[0] if at_start else core[-1]
        dv = unit(core[0] - core[min(5, len(core) - 1)]) if at_start else unit(core[-1] - core[max(-6, -len(core))])
        ln = float(ray_lengths(mask, grid, e[None], dv[None], 60.0, grid.res / 2)[0]) - 1.0
        if ln > step:
            ext = e + dv * np.arange(step, ln, step)[:, None]
            core = np.concatenate([ext[::-1], core]) if at_start else np.concatenate([core, ext])
    return core


def _junction_points(raw_arms: list, junctions: dict) -> dict:
    """Junction group -> the point where its arms' axes meet (least squares)."""
    ends: dict[int, list] = {}
    for arm in raw_arms:
        c = arm["core"]
        ends.setdefault(arm["ga"], []).append((c[0], unit(c[0] - c[min(5, len(c) - 1)])))
        ends.setdefault(arm["gb"], []).append((c[-1], unit(c[-1] - c[max(-6, -len(c))])))
    jpos = {}
    for g, lines in ends.items():
        if len(lines) >= 3 or (len(lines) == 2 and junctions["deg"].get(g, 0) >= 3):
            jpos[g] = junction_point(lines, junctions["c"][g])
    return jpos


def _nodes_and_arms(raw_arms: list, jpos: dict, mask, grid, p: ScanSourceParams) -> tuple[dict, list]:
    """Nodes (junctions at their points, ends where the carriageway ends) and arms reaching them, their axes
    resampled every ``sample_m``; nodes numbered 0..n-1."""
    step = STEP_M
    nodes: dict[int, dict] = {}
    arms: list[Arm] = []
    for arm in raw_arms:
        c = arm["core"]
        pts = [c]
        for g, at_start in ((arm["ga"], True), (arm["gb"], False)):
            if g in jpos:
                q = jpos[g]
                nodes.setdefault(g, {"xy": q, "kind": "junction"})
                seg = np.array([q, c[0]]) if at_start else np.array([c[-1], q])
                seg = resample(seg, step)
                pts.insert(0, seg[:-1]) if at_start else pts.append(seg[1:])
            else:  # an end: continue straight to the mask's end, for the outer lanes too (at a road
                # that bends where the scan ends, the axis reaches farther than the lanes beside it)
                e = c[0] if at_start else c[-1]
                d = unit(c[0] - c[min(5, len(c) - 1)]) if at_start else unit(c[-1] - c[max(-6, -len(c))])
                side = np.array([-d[1], d[0]]) * max(arm["width"] / 2 - 0.5, 0.0)
                starts = np.stack([e, e + side, e - side])
                ln = float(ray_lengths(mask, grid, starts, np.tile(d, (3, 1)), 60.0, grid.res / 2).min())
                q = e + d * ln
                seg = resample(np.array([q, e]) if at_start else np.array([e, q]), step)
                pts.insert(0, seg[:-1]) if at_start else pts.append(seg[1:])
                key = ("end", len(nodes), at_start, id(arm))
                g_end = hash(key) & 0x7FFFFFFF
                nodes[g_end] = {"xy": q, "kind": "end"}
                if at_start:
                    arm["ga"] = g_end
                else:
                    arm["gb"] = g_end
        xy = np.concatenate([x for x in pts if len(x)])
        xy = resample(xy, p.sample_m)
        arms.append(Arm(arm["ga"], arm["gb"], xy, arm["width"]))
    ren = {g: i for i, g in enumerate(nodes)}
    nodes = {ren[g]: nd for g, nd in nodes.items()}
    for arm in arms:
        arm.a, arm.b = ren[arm.a], ren[arm.b]
    return nodes, arms


#: sidewalk surface more than this above the carriageway level beside it is not a sidewalk (a roof, a wall)
WALK_MAX_M = 0.5


def carriageway_level(net: Network, v, f) -> np.ndarray:
    """The carriageway level's height per pixel of ``net.grid`` (:func:`.masks.level_raster` of its level faces and
    carriageway mask), made once per network: the sidewalks and the heights both read it."""
    if net.level_z is None:
        net.level_z = level_raster(v, f, net.level_faces, net.grid, net.mask)
    return net.level_z


def add_sidewalks(net: Network, v, f, labels, p: ScanSourceParams) -> None:
    """Sidewalk width beyond each curb: the run of sidewalk-labelled surface (else the raised level)."""
    from scipy import ndimage

    grid = net.grid
    if labels is not None and (labels == SIDEWALK).any():
        lv = labels[f]
        sw_f = np.flatnonzero((lv == SIDEWALK).sum(1) >= 2)
        # a sidewalk one can step onto from the road: within WALK_MAX_M of the carriageway level beside it
        # (an aerial scan's flat roofs and walls can take the sidewalk label too)
        zr = carriageway_level(net, v, f)
        cz = v[f[sw_f], 2].mean(1)
        dz = cz - grid.sample(zr, v[f[sw_f], :2].mean(1))
        sw_f = sw_f[(dz > -0.1) & (dz < WALK_MAX_M)]
        sw = rasterize_faces(v, f, sw_f, grid)
        sw = ndimage.binary_closing(sw, np.ones((5, 5), bool))
        src = "sidewalk labels"
    else:  # the raised level: up-facing faces 6-35 cm above the carriageway level, just beyond the curb
        from ..mesh2d import face_normals_z

        nz = face_normals_z(v, f)
        up = np.flatnonzero(nz > 0.9)
        zr = carriageway_level(net, v, f)
        cz = v[f[up], 2].mean(1)
        lvl = grid.sample(zr, v[f[up], :2].mean(1))
        raised = up[(cz - lvl > 0.06) & (cz - lvl < 0.35) & np.isfinite(lvl)]
        sw = rasterize_faces(v, f, raised, grid) & ~net.mask
        src = "raised level beside the curb"
    net.sidewalk_mask = sw
    net.stats["sidewalks_from"] = src
    for arm in net.arms:
        nrm = normals(arm.xy)
        for side, sgn in (("left", 1.0), ("right", -1.0)):
            edge = arm.xy + sgn * nrm * (arm.width_m / 2 + 0.3)  # past the curb stone (its own label varies)
            run = ray_lengths(sw, grid, edge, sgn * nrm, 15.0, grid.res / 2) - grid.res / 2
            # only away from the junctions (the cross street's carriageway crosses the sidewalk there)
            ok = np.ones(len(run), bool)
            for nid in (arm.a, arm.b):
                nd = net.nodes[nid]
                if nd["kind"] == "junction":
                    ok &= np.hypot(*(arm.xy - nd["xy"]).T) > arm.width_m + 6.0
            vals = run[ok] if ok.sum() >= 3 else run
            wv = float(np.percentile(vals, 60)) + 0.3 if len(vals) else 0.0  # + the curb stone the ray started past
            wv = min(wv, p.max_sidewalk_m)
            if wv >= p.min_sidewalk_m and float(np.mean(vals > 0.5)) >= 0.3:
                setattr(arm, f"sidewalk_{side}_m", round(wv, 2))


def add_heights_and_signals(net: Network, v, f, labels, p: ScanSourceParams) -> None:
    zr = carriageway_level(net, v, f)
    for arm in net.arms:
        # the carriageway's height at each shape point: the median of its level across the road (a lane
        # off the axis of a cambered or sloping street is as far above as the other is below), lightly
        # smoothed along the road (3 points)
        nrm = normals(arm.xy)
        across = np.linspace(-0.4, 0.4, 9) * arm.width_m
        zz = net.grid.sample(zr, arm.xy[:, None, :] + across[None, :, None] * nrm[:, None, :]).astype(float)

        def smooth3(a):
            return np.convolve(np.pad(a, 1, mode="edge"), np.ones(3) / 3, mode="valid")

        arm.z = smooth3(np.median(zz, axis=1))
        # each direction's driving lanes lie from the axis outwards (netconvert spreads them to the right of
        # the edge's shape), over lanes x lane_m: its height is the surface's across that band
        lay = lane_layout(arm.width_m, p)
        band = lay["lanes"] * lay["lane_m"]
        off = np.linspace(0.1, 0.9, 5) * band
        for side, sgn in (("z_right", -1.0), ("z_left", 1.0)):  # the normal points left
            q = arm.xy[:, None, :] + (sgn * off)[None, :, None] * nrm[:, None, :]
            setattr(arm, side, smooth3(np.median(net.grid.sample(zr, q).astype(float), axis=1)))
    # a node's height is where its roads meet it (their ends' heights), not the level raster at its point:
    # a junction point can lie off the carriageway, where the nearest carriageway face is another one
    # (IGN: a three-way junction 0.7 m under the ground)
    ends: dict[int, list[float]] = {}
    for arm in net.arms:
        ends.setdefault(arm.a, []).append(float(arm.z[0]))
        ends.setdefault(arm.b, []).append(float(arm.z[-1]))
    for nid, nd in net.nodes.items():
        nd["z"] = (float(np.median(ends[nid])) if nid in ends
                   else float(net.grid.sample(zr, np.asarray(nd["xy"])[None])[0]))
        nd["signals"] = False
    if labels is None or p.min_traffic_light_vertices <= 0:
        return
    tl = v[labels == TRAFFIC_LIGHT, :2]
    for nid, nd in net.nodes.items():
        if nd["kind"] != "junction" or not len(tl):
            continue
        r = max(a.width_m / 2 for a in net.arms if nid in (a.a, a.b)) + p.traffic_light_radius_m
        near = int((np.hypot(*(tl - nd["xy"]).T) < r).sum())
        nd["signals"] = near >= p.min_traffic_light_vertices
        nd["traffic_light_vertices"] = near

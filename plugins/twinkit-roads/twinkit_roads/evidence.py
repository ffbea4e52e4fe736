"""The aligned road network as evidence for the ground classes of the per-vertex labels.

Every lane of the OpenDRIVE is a polygon on the ground, and its type says what the surface there
is: driving-like lanes (driving, bidirectional, parking, shoulder, entry/exit, ramps, biking,
stop...) are carriageway -> *road*; sidewalk lanes -> *sidewalk*; border, median, curb, none,
restricted, rail, tram vote nothing. A lane is only evidence, never an order:

* only **ground-level, up-facing** vertices the scan already calls a **ground class** (road,
  sidewalk, terrain) can change, and only among those classes;
* the scan's geometry decides which *level* a vertex is on: the carriageway level (within
  ``curb_min_m`` of the local lowest ground) or raised above it by a curb step. Road lies on the
  carriageway level and sidewalk on the raised level: a sidewalk lane over carriageway-level
  surface (netconvert places its fixed 2 m sidewalk at the edge of the driving lanes, i.e. over a
  parking strip it does not model) or a driving lane over a raised pavement is a *disagreement*
  and is left alone;
* a lane over a building, a wall, a car or anything else that is not ground (by geometry or by the
  scan's label) is a disagreement too;
* a lane, or a road, whose area disagrees with the scan's geometry over more than
  ``max_disagreement`` of its surface casts no vote at all; and when the driving-like lanes of the
  whole network disagree over more than ``max_network_disagreement`` (a wrong or outdated OSM, a
  failed alignment: a right network's carriageway lies on carriageway-level ground) no lane votes.
  Disagreements are reported either way.

A sidewalk lane that agrees with the scan (raised ground, ground class) marks the raised
*plateau* it lies on (the connected raised ground around it, bounded by curbs and buildings) as
pavement: road votes on that plateau become sidewalk. Road on a raised plateau beside a sidewalk
lane is the scan's commonest error (most pavement is voted road), and netconvert's sidewalk lanes
are narrower than real pavements and often sit a parking strip off them, so where the lane lies
alone would miss most of it. Terrain votes on the plateau stay: grass verges share the pavement's
level and only the texture tells them apart.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twinkit.cityscapes import GROUND, ROAD, SIDEWALK, TERRAIN

#: OpenDRIVE lane type (as written in the file, lower case) -> the class it votes for.
ROAD_TYPES = ("driving", "bidirectional", "parking", "shoulder", "entry", "exit", "onramp", "offramp",
              "biking", "stop", "roadworks", "special1", "special2", "special3")
SIDEWALK_TYPES = ("sidewalk",)
#: lane kinds in the raster
NONE, L_ROAD, L_SIDEWALK = 0, 1, 2


@dataclass
class Lane:
    key: tuple  # (road id, section id, lane id)
    type: str  # OpenDRIVE lane type, lower case
    vote: int  # L_ROAD | L_SIDEWALK | NONE
    left: np.ndarray  # (k, 2) border polyline, site frame
    right: np.ndarray  # (k, 2)
    junction: bool


def _lane_vote(t: str, road_types, sidewalk_types) -> int:
    t = t.lower()
    if t in sidewalk_types:
        return L_SIDEWALK
    if t in road_types:
        return L_ROAD
    return NONE


def lane_polygons(xodr_text: str, step_m: float = 0.5, road_types=ROAD_TYPES,
                  sidewalk_types=SIDEWALK_TYPES) -> list[Lane]:
    """Every lane of every type as a pair of border polylines (site frame): :meth:`LaneMap.lanes`, so a
    lane not next to a driving lane is not seen."""
    from twinkit.street.lanes import LaneMap

    lanes = []
    for ln in LaneMap(xodr_text, "evidence").lanes(step_m).per_lane():
        t = str(ln.type[0]).lower()
        L, R = ln.borders()
        lanes.append(Lane(ln.key, t, _lane_vote(t, road_types, sidewalk_types), L, R, bool(ln.in_junction[0])))
    return lanes


def lane_raster(lanes: list[Lane], grid) -> tuple[np.ndarray, np.ndarray]:
    """(vote raster uint8: NONE / L_ROAD / L_SIDEWALK, lane index raster int32: -1 outside).

    Sidewalk lanes are drawn after driving lanes: where netconvert's polygons overlap at a
    junction corner the pavement wins (it is the narrower, rarer evidence)."""
    from PIL import Image, ImageDraw

    vote = Image.new("L", (grid.w, grid.h), NONE)
    idx = Image.new("I", (grid.w, grid.h), -1)
    dv, di = ImageDraw.Draw(vote), ImageDraw.Draw(idx)
    order = sorted(range(len(lanes)), key=lambda i: lanes[i].vote)
    for i in order:
        ln = lanes[i]
        if ln.vote == NONE or len(ln.left) < 2:
            continue
        L, R = grid.to_px(ln.left), grid.to_px(ln.right)
        for k in range(len(L) - 1):
            poly = [tuple(L[k]), tuple(L[k + 1]), tuple(R[k + 1]), tuple(R[k])]
            dv.polygon(poly, fill=ln.vote)
            di.polygon(poly, fill=i)
    return np.asarray(vote), np.asarray(idx).astype(np.int32)


def vertex_areas(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """A third of each adjacent triangle's area, m^2 per vertex."""
    from twinkit.mesh.core import face_areas

    a = face_areas(v, f) / 3.0
    return np.bincount(f.ravel(), weights=np.repeat(a, 3), minlength=len(v))


def plateaus(v: np.ndarray, raised: np.ndarray, cell_m: float, close_m: float) -> np.ndarray:
    """Per vertex the id (1..) of the raised plateau it lies on, 0 for vertices not raised."""
    from scipy import ndimage

    comp = np.zeros(len(v), np.int64)
    if not raised.any():
        return comp
    xy = v[:, :2]
    lo = xy[raised].min(0) - 2 * close_m
    ij = np.floor((xy - lo) / cell_m).astype(np.int64)
    r = ij[raised]
    shape = tuple(r.max(0) + 1 + int(np.ceil(2 * close_m / cell_m)))
    mask = np.zeros(shape, bool)
    mask[r[:, 0], r[:, 1]] = True
    k = max(1, int(round(close_m / cell_m)))
    mask = ndimage.binary_closing(mask, structure=np.ones((2 * k + 1, 2 * k + 1), bool))
    lab, _ = ndimage.label(mask)
    comp[raised] = lab[r[:, 0], r[:, 1]]
    return comp


@dataclass
class Evidence:
    labels: np.ndarray  # new labels
    changed: np.ndarray  # bool per vertex
    lane_vote: np.ndarray  # per vertex NONE / L_ROAD / L_SIDEWALK (of the lanes that vote)
    status: np.ndarray  # per vertex: see STATUS
    lanes: list  # per lane dict: key, type, vote, area, disagreement, voted
    height: np.ndarray  # per vertex height above the local ground, m
    ground: np.ndarray  # bool per vertex: ground-level, up-facing
    area: np.ndarray  # per vertex area, m^2
    network_disagreement: float = 0.0  # of the driving-like lanes' ground: share on the wrong level / not ground
    network_vetoed: bool = False  # above max_network_disagreement: no lane voted


#: per-vertex status codes
S_OUT, S_AGREE, S_RELABEL, S_NONGROUND_GEOM, S_NONGROUND_LABEL, S_LEVEL, S_VETOED = 0, 1, 2, 3, 4, 5, 6
STATUS = {S_OUT: "outside the voting lanes", S_AGREE: "agrees", S_RELABEL: "relabelled",
          S_NONGROUND_GEOM: "lane over raised/non-ground geometry", S_NONGROUND_LABEL: "lane over a non-ground class",
          S_LEVEL: "lane type contradicts the surface level (curb)", S_VETOED: "lane vetoed (mostly disagrees)"}


def _lane_vetoes(lanes: list[Lane], li: np.ndarray, inl: np.ndarray, status: np.ndarray, area: np.ndarray,
                 max_disagreement: float, max_network_disagreement: float):
    """Which lanes may not vote: (vetoed per lane, area per lane m2, its disagreeing fraction, its road's
    disagreeing fraction, the network's disagreeing fraction, whether the whole network is vetoed)."""
    # per lane: how much of its area disagrees with the scan; a mostly-wrong lane does not vote
    nl = len(lanes)
    # geometry only: a lane over a building or on the wrong side of a curb; a label the scan got wrong
    # (a car voted on the pavement) is no sign of a wrong map and is left out of both sums
    counted = inl & (li >= 0) & (status != S_NONGROUND_LABEL)
    a_tot = np.bincount(li[counted], weights=area[counted], minlength=nl)
    dis = counted & np.isin(status, (S_NONGROUND_GEOM, S_LEVEL))
    a_dis = np.bincount(li[dis], weights=area[dis], minlength=nl)
    frac = np.where(a_tot > 0, a_dis / np.maximum(a_tot, 1e-12), 0.0)
    # ...and a road (all its lanes together) that mostly disagrees silences all its lanes
    rid = np.array([int(ln.key[0]) for ln in lanes], np.int64)
    _, rinv = np.unique(rid, return_inverse=True)
    r_tot = np.bincount(rinv, weights=a_tot, minlength=len(set(rid.tolist())))
    r_dis = np.bincount(rinv, weights=a_dis, minlength=len(r_tot))
    road_frac = np.where(r_tot > 0, r_dis / np.maximum(r_tot, 1e-12), 0.0)[rinv]
    vetoed_lane = (frac > max_disagreement) | (road_frac > max_disagreement)
    # ...and a network whose carriageway does not lie on the scan's carriageway (a wrong or outdated OSM,
    # a failed alignment) casts no vote anywhere: driving-like lanes of a right network lie on low ground
    drv = np.array([ln.vote == L_ROAD for ln in lanes], bool)
    network_frac = float(a_dis[drv].sum() / a_tot[drv].sum()) if nl and a_tot[drv].sum() > 0 else 0.0
    network_vetoed = network_frac > max_network_disagreement
    if network_vetoed:
        vetoed_lane[:] = True
    return vetoed_lane, a_tot, frac, road_frac, network_frac, network_vetoed


def _grow_plateaus(v: np.ndarray, raised: np.ndarray, lv: np.ndarray, area: np.ndarray, new: np.ndarray,
                   status: np.ndarray, relabel_from, cell_m: float, close_m: float, min_agree_m2: float) -> None:
    """Relabel sidewalk the raised ground plateaus the sidewalk lanes agree on (``new``, ``status`` in place)."""
    # raised ground plateaus: connected cells of a top-down raster of the raised ground vertices, small
    # gaps (a bollard, a mesh defect, a car's wheel) closed; curbs to the carriageway and buildings separate
    comp = plateaus(v, raised, cell_m, close_m)
    seed = (lv == L_SIDEWALK) & np.isin(status, (S_AGREE, S_RELABEL))
    agree_area = np.bincount(comp[seed], weights=area[seed], minlength=comp.max() + 1)
    road_area = np.bincount(comp[raised & (lv == L_ROAD)], weights=area[raised & (lv == L_ROAD)],
                            minlength=comp.max() + 1)
    pave = (agree_area >= min_agree_m2) & (road_area < agree_area)
    pave[0] = False  # 0: not on a plateau
    grow = raised & pave[comp] & np.isin(new, [c for c in relabel_from if c not in (SIDEWALK, TERRAIN)]) & \
        (status != S_VETOED) & (lv != L_ROAD)
    new[grow] = SIDEWALK
    status[grow & (status == S_OUT)] = S_RELABEL


def _lane_info(lanes: list[Lane], a_tot: np.ndarray, frac: np.ndarray, road_frac: np.ndarray,
               vetoed_lane: np.ndarray) -> list[dict]:
    """Per lane, what the report shows: its key, type, vote, area, disagreement and veto."""
    lane_info = []
    for i, ln in enumerate(lanes):
        lane_info.append({"road": int(ln.key[0]), "section": int(ln.key[1]), "lane": int(ln.key[2]), "type": ln.type,
                          "votes": {NONE: None, L_ROAD: "road", L_SIDEWALK: "sidewalk"}[ln.vote],
                          "junction": ln.junction, "area_m2": round(float(a_tot[i]), 2),
                          "disagreement": round(float(frac[i]), 3),
                          "road_disagreement": round(float(road_frac[i]), 3), "vetoed": bool(vetoed_lane[i] and ln.vote)})
    return lane_info


def road_evidence(v: np.ndarray, f: np.ndarray, labels: np.ndarray, lanes: list[Lane], grid, *,
                  normal_min_z: float = 0.9, max_height_m: float = 0.45, curb_min_m: float = 0.06,
                  curb_max_m: float = 0.35, cell_m: float = 0.5, window_m: float = 8.0, ground_pct: float = 5.0,
                  max_disagreement: float = 0.5, max_network_disagreement: float = 0.10, plateau: bool = True,
                  plateau_min_agree_m2: float = 1.0,
                  plateau_cell_m: float = 0.25, plateau_close_m: float = 0.5,
                  relabel_from=GROUND) -> Evidence:
    """Vote the lanes into ``labels`` (see the module docstring); returns the new labels and why."""
    from twinkit.mesh.core import vertex_normals
    from twinkit.street.ground import LocalGround

    labels = np.asarray(labels)
    n = len(v)
    vn = vertex_normals(v, f)
    up = vn[:, 2] >= normal_min_z
    h = LocalGround(v, up, cell_m=cell_m, window="min", window_m=window_m, pct=ground_pct, odd_window=False,
                    pad_cells=0, fill="lowest", if_none_up="all").height()
    ground = up & (h <= max_height_m)
    raised = ground & (h >= curb_min_m) & (h <= curb_max_m)
    low = ground & (h < curb_min_m)
    area = vertex_areas(v, f)
    vraster, iraster = lane_raster(lanes, grid)
    lv = grid.sample(vraster, v[:, :2]).astype(np.int8)
    li = grid.sample(iraster + 1, v[:, :2]).astype(np.int64) - 1  # sample() fills 0 outside
    is_ground_label = np.isin(labels, relabel_from)
    want = np.where(lv == L_ROAD, ROAD, np.where(lv == L_SIDEWALK, SIDEWALK, -1))
    status = np.full(n, S_OUT, np.int8)
    inl = lv != NONE
    status[inl & ~ground] = S_NONGROUND_GEOM
    status[inl & ground & ~is_ground_label] = S_NONGROUND_LABEL
    gl = inl & ground & is_ground_label
    level_ok = np.where(lv == L_ROAD, low, raised)
    status[gl & ~level_ok] = S_LEVEL
    ok = gl & level_ok
    status[ok & (labels == want)] = S_AGREE
    status[ok & (labels != want)] = S_RELABEL
    vetoed_lane, a_tot, frac, road_frac, network_frac, network_vetoed = _lane_vetoes(
        lanes, li, inl, status, area, max_disagreement, max_network_disagreement)
    vet = inl & (li >= 0) & vetoed_lane[np.maximum(li, 0)] & np.isin(status, (S_AGREE, S_RELABEL))
    status[vet] = S_VETOED
    new = labels.copy()
    rel = status == S_RELABEL
    new[rel] = want[rel]
    if plateau:
        _grow_plateaus(v, raised, lv, area, new, status, relabel_from, plateau_cell_m, plateau_close_m,
                       plateau_min_agree_m2)
    lane_info = _lane_info(lanes, a_tot, frac, road_frac, vetoed_lane)
    return Evidence(new, new != labels, lv, status, lane_info, h, ground, area, network_frac, network_vetoed)


#: picture colours of the per-vertex status
STATUS_RGB = {S_OUT: (60, 60, 60), S_AGREE: (40, 170, 60), S_RELABEL: (0, 220, 255), S_NONGROUND_GEOM: (230, 30, 30),
              S_NONGROUND_LABEL: (255, 150, 0), S_LEVEL: (200, 40, 220), S_VETOED: (255, 240, 0)}


def draw_evidence(v: np.ndarray, f: np.ndarray, labels_before: np.ndarray, ev: Evidence, lanes: list[Lane], out,
                  px_per_m: float = 10.0, max_px: int = 2048) -> None:
    """Top-down picture, three panels: the labels before, after, and where lanes and scan agree / disagree.
    Lane borders over all three: driving-like white, sidewalk magenta, non-voting grey."""
    from PIL import Image, ImageDraw

    from twinkit.cityscapes import colorize

    from .mesh2d import picture_grid, top_faces

    xy = v[:, :2]
    grid, res = picture_grid(xy, px_per_m, max_px)

    top = top_faces(v, f, grid)  # one rasterisation, then three colourings of it
    empty = top < 0
    top[empty] = 0

    def face_rgb(per_vertex_rgb):
        return per_vertex_rgb[f].mean(1).astype(np.uint8)

    st = np.array([STATUS_RGB[int(s)] for s in range(len(STATUS_RGB))], np.uint8)[ev.status]
    # a face takes its most telling vertex status (a disagreement over an agreement)
    rank = np.array([0, 1, 3, 5, 4, 6, 2])[ev.status]  # OUT < AGREE < VETOED < RELABEL < LABEL < GEOM < LEVEL
    fv = np.take_along_axis(f, rank[f].argmax(1)[:, None], 1)[:, 0]
    panels = []
    for cols in (face_rgb(colorize(labels_before)), face_rgb(colorize(ev.labels)), st[fv]):
        arr = cols[top]
        arr[empty] = (25, 25, 25)
        img = Image.fromarray(arr)
        d = ImageDraw.Draw(img)
        for ln in lanes:
            col = {NONE: (150, 150, 150), L_ROAD: (255, 255, 255), L_SIDEWALK: (255, 0, 255)}[ln.vote]
            for side in (ln.left, ln.right):
                q = [tuple(p) for p in grid.to_px(side)]
                if len(q) >= 2:
                    d.line(q, fill=col, width=1)
        panels.append(img)
    W, H = grid.w, grid.h
    canvas = Image.new("RGB", (3 * W + 20, H + 120), (0, 0, 0))
    for k, p in enumerate(panels):
        canvas.paste(p, (k * (W + 10), 0))
    d = ImageDraw.Draw(canvas)
    d.text((8, H + 6), "labels before (CityScapes colours)", fill=(255, 255, 255))
    d.text((W + 18, H + 6), "labels after the road network's vote", fill=(255, 255, 255))
    d.text((2 * W + 28, H + 6), "lanes vs scan:", fill=(255, 255, 255))
    y = H + 22
    for s, name in STATUS.items():
        if s == S_OUT:
            continue
        d.rectangle([2 * W + 28, y, 2 * W + 40, y + 10], fill=STATUS_RGB[s])
        d.text((2 * W + 46, y), name, fill=(255, 255, 255))
        y += 14
    d.text((8, H + 22), "lane borders: white driving-like, magenta sidewalk, grey no vote", fill=(255, 255, 255))
    bar = 10.0 / res
    d.line([(8, H + 44), (8 + bar, H + 44)], fill=(255, 255, 255), width=3)
    d.text((14 + bar, H + 38), "10 m", fill=(255, 255, 255))
    canvas.save(out)


def lanes_of(xodr_text: str, where, step_m: float, road_types, sidewalk_types) -> list[Lane]:
    """``lane_polygons`` of an aligned OpenDRIVE map (``where``: its path, for the messages), the lane types
    compared in lower case; an unreadable map or one without lanes is an ``InputError`` that names the fix."""
    from twinkit import InputError
    from twinkit.street.lanes import OpenDriveError

    try:
        lanes = lane_polygons(xodr_text, step_m, tuple(t.lower() for t in road_types),
                              tuple(t.lower() for t in sidewalk_types))
    except OpenDriveError as exc:
        raise InputError(f"{where}: {exc.why}; re-run apply_alignment") from None
    except (OSError, UnicodeDecodeError, RuntimeError, ValueError) as exc:
        raise InputError(f"{where}: not a readable OpenDRIVE ({exc}); re-run apply_alignment") from None
    if not lanes:
        raise InputError(f"{where}: carla.Map finds no lanes in it; check the OpenDRIVE (osm_to_opendrive)")
    return lanes


def passthrough_reason(enabled: bool, no_roads: bool, rings_share: float | None, min_share: float) -> str | None:
    """Why no lane may vote, in words, or None when they may: switched off, a map without roads, or a capture
    sampled in rings (``rings_share``: its ground's two-way share, under ``min_share``: no kerb step, no level)."""
    if no_roads:
        return "no roads in the map (the scan holds none)"
    if not enabled:
        return "switched off (steps.road_evidence.enabled=false or site road_evidence: false)"
    if rings_share is not None:
        return (f"the capture's ground is sampled in rings ({100 * rings_share:.0f} % of it sampled both ways, under "
                f"min_two_way_share {100 * min_share:.0f} %: a single spinning sweep): no kerb step can be measured "
                "across it, so which lanes lie on the carriageway level cannot be told")
    return None


def draw_passthrough(out, why: str) -> None:
    """The evidence picture when no lane voted at all (switched off, no roads): one line that says ``why``."""
    import textwrap

    from PIL import Image, ImageDraw

    lines = textwrap.wrap(f"road network evidence: {why}; labels unchanged", 70)
    img = Image.new("RGB", (460, 20 + 14 * len(lines)), (0, 0, 0))
    d = ImageDraw.Draw(img)
    for i, line in enumerate(lines):
        d.text((10, 10 + 14 * i), line, fill=(255, 255, 255))
    img.save(out)


def unchanged(ev: Evidence, labels: np.ndarray) -> Evidence:
    """``ev`` with the labels as they were (relabel=false: the picture shows the votes, no change)."""
    import dataclasses

    return dataclasses.replace(ev, labels=labels.copy())


def _class_name(c: int) -> str:
    from twinkit.cityscapes import NAMES

    return NAMES[c] if c < len(NAMES) else "unlabelled"


DEFINITION = ("areas in m^2 of mesh surface (a third of each adjacent triangle per vertex) under the lanes "
              "that vote (driving-like: road, sidewalk: sidewalk). agrees: ground-level surface of the "
              "lane's class; relabelled: ground class changed to the lane's; disagreements: the lane lies "
              "over raised/non-ground geometry (a building, a wall, a car body), over ground the scan calls "
              "a non-ground class, or on the wrong level (sidewalk lane on the carriageway level, driving "
              "lane on a raised pavement); vetoed: a lane or road mostly disagreeing casts no vote")


def evidence_report(ev: Evidence, labels: np.ndarray, new: np.ndarray, relabel: bool, params: dict) -> tuple[dict, dict]:
    """road_evidence.json and the step's metrics: the labels changed (``labels`` -> ``new``, uint8 per vertex)
    by class and transition, and the lanes' areas (m^2 of mesh surface) by status and vote."""
    ch = new != labels
    trans: dict[str, int] = {}
    for a, b in zip(labels[ch].tolist(), new[ch].tolist()):
        k = f"{_class_name(a)} -> {_class_name(b)}"
        trans[k] = trans.get(k, 0) + 1
    area = ev.area
    a = lambda m: round(float(area[m].sum()), 2)  # noqa: E731
    inl = ev.lane_vote > 0
    geo = (ev.status == S_NONGROUND_GEOM) | (ev.status == S_LEVEL)
    areas = {STATUS[s].replace(" ", "_"): a(ev.status == s) for s in STATUS if s}
    per_vote = {nm: {"lane_area_m2": a(ev.lane_vote == lv), "agree_m2": a((ev.lane_vote == lv) & (ev.status == S_AGREE)),
                     "relabelled_m2": a((ev.lane_vote == lv) & (ev.status == S_RELABEL)),
                     "disagree_geometry_m2": a((ev.lane_vote == lv) & geo),
                     "disagree_label_m2": a((ev.lane_vote == lv) & (ev.status == S_NONGROUND_LABEL))}
                for nm, lv in (("road", L_ROAD), ("sidewalk", L_SIDEWALK))}
    doc = {
        "enabled": True, "relabel": relabel,
        "changed_vertices": int(ch.sum()), "changed_area_m2": a(ch), "transitions": trans,
        "changed_per_class": {_class_name(c): int(((new == c) & ch).sum()) - int(((labels == c) & ch).sum())
                              for c in sorted(set(labels[ch].tolist()) | set(new[ch].tolist()))},
        "lane_area_m2": a(inl), "areas_m2": areas, "per_vote": per_vote,
        "disagreement_area_m2": a(inl & (geo | (ev.status == S_NONGROUND_LABEL))),
        "disagreement_geometry_m2": a(inl & geo),
        "disagreement_fraction": round(float(area[inl & geo].sum() / max(area[inl].sum(), 1e-9)), 4),
        "network_disagreement": round(ev.network_disagreement, 4), "network_vetoed": ev.network_vetoed,
        "vetoed_lanes": [ln for ln in ev.lanes if ln["vetoed"]],
        "lanes": ev.lanes,
        "definition": DEFINITION,
        "params": params,
    }
    metrics = {"changed_vertices": int(ch.sum()), "changed_area_m2": a(ch),
               "disagreement_geometry_m2": doc["disagreement_geometry_m2"],
               "disagreement_fraction": doc["disagreement_fraction"], "vetoed_lanes": len(doc["vetoed_lanes"]),
               "network_disagreement": doc["network_disagreement"], "network_vetoed": ev.network_vetoed}
    return doc, metrics


def add_evaluation(doc: dict, metrics: dict, labels: np.ndarray, new: np.ndarray, gt: np.ndarray) -> tuple[dict, dict]:
    """The IoU (percent) of the labels before and after against the ground truth ``gt`` (per vertex), into
    ``doc["evaluation"]`` and the road, sidewalk, terrain and mean IoU into ``metrics``. Returns (before, after)."""
    before, after = iou(labels, gt), iou(new, gt)
    doc["evaluation"] = {"iou_before": before, "iou_after": after}
    metrics["iou_before"] = {k: before[k] for k in ("road", "sidewalk", "terrain", "miou") if k in before}
    metrics["iou_after"] = {k: after[k] for k in ("road", "sidewalk", "terrain", "miou") if k in after}
    return before, after


def iou(pred, gt) -> dict:
    """Per-class IoU (percent) over the classes present in the ground truth, and their mean (the segmentation
    plugin's definition: unlabelled predictions are misses, unlabelled ground truth is left out)."""
    from twinkit.cityscapes import N_CLASSES, NAMES

    gt = np.asarray(gt).astype(np.int64)
    pred = np.asarray(pred).astype(np.int64)
    valid = gt < N_CLASSES
    g, p = gt[valid], pred[valid]
    out = {}
    for c in np.unique(g):
        tp = int(((p == c) & (g == c)).sum())
        fp = int(((p == c) & (g != c)).sum())
        fn = int(((p != c) & (g == c)).sum())
        out[NAMES[c]] = round(100.0 * tp / max(tp + fp + fn, 1), 2)
    out["miou"] = round(float(np.mean(list(out.values()))), 2) if out else 0.0
    return out

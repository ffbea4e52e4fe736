"""Kerbs: the last centimetres of the road alignment.

After ``align.fit`` the network's carriageway edges are brought onto the kerb feet found in the mesh:
a small rigid refinement of the whole network (``refine_to_kerbs``), then a sideways lane offset per
road (``road_lane_offsets``) written into the OpenDRIVE's ``<laneOffset>`` (``set_lane_offsets``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # align's helpers are imported where they are used (kerbs extends align's fit)
    from .align import FitResult, Transform2D


@dataclass
class KerbFit:
    tf: Transform2D  # the refined transform (the input one when not ``applied``)
    edges: int  # carriageway edges that found a kerb in the mesh
    before_m: float  # median |edge - kerb foot| before
    after_m: float  # ... and after the refinement
    shift_m: tuple[float, float]  # translation added (site frame)
    yaw_deg: float  # rotation added
    applied: bool
    why: str = ""


def kerb_feet(edge: np.ndarray, out: np.ndarray, vertices: np.ndarray, faces: np.ndarray, *, reach_m: float = 0.8,
              search_m: float = 0.5, step_m: float = 0.01, kerb_min_m: float = 0.06, kerb_max_m: float = 0.30,
              rise_m: float = 0.025, flat_m: float = 0.03) -> np.ndarray:
    """Signed distance (m, along ``out``) from each carriageway edge point to the foot of the kerb beside it
    in the mesh, or nan where no kerb is seen.

    A profile of vertical rays crosses each edge (``step_m`` apart, ``reach_m`` each way). It shows a kerb
    when both ends are flat (10-90 % height spread under ``flat_m``: no car, no bollard) and the outer end
    stands ``kerb_min_m`` to ``kerb_max_m`` above the inner one. The foot is where, within ``search_m`` of
    the edge, the surface last lies within ``rise_m`` of the road and everything outward of it above."""
    import warnings

    import open3d as o3d

    from twinkit.surface.closest import Surface

    edge = np.asarray(edge, float)
    out = np.asarray(out, float)
    res = np.full(len(edge), np.nan)
    if len(edge) == 0:
        return res
    scene = Surface(np.asarray(vertices, np.float64), np.asarray(faces)).scene
    u = np.arange(-reach_m, reach_m + step_m / 2, step_m)
    pts = edge[:, None, :] + u[None, :, None] * out[:, None, :]
    top = float(vertices[:, 2].max()) + 1.0
    rays = np.zeros((pts.shape[0] * pts.shape[1], 6), np.float32)
    rays[:, :2] = pts.reshape(-1, 2)
    rays[:, 2] = top
    rays[:, 5] = -1.0
    t = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().reshape(pts.shape[:2])
    z = np.where(np.isfinite(t), top - t, np.nan)
    inner, outer = u < -search_m, u > search_m
    mid = ~inner & ~outer
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-nan rows: profiles off the mesh
        zi = np.nanmedian(z[:, inner], axis=1)
        zo = np.nanmedian(z[:, outer], axis=1)
        spread_i = np.nanpercentile(z[:, inner], 90, axis=1) - np.nanpercentile(z[:, inner], 10, axis=1)
        spread_o = np.nanpercentile(z[:, outer], 90, axis=1) - np.nanpercentile(z[:, outer], 10, axis=1)
    rise = zo - zi
    ok = (np.isfinite(z[:, mid]).all(axis=1) & (spread_i < flat_m) & (spread_o < flat_m)
          & (rise >= kerb_min_m) & (rise <= kerb_max_m))
    um = u[mid]
    for i in np.flatnonzero(ok):
        low = z[i, mid] <= zi[i] + rise_m
        if not low.any() or low.all():
            continue
        j = int(np.flatnonzero(low).max())  # the last low sample: outward of it the kerb
        if j + 1 >= len(um) or not (z[i, mid][j + 1:] > zi[i] + rise_m).all():
            continue  # no clean step (a ramp, a gully, a dip beyond)
        res[i] = um[j] + step_m / 2
    return res


def lane_edges(lines: list[dict]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Both borders of every driving lane outside junctions (``lane_lines``): points (k, 2), unit normals
    pointing out of the lane (k, 2), the OpenDRIVE road id (k,) and the unit normal to the left of the
    road's reference line (k, 2; lanes with a positive id run against it). Borders between two lanes
    are in too: they see no kerb."""
    P, O, R, L = [], [], [], []
    for ln in lines:
        if ln["junction"] or len(ln["centre"]) < 2:
            continue
        n = ln["right"] - ln["centre"]
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-9)  # right of travel
        for side, sign in (("right", 1.0), ("left", -1.0)):
            P.append(ln[side])
            O.append(sign * n)
            R.append(np.full(len(n), ln["id"][0]))
            L.append(-n if ln["id"][2] < 0 else n)
    if not P:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros((0, 2))
    return np.concatenate(P), np.concatenate(O), np.concatenate(R), np.concatenate(L)


def refine_to_kerbs(lines: list[dict], tf: Transform2D, vertices: np.ndarray, faces: np.ndarray, *,
                    max_shift_m: float = 0.3, max_yaw_deg: float = 0.5, min_edges: int = 12,
                    **kerb_kw) -> KerbFit:
    """The carriageway edges onto the kerbs' feet: a small rigid correction (yaw about the sections' middle,
    translation) of ``tf`` by robust least squares on the measured kerb offsets (``kerb_feet``).

    The rigid fit on the road mask is as good as its raster (0.1 m) and its residual rotation shows at
    the ends of long roads: lanes a few cm over the kerb, where a wheel meets its rounded foot. Only
    the directions the kerbs constrain move (kerbs along one axis fix nothing along it). Kept only when
    at least ``min_edges`` edges see a kerb, the correction stays within ``max_shift_m`` /
    ``max_yaw_deg``, and the median offset shrinks."""
    from .align import Transform2D, _weights

    p0, o0, _, _ = lane_edges(lines)
    edge, out = tf.apply(p0), tf.apply_dir(o0)
    d = kerb_feet(edge, out, vertices, faces, **kerb_kw)
    ok = np.isfinite(d)
    none = KerbFit(tf, int(ok.sum()), float(np.median(np.abs(d[ok]))) if ok.any() else float("nan"),
                   float("nan"), (0.0, 0.0), 0.0, False)
    if ok.sum() < min_edges:
        none.why = f"{int(ok.sum())} edges see a kerb (at least {min_edges} needed)"
        return none
    e, o, r = edge[ok], out[ok], d[ok]
    a = np.asarray(tf.about) + np.array([tf.tx, tf.ty])  # where the sections' middle went
    p = e - a
    A = np.stack([o[:, 0] * -p[:, 1] + o[:, 1] * p[:, 0], o[:, 0], o[:, 1]], 1)
    x = np.zeros(3)
    for it in range(1, 15):
        res_ = r - A @ x
        w = _weights(res_, it + 8, 0.05)  # Tukey around the robust scale: a parked car's edge drops out
        U, S, Vt = np.linalg.svd(A * np.sqrt(w)[:, None], full_matrices=False)
        keep = S > 1e-3 * S[0] * np.sqrt(len(r))  # directions no kerb constrains stay where they are
        x = Vt[keep].T @ ((U[:, keep].T @ (np.sqrt(w) * r)) / S[keep])
    dyaw, dx, dy = float(x[0]), float(x[1]), float(x[2])
    after = float(np.median(np.abs(r - A @ x)))
    fitres = KerbFit(tf, int(ok.sum()), none.before_m, after, (dx, dy), math.degrees(dyaw), False)
    if math.hypot(dx, dy) > max_shift_m or abs(math.degrees(dyaw)) > max_yaw_deg:
        fitres.why = "the correction is larger than a refinement may be"
        return fitres
    if after >= none.before_m:
        fitres.why = "no better than before"
        return fitres
    # new(x) = R(dyaw) (tf(x) - a) + a + (dx, dy), and tf(x) - a = scale R(yaw) (x - about)
    fitres.tf = Transform2D(tf.yaw_rad + dyaw, tf.tx + dx, tf.ty + dy, tf.scale, tf.about)
    fitres.applied = True
    return fitres


def road_lane_offsets(lines: list[dict], tf: Transform2D, vertices: np.ndarray, faces: np.ndarray, *,
                      min_edges: int = 5, max_offset_m: float = 0.15, min_offset_m: float = 0.01,
                      **kerb_kw) -> dict[int, float]:
    """Per road, the lateral shift (m, OpenDRIVE ``t``: to the left of the road's reference line) that puts
    its lane borders onto the kerbs' feet beside them, after the rigid transform ``tf``: the median over
    the road's borders that see a kerb (``kerb_feet``), kept when at least ``min_edges`` do and it lies
    between ``min_offset_m`` and ``max_offset_m``. One rigid move cannot fit every street: an OSM way drawn
    a few cm off its neighbours keeps its lanes over the kerb (the demo's north side street: 3 cm at
    its east kerb after the rigid fit, the drop test's outermost rays on the kerb's foot). A road whose two
    kerbs ask for opposite shifts (it is narrower or wider than the map says) gets their median."""
    P, O, R, L = lane_edges(lines)
    if not len(P):
        return {}
    d = kerb_feet(tf.apply(P), tf.apply_dir(O), vertices, faces, **kerb_kw)
    ok = np.isfinite(d)
    dt = d * np.einsum("ij,ij->i", tf.apply_dir(O), tf.apply_dir(L))  # the wanted move, along the road's left
    out = {}
    for r in np.unique(R[ok]):
        k = ok & (R == r)
        if k.sum() < min_edges:
            continue
        m = float(np.median(dt[k]))
        if min_offset_m <= abs(m) <= max_offset_m:
            out[int(r)] = round(m, 4)
    return out


def set_lane_offsets(text: str, offsets: dict) -> str:
    """Add ``offsets`` ({road id: metres, to the left}) to the roads' ``<laneOffset>`` (created at s = 0
    when the road has none): every lane of the road moves sideways by it."""
    import xml.etree.ElementTree as ET

    if not offsets:
        return text
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    root = ET.fromstring(text, parser=parser)
    want = {str(int(k)): float(v) for k, v in offsets.items()}
    for road in root.iter("road"):
        rid = road.get("id")
        if rid not in want or road.find("lanes") is None:
            continue
        lanes = road.find("lanes")
        offs = lanes.findall("laneOffset")
        if not offs:
            lanes.insert(0, ET.Element("laneOffset", {"s": "0", "a": "0", "b": "0", "c": "0", "d": "0"}))
            offs = lanes.findall("laneOffset")
        for o in offs:
            o.set("a", f"{float(o.get('a', 0.0)) + want[rid]:.6f}")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def kerb_correction(xodr_text: str, res: FitResult, vertices: np.ndarray, faces: np.ndarray, *, max_shift_m: float,
                    road_offset_m: float, log) -> tuple[KerbFit, dict[int, float]]:
    """The kerb step of the alignment: ``refine_to_kerbs`` on the lanes of ``xodr_text`` (``res.tf`` is replaced
    by the refined transform when it is applied), then, when ``road_offset_m`` > 0, ``road_lane_offsets`` of at
    most that many metres per road. Returns the refinement and {road id: metres to the left}."""
    from .align import lane_lines

    lines = lane_lines(xodr_text, 1.0)
    kerb = refine_to_kerbs(lines, res.tf, vertices, faces, max_shift_m=max_shift_m)
    if kerb.applied:
        res.tf = kerb.tf
        log.info("alignment: lane edges onto %d kerb feet: median offset %.3f -> %.3f m (moved %.3f m, %.3f deg)",
                 kerb.edges, kerb.before_m, kerb.after_m, math.hypot(*kerb.shift_m), kerb.yaw_deg)
    else:
        log.info("alignment: kerb refinement not applied: %s", kerb.why)
    offsets: dict[int, float] = {}
    if road_offset_m > 0:
        offsets = road_lane_offsets(lines, res.tf, vertices, faces, max_offset_m=road_offset_m)
        if offsets:
            log.info("alignment: %d road(s) moved sideways onto their kerbs: %s", len(offsets),
                     ", ".join(f"road {k} {v:+.3f} m" for k, v in sorted(offsets.items())))
    return kerb, offsets

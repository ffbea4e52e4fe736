"""Fitting the road network to the road surface of the mesh, and moving the OpenDRIVE accordingly.

The network is sampled as carriageway cross-sections (centre point, normal, half width: all
driving lanes of a road at one s). For each, the mesh's road surface is scanned along the normal
and the middle of the road run found; the signed offset between the two middles is the residual.
A robust (Huber-weighted) Gauss-Newton fit finds yaw and translation (optionally scale) that zero
these offsets; a coarse correlation search on the road mask first brings it into the basin.
Carriageway *middles* are compared, not edges, so parking strips or sidewalks of the same width on
both sides (not in OSM) do not bias the result.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twinkit import InputError

from .mesh2d import Grid


class NoOverlap(InputError):
    """The fit found too few road cross-sections on the mesh's road surface (the fix depends on the source)."""


@dataclass
class Sections:
    c: np.ndarray  # (n, 2) carriageway centres, site frame
    n: np.ndarray  # (n, 2) unit normals (to the right of the road direction)
    hw: np.ndarray  # (n,) half widths of the driving carriageway
    z: np.ndarray  # (n,) road height in the OpenDRIVE
    road: np.ndarray  # (n,) road id


def network_mask(lines: list[dict], grid: Grid) -> np.ndarray:
    """Driving area of the network (junction lanes included) drawn into ``grid``."""
    from PIL import Image, ImageDraw

    img = Image.new("L", (grid.w, grid.h), 0)
    draw = ImageDraw.Draw(img)
    for ln in lines:
        L, R = grid.to_px(ln["left"]), grid.to_px(ln["right"])
        for i in range(len(L) - 1):
            draw.polygon([tuple(L[i]), tuple(L[i + 1]), tuple(R[i + 1]), tuple(R[i])], fill=1)
        if len(L) == 1:
            draw.line([tuple(L[0]), tuple(R[0])], fill=1, width=2)
    from scipy import ndimage

    return ndimage.binary_closing(np.asarray(img) > 0, iterations=2)


def sample_sections(xodr_text: str, step_m: float = 1.0, res_m: float = 0.1, limit_m: float = 25.0) -> Sections:
    """Cross-sections of the driving carriageways outside junctions, from carla.Map offline.

    A carriageway is the contiguous driving area across the road's normal, whichever OpenDRIVE
    roads its lanes belong to (netconvert writes each direction of a street as its own road).
    """
    lines = lane_lines(xodr_text, step_m, junctions=True)
    if not any(not ln["junction"] for ln in lines):
        raise InputError("the OpenDRIVE has no driving lanes outside junctions; nothing to align")
    allpts = np.concatenate([np.concatenate([ln["left"], ln["right"]]) for ln in lines])
    grid = Grid.around(allpts, res_m, pad=limit_m)
    net = network_mask(lines, grid)
    P, Nrm, Z, R = [], [], [], []
    for ln in lines:
        if ln["junction"] or len(ln["centre"]) < 2:
            continue
        c = ln["centre"]
        d = np.gradient(c, axis=0)
        d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
        P.append(c)
        Z.append(ln["z"])  # the OpenDRIVE's own heights (0 from OSM; the scanned heights from road_source=scan)
        Nrm.append(np.stack([d[:, 1], -d[:, 0]], 1))
        R.append(np.full(len(c), hash(ln["id"]) % 100000))
    P, Nrm, Z, R = np.concatenate(P), np.concatenate(Nrm), np.concatenate(Z), np.concatenate(R)
    off, ok, wid = _runs(P, Nrm, np.full(len(P), limit_m / 2), net, grid, limit_m / 2, (0.0, 1e9))
    if ok.sum() == 0:
        raise InputError("no carriageway cross-section could be measured in the OpenDRIVE")
    C = P[ok] + off[ok, None] * Nrm[ok]
    return Sections(C, Nrm[ok], wid[ok] / 2, Z[ok], R[ok])


def _rot(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


@dataclass
class Transform2D:
    yaw_rad: float = 0.0
    tx: float = 0.0
    ty: float = 0.0
    scale: float = 1.0
    about: tuple[float, float] = (0.0, 0.0)  # rotation / scale centre

    def apply(self, xy: np.ndarray) -> np.ndarray:
        p = np.asarray(xy, float) - np.asarray(self.about)
        return (self.scale * p @ _rot(self.yaw_rad).T) + np.asarray(self.about) + np.array([self.tx, self.ty])

    def apply_dir(self, v: np.ndarray) -> np.ndarray:
        return np.asarray(v, float) @ _rot(self.yaw_rad).T

    def about_origin(self) -> tuple[float, float, float, float]:
        """(yaw, tx, ty, scale) of the same transform written about the site origin."""
        a = np.asarray(self.about)
        t = a + np.array([self.tx, self.ty]) - self.scale * _rot(self.yaw_rad) @ a
        return self.yaw_rad, float(t[0]), float(t[1]), self.scale


def _runs(c: np.ndarray, n: np.ndarray, hw: np.ndarray, mask: np.ndarray, grid: Grid, margin_m: float,
          width_ratio: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Along each line c + u n, the mask run nearest u=0: (middle offset, valid, width)."""
    step = grid.res / 2
    U = float(np.max(hw)) + margin_m
    us = np.arange(-U, U + step / 2, step)
    k0 = len(us) // 2
    off = np.zeros(len(c))
    wid = np.zeros(len(c))
    ok = np.zeros(len(c), bool)
    m8 = mask.astype(np.uint8)
    for i0 in range(0, len(c), 2048):
        sl = slice(i0, i0 + 2048)
        pts = c[sl, None, :] + us[None, :, None] * n[sl, None, :]
        road = grid.sample(m8, pts) > 0
        for j in range(road.shape[0]):
            i = i0 + j
            row = road[j]
            lim = np.abs(us) <= hw[i] + margin_m
            idx = np.flatnonzero(row & lim)
            if len(idx) == 0:
                continue
            start = idx[np.argmin(np.abs(idx - k0))]
            if abs(us[start]) > hw[i] + 1e-9 and abs(us[start]) > margin_m / 2:
                continue
            a = start
            while a - 1 >= 0 and row[a - 1] and lim[a - 1]:
                a -= 1
            b = start
            while b + 1 < len(us) and row[b + 1] and lim[b + 1]:
                b += 1
            if a == 0 or b == len(us) - 1 or not lim[a - 1] or not lim[b + 1]:
                continue  # the run reaches the search limit: a junction, a plaza, the mesh border
            w = us[b] - us[a] + step
            if not (width_ratio[0] * 2 * hw[i] <= w <= width_ratio[1] * 2 * hw[i]):
                continue
            off[i] = (us[a] + us[b]) / 2
            wid[i] = w
            ok[i] = True
    return off, ok, wid


def centre_offsets(sec: Sections, tf: Transform2D, mask: np.ndarray, grid: Grid, margin_m: float = 6.0,
                   width_ratio: tuple[float, float] = (0.6, 2.0)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Signed offset (along the moved normal) from each moved section centre to the mesh road middle."""
    return _runs(tf.apply(sec.c), tf.apply_dir(sec.n), sec.hw * tf.scale, mask, grid, margin_m, width_ratio)


def coarse_search(sec: Sections, mask: np.ndarray, grid: Grid, search_m: float, yaw_range_deg: float,
                  res: float = 0.25) -> Transform2D:
    """Best overlap of the carriageway areas with the road mask over a grid of yaws and shifts."""
    from scipy import ndimage, signal

    f = max(1, int(round(res / grid.res)))
    small = ndimage.zoom(mask.astype(np.float32), 1.0 / f, order=1) if f > 1 else mask.astype(np.float32)
    sg = Grid(grid.x0, grid.y0, grid.res * f, small.shape[1], small.shape[0])
    about = tuple(sec.c.mean(0))
    best = (-1.0, Transform2D(about=about))
    yaws = np.deg2rad(np.arange(-yaw_range_deg, yaw_range_deg + 1e-9, 0.5)) if yaw_range_deg > 0 else [0.0]
    # carriageway model: points across each section's width
    fr = np.linspace(-1, 1, 9)
    shift = int(math.ceil(search_m / sg.res))
    target = small - small.mean()  # zero-mean so that simply covering more area does not win
    for yaw in yaws:
        tf = Transform2D(yaw_rad=float(yaw), about=about)
        c = tf.apply(sec.c)
        n = tf.apply_dir(sec.n)
        pts = (c[:, None, :] + (fr[None, :, None] * sec.hw[:, None, None]) * n[:, None, :]).reshape(-1, 2)
        model = np.zeros_like(small)
        p = np.floor(sg.to_px(pts)).astype(int)
        okp = (p[:, 0] >= 0) & (p[:, 0] < sg.w) & (p[:, 1] >= 0) & (p[:, 1] < sg.h)
        model[p[okp, 1], p[okp, 0]] = 1.0
        model = ndimage.binary_dilation(model > 0, iterations=2).astype(np.float32)
        corr = signal.fftconvolve(target, model[::-1, ::-1], mode="same")
        cy, cx = small.shape[0] // 2, small.shape[1] // 2
        win = corr[max(cy - shift, 0):cy + shift + 1, max(cx - shift, 0):cx + shift + 1]
        j, i = np.unravel_index(np.argmax(win), win.shape)
        score = float(win[j, i])
        dy_px = j + max(cy - shift, 0) - cy
        dx_px = i + max(cx - shift, 0) - cx
        if score > best[0]:
            best = (score, Transform2D(yaw_rad=float(yaw), tx=dx_px * sg.res, ty=-dy_px * sg.res, about=about))
    return best[1]


def _typical_width(sec: Sections, ok: np.ndarray, wid: np.ndarray, tol_m: float) -> np.ndarray:
    """Keep sections whose mesh road width is the usual one for their road (both edges seen).

    A car parked at the curb or a driveway moves one edge and so the middle; such sections are
    narrower or wider than the road's median width and are dropped. ``tol_m`` <= 0 keeps all.
    """
    if tol_m <= 0:
        return ok
    keep = ok.copy()
    for g in np.unique(sec.road[ok]):
        sel = ok & (sec.road == g)
        if sel.sum() < 5:
            continue
        med = float(np.median(wid[sel]))
        keep[sel] = np.abs(wid[sel] - med) <= tol_m
    return keep


@dataclass
class FitResult:
    tf: Transform2D
    rmse_before: float
    rmse_after: float
    n_sections: int
    n_used: int
    iterations: int
    degenerate: bool
    #: the fit did no better than leaving the network where it was (the robust loss on the cross-sections
    #: both find the road at): the identity is returned
    kept_identity: bool = False


def _huber_cost(r: np.ndarray, h: float) -> float:
    a = np.abs(r)
    return float(np.mean(np.where(a <= h, 0.5 * a * a, h * (a - 0.5 * h))))


def _weights(r: np.ndarray, it: int, huber_m: float) -> np.ndarray:
    """Huber for the first iterations, then Tukey's biweight around a robust scale (outliers drop out)."""
    w = np.where(np.abs(r) <= huber_m, 1.0, huber_m / np.maximum(np.abs(r), 1e-9))
    if it > 8:
        sigma = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), 0.05)
        cut = max(4.685 * sigma, 0.15)
        w = np.where(np.abs(r) < cut, (1 - (r / cut) ** 2) ** 2, 0.0)
    return w


def _design(sec: Sections, tf: Transform2D, ok: np.ndarray, off: np.ndarray, wid: np.ndarray, about: tuple,
            grid: Grid, model: str, fit_scale: bool, extra: dict[int, float]
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, np.ndarray]:
    """One Gauss-Newton linear system on the sections ``ok``: (M, rhs, residuals now, pose unknowns k, road ids).

    The first k columns of M are yaw, tx, ty (and scale) about ``about``; with ``model="edges"`` one
    extra-width column per road follows (the road ids' order), each edge a row.
    """
    c = tf.apply(sec.c[ok]) - np.asarray(about) - np.array([tf.tx, tf.ty])
    n = tf.apply_dir(sec.n[ok])
    cols = [n[:, 0] * -c[:, 1] + n[:, 1] * c[:, 0], n[:, 0], n[:, 1]]
    if fit_scale:
        cols.append(n[:, 0] * c[:, 0] + n[:, 1] * c[:, 1])
    A = np.stack(cols, 1)
    k = A.shape[1]
    if model == "middles":
        return A, off[ok], off[ok], k, np.zeros(0)
    half_step = grid.res / 4
    hw = sec.hw[ok] * tf.scale
    lo = off[ok] - wid[ok] / 2 + half_step
    hi = off[ok] + wid[ok] / 2 - half_step
    groups, gi = np.unique(sec.road[ok], return_inverse=True)
    G = len(groups)
    E = np.zeros((len(gi), G))
    E[np.arange(len(gi)), gi] = 1.0
    M = np.vstack([np.hstack([A, E]), np.hstack([A, -E])])
    rhs = np.concatenate([hi - hw, lo + hw])
    prev = np.array([extra.get(int(g), float(np.median(((hi - lo) / 2 - hw)[gi == j])))
                     for j, g in enumerate(groups)])
    r = rhs - np.concatenate([prev[gi], -prev[gi]])
    return M, rhs, r, k, groups


def _solve_weighted(M: np.ndarray, rhs: np.ndarray, w: np.ndarray, k: int) -> tuple[np.ndarray, bool]:
    """The weighted least-squares step x and whether the pose block is degenerate (then damped)."""
    MtM = (M * w[:, None]).T @ M
    ev = np.linalg.eigvalsh(MtM[:k, :k])
    degenerate = bool(ev[0] < 1e-6 * max(ev[-1], 1e-12) * len(w))
    lam = 1e-9 * np.trace(MtM) + (1e-3 * np.trace(MtM[:k, :k]) if degenerate else 0.0)
    x = np.linalg.solve(MtM + lam * np.eye(M.shape[1]), (M * w[:, None]).T @ rhs)
    return x, degenerate


def _sections_found(sec: Sections, tf: Transform2D, mask: np.ndarray, grid: Grid, margin_m: float,
                    width_tol_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """centre_offsets under ``tf`` with the sections of untypical width dropped: (offset, ok, width)."""
    off, ok, wid = centre_offsets(sec, tf, mask, grid, margin_m)
    return off, _typical_width(sec, ok, wid, width_tol_m), wid


def fit(sec: Sections, mask: np.ndarray, grid: Grid, *, fit_scale: bool = False, search_m: float = 8.0,
        yaw_range_deg: float = 3.0, iterations: int = 30, huber_m: float = 0.3, margin_m: float = 6.0,
        width_tol_m: float = 0.0, model: str = "middles", keep_identity: bool = False) -> FitResult:
    """Robust Gauss-Newton fit of yaw and translation (and scale).

    ``model="middles"``: residual = offset of the mesh road's middle from the carriageway middle.
    ``model="edges"``: each mesh road edge separately, against the carriageway edge plus an unknown
    extra width per road (parking strips, verges): a car hiding one curb then costs one outlier
    edge instead of moving the middle, so the robust loss removes it.
    """
    if model not in ("edges", "middles"):
        raise InputError(f"align model must be 'middles' or 'edges', not '{model}'")
    about = tuple(sec.c.mean(0))
    off0, ok0, _ = centre_offsets(sec, Transform2D(about=about), mask, grid, margin_m)
    rmse0 = float(np.sqrt(np.mean(off0[ok0] ** 2))) if ok0.any() else float("nan")
    tf = coarse_search(sec, mask, grid, search_m, yaw_range_deg) if search_m > 0 else Transform2D(about=about)
    degenerate = False
    it = 0
    extra: dict[int, float] = {}
    r_last = np.zeros(0)
    for it in range(1, iterations + 1):
        off, ok, wid = _sections_found(sec, tf, mask, grid, margin_m, width_tol_m)
        if ok.sum() < 6:
            raise NoOverlap(f"only {int(ok.sum())} road cross-sections found the road surface in the mesh; the network "
                            "and the mesh do not overlap")
        M, rhs, r, k, groups = _design(sec, tf, ok, off, wid, about, grid, model, fit_scale, extra)
        w = _weights(r, it, huber_m)
        x, degenerate = _solve_weighted(M, rhs, w, k)
        d = x[:k]
        if model == "edges":
            extra = {int(g): float(x[k + j]) for j, g in enumerate(groups)}
        r_last = (rhs - M @ x)[w > 0]
        tf = Transform2D(tf.yaw_rad + d[0], tf.tx + d[1], tf.ty + d[2],
                         tf.scale * (1 + d[3]) if fit_scale else 1.0, about)
        if it > 9 and abs(d[0]) < 2e-5 and abs(d[1]) < 1e-3 and abs(d[2]) < 1e-3:
            break
    off, ok, _ = _sections_found(sec, tf, mask, grid, margin_m, width_tol_m)
    # the fit has to beat leaving the network where it is: both judged by the carriageway middles' robust
    # loss on the cross-sections that find the road either way (a network drawn from this very mesh, as
    # road_source=scan's, is already in place; a fit pulled by a few wrong sections must not turn it)
    ident = Transform2D(about=about)
    off_i, ok_i, _ = _sections_found(sec, ident, mask, grid, margin_m, width_tol_m)
    both = ok & ok_i
    kept_identity = keep_identity or bool(both.sum() >= 6 and
                                          _huber_cost(off_i[both], huber_m) <= _huber_cost(off[both], huber_m))
    if kept_identity:
        tf, off, ok, r_last = ident, off_i, ok_i, off_i[ok_i]
    if model == "middles":
        rmse1 = float(np.sqrt(np.mean(off[ok] ** 2))) if ok.any() else float("nan")
    else:  # RMS of the edge residuals kept by the robust loss
        rmse1 = float(np.sqrt(np.mean(r_last ** 2))) if len(r_last) else float("nan")
    return FitResult(tf, rmse0, rmse1, len(sec.c), int(ok.sum()), it, degenerate, kept_identity)


# --------------------------------------------------------------------------- OpenDRIVE rewriting


def transform_xodr(text: str, yaw_rad: float, tx: float, ty: float, dz: float = 0.0) -> str:
    """Move every road's plan view rigidly (about the site origin) and shift elevations by dz.

    Lane, signal and object positions are in road coordinates (s, t) and move with the roads; the
    geoReference stays: it describes the frame, which is the mesh's.
    """
    import xml.etree.ElementTree as ET

    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    root = ET.fromstring(text, parser=parser)
    R = _rot(yaw_rad)
    xs, ys = [], []
    for g in root.iter("geometry"):
        x, y = float(g.get("x")), float(g.get("y"))
        nx, ny = R @ np.array([x, y]) + np.array([tx, ty])
        g.set("x", f"{nx:.8f}")
        g.set("y", f"{ny:.8f}")
        g.set("hdg", f"{float(g.get('hdg', 0.0)) + yaw_rad:.8f}")
        xs.append(nx)
        ys.append(ny)
    if dz:
        for road in root.iter("road"):
            prof = road.find("elevationProfile")
            if prof is None:
                prof = ET.Element("elevationProfile")
                pv = list(road).index(road.find("planView")) if road.find("planView") is not None else 0
                road.insert(pv + 1, prof)
            els = prof.findall("elevation")
            if not els:
                ET.SubElement(prof, "elevation", {"s": "0", "a": "0", "b": "0", "c": "0", "d": "0"})
                els = prof.findall("elevation")
            for e in els:
                e.set("a", f"{float(e.get('a', 0.0)) + dz:.6f}")
    head = root.find("header")
    if head is not None and xs:
        head.set("north", f"{max(ys):.3f}")
        head.set("south", f"{min(ys):.3f}")
        head.set("east", f"{max(xs):.3f}")
        head.set("west", f"{min(xs):.3f}")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def lane_lines(xodr_text: str, step_m: float = 1.0, junctions: bool = False) -> list[dict]:
    """Centre lines and borders of driving lanes (site frame), one polyline per lane segment."""
    from twinkit.street.lanes import LaneMap

    wp = LaneMap(xodr_text, "lines").waypoints(step_m)
    wp = wp.take(wp.is_type("driving") & (junctions | ~wp.in_junction))
    lines = []
    for ln in wp.per_lane():
        L, R = ln.borders()
        lines.append({"id": ln.key, "junction": bool(ln.in_junction[0]), "centre": ln.xyz[:, :2], "z": ln.xyz[:, 2],
                      "left": L, "right": R})
    return lines


def polyline_distance(p: np.ndarray, lines: list[np.ndarray]) -> np.ndarray:
    """Distance from each point to the nearest of several polylines."""
    best = np.full(len(p), np.inf)
    for ln in lines:
        a, b = ln[:-1], ln[1:]
        ab = b - a
        L2 = np.maximum((ab ** 2).sum(1), 1e-12)
        t = np.clip(((p[:, None, :] - a[None]) * ab[None]).sum(2) / L2[None], 0, 1)
        q = a[None] + t[..., None] * ab[None]
        best = np.minimum(best, np.sqrt(((p[:, None, :] - q) ** 2).sum(2)).min(1))
    return best


def centreline_rmse(xodr_text: str, truth_lines: list[np.ndarray], bounds: tuple[float, float, float, float] | None = None,
                    step_m: float = 1.0) -> tuple[float, int]:
    """RMSE of driving-lane centre-line points (outside junctions) to the nearest true centre line."""
    pts = np.concatenate([ln["centre"] for ln in lane_lines(xodr_text, step_m)])
    if bounds is not None:
        xmin, ymin, xmax, ymax = bounds
        pts = pts[(pts[:, 0] >= xmin) & (pts[:, 0] <= xmax) & (pts[:, 1] >= ymin) & (pts[:, 1] <= ymax)]
    d = polyline_distance(pts, [np.asarray(t, float)[:, :2] for t in truth_lines])
    return float(np.sqrt(np.mean(d ** 2))), int(len(pts))


DEFINITION = "aligned_xy = Rz(yaw_deg) @ xy + [tx_m, ty_m] about the site origin; z += dz_m"


def no_roads_alignment() -> dict:
    """alignment.json for a map without roads (road_source=scan found none): the identity."""
    return {"yaw_deg": 0.0, "tx_m": 0.0, "ty_m": 0.0, "dz_m": 0.0, "scale_estimate": 1.0, "kept_identity": True,
            "no_roads": True, "definition": DEFINITION, "note": "no roads in the map: nothing to align"}


def fit_or_keep(sec: Sections, mask: np.ndarray, grid: Grid, *, source: str, log, search_m: float,
                **fit_kw) -> FitResult:
    """``fit`` of the sections to the road mask; a network drawn from this very mesh (``source`` 'scan', see
    twinkit.geo.xodr.source_kind) is not searched for and keeps the identity unless a rigid move fits better,
    and when the fit finds no road surface at all it is kept in place (``kept_identity``, residuals NaN) instead
    of failing the run. A network of another source that finds no road surface fails with the fix that fits its
    source (``source_hint(source, "no_overlap")``).

    A network from the scan is already where the mesh's roads are: a fit against a cruder road surface (the
    ground level, which takes ramped sidewalks too) can only move it off; and that the cruder surface does not
    find it is no reason to stop the run (paths drawn on paved-looking ground the ground test does not take)."""
    from twinkit.geo.xodr import source_hint

    from_scan = source == "scan"
    try:
        return fit(sec, mask, grid, search_m=0.0 if from_scan else search_m, keep_identity=from_scan, **fit_kw)
    except NoOverlap as exc:
        if not from_scan:
            raise InputError(f"{exc} ({source_hint(source, 'no_overlap')})") from None
        log.warning("alignment: %s; the scan's own network needs no alignment and is kept in place (its residual "
                    "is not measured)", exc)
        nan = float("nan")
        return FitResult(Transform2D(about=tuple(sec.c.mean(0)) if len(sec.c) else (0.0, 0.0)), nan, nan,
                         len(sec.c), 0, 0, False, kept_identity=True)


def surface_dz(vertices: np.ndarray, faces: np.ndarray, fidx: np.ndarray, tf: Transform2D, sec: Sections,
               from_scan: bool) -> float:
    """Metres to add to the OpenDRIVE's heights: the median, over the carriageway middles moved by ``tf``, of
    the road surface's height (the nearest vertex of the road faces ``fidx`` within 1 m, site frame) minus the
    OpenDRIVE's own height there (0 from OSM; the scanned heights from road_source=scan). With fewer than 6
    middles on the surface: 0 for the scan's own network (it carries the scanned heights), else the difference
    of the medians of the whole surface and network."""
    from scipy.spatial import cKDTree

    rv = np.unique(faces[fidx].ravel())
    d, i = cKDTree(vertices[rv, :2]).query(tf.apply(sec.c), distance_upper_bound=1.0)
    hit = np.isfinite(d)
    if hit.sum() >= 6:
        return float(np.median(vertices[rv[i[hit]], 2] - sec.z[hit]))
    if from_scan:
        return 0.0
    return float(np.median(vertices[rv, 2]) - np.median(sec.z))


def _r(x: float, nd: int) -> float | None:
    return round(x, nd) if math.isfinite(x) else None


def alignment_doc(res: FitResult, dz: float, how: str, model: str, kerb=None, offsets: dict | None = None) -> dict:
    """alignment.json: the rigid move (``res.tf`` about the site origin), the height offset ``dz`` (m), the fit's
    residuals and, when the kerb refinement ran (``kerb``: a ``kerbs.KerbFit``), its result and the per-road lane
    offsets ({road id: metres to the left})."""
    yaw, tx, ty, scale = res.tf.about_origin()
    doc = {
        "yaw_deg": round(math.degrees(yaw), 6), "tx_m": round(tx, 4), "ty_m": round(ty, 4), "dz_m": round(dz, 4),
        "scale_estimate": round(scale, 6),
        "definition": DEFINITION + ". Edit the numbers and re-run: later steps use your values.",
        "residual_rmse_m": _r(res.rmse_after, 4), "residual_rmse_before_m": _r(res.rmse_before, 4),
        "sections": res.n_sections, "sections_used": res.n_used, "iterations": res.iterations,
        "degenerate": res.degenerate, "kept_identity": res.kept_identity, "road_surface_from": how,
        "model": model,
        "note": "residual = RMS offset between carriageway middles of the network and of the mesh's road surface",
    }
    if kerb is not None:
        doc["kerbs"] = {"edges": kerb.edges, "applied": kerb.applied, "why_not": kerb.why or None,
                        "median_offset_before_m": _r(kerb.before_m, 4), "median_offset_after_m": _r(kerb.after_m, 4),
                        "shift_m": [round(x, 4) for x in kerb.shift_m], "yaw_deg": round(kerb.yaw_deg, 4),
                        "note": "lane edges against the foot of the kerb beside them (profiles of vertical rays "
                                "across each driving lane border); included in yaw_deg / tx_m / ty_m when applied"}
        doc["lane_offsets_m"] = {str(k): v for k, v in sorted((offsets or {}).items())}
        doc["lane_offsets_note"] = ("per OpenDRIVE road id: metres to the left of its reference line, added to its "
                                    "<laneOffset> by apply_alignment after the rigid move (each road onto its own "
                                    "kerbs); edit or empty it by hand like the numbers above")
    return doc


def alignment_metrics(doc: dict, kerb=None) -> dict:
    """The align_roads step's metrics from its alignment.json ``doc`` and the kerb refinement."""
    return {**{k: doc[k] for k in ("yaw_deg", "tx_m", "ty_m", "dz_m", "residual_rmse_m", "residual_rmse_before_m",
                                   "sections_used", "road_surface_from", "kept_identity")},
            "kerb_edges": kerb.edges if kerb else 0, "kerb_applied": bool(kerb and kerb.applied),
            "kerb_offset_after_m": doc.get("kerbs", {}).get("median_offset_after_m")}

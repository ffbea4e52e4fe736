"""CPU dense reconstruction: plane-sweep stereo per photo, then multi-view consistency fusion.

Why plane sweep and not rectified-pair block matching: walked photo sets move mostly forward (the
epipole lies inside the image), where rectification degenerates; a plane sweep handles any motion.

Per reference photo r and its best neighbours n (triangulation angle 3-30 degrees, similar viewing
direction, many shared SfM points):
  coarse: at ``coarse_scale`` of the working resolution, four plane families (fronto-parallel, the
  ground, the two street sides; Gallup et al. 2007) spaced one pixel of parallax apart; each plane warps
  every neighbour with its homography K_n (R + t n^T / d) K_r^-1 and scores a zero-mean NCC over a
  window (box filters); the best neighbour's cost counts; winner takes all.
  fine: passes at full working resolution with 9 per-pixel depth hypotheses around the current depth
  (cv2.remap), a parabola for sub-sample precision; weak, textureless or edge-of-search pixels dropped.
Fusion: every depth is projected into the other photos' depth maps; a pixel survives when at least
``min_consistent`` other depth maps agree within ``rel_tol`` of the depth (one, where fewer other photos could
confirm it at all: ``confirm_max_scale``). Normals come from the depth
map (cross product of neighbouring points), oriented towards the photo; colours from the photo.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np


def scaled_view(gray: np.ndarray, K: np.ndarray, f: float) -> tuple[np.ndarray, np.ndarray]:
    """A photo resized by ``f`` (area averaging) and its intrinsics for that size (pixel centres kept)."""
    import cv2

    hh, ww = gray.shape
    g = cv2.resize(gray, (int(round(ww * f)), int(round(hh * f))), interpolation=cv2.INTER_AREA)
    K2 = np.array(K, np.float64, copy=True)
    K2[:2, :2] *= f
    K2[0, 2] = (K[0, 2] + 0.5) * f - 0.5
    K2[1, 2] = (K[1, 2] + 0.5) * f - 0.5
    return g, K2


@dataclass
class DenseOptions:
    max_image_px: int = 640
    planes: int = 192  # most planes per family of the coarse sweep
    neighbors: int = 4
    window_px: int = 7
    min_ncc: float = 0.55
    min_angle_deg: float = 3.0
    max_angle_deg: float = 30.0
    min_shared: int = 10  # SfM points two photos must share to be matched against each other
    min_consistent: int = 2
    rel_tol: float = 0.01
    max_depth_m: float = 0.0  # 0 = from the SfM points only
    plane_step_px: float = 1.0  # coarse sweep: planes this many pixels of parallax apart
    refine_passes: int = 2  # full-resolution refinements (9 hypotheses each, shrinking)
    up: tuple = (0.0, 0.0, 1.0)  # world up (the site frame's z)
    coarse_scale: float = 0.25  # resolution of the coarse sweep (0.5 = half: 4x faster, less reliable)
    threads: int = 2
    average_depths: bool = True  # fuse: average each point's depth with the depth maps that agree
    min_triangulation_deg: float = 0.0  # fuse: keep a point only if an agreeing map sees it this far apart
    # fuse: a point needs min_consistent agreeing maps only where that many other photos could confirm it (it
    # lies in their frame and depth range, seen from at most this many times its distance); else one. 0 = always
    confirm_max_scale: float = 0.0
    ground_planes: bool = True  # PatchMatch: try the ground under the camera (from the SfM points) at every pixel


@dataclass
class View:
    name: str
    K: np.ndarray  # at the working resolution
    R_wc: np.ndarray
    C: np.ndarray
    gray: np.ndarray  # float32 0..1
    rgb: np.ndarray  # uint8
    dmin: float = 0.0
    dmax: float = 0.0
    depth: np.ndarray | None = None
    planes: tuple | None = None  # PatchMatch's per-pixel planes (normals (h, w, 3), offsets (h, w)), camera frame
    pts_cam: np.ndarray | None = None  # SfM points seen by the photo, camera frame
    normal: np.ndarray | None = None

    @property
    def R_cw(self):
        return self.R_wc.T

    def to_cam(self, X):
        return (X - self.C) @ self.R_wc  # == R_cw @ (X - C)


def load_views(image_dir: Path, cams: list[dict], max_px: int) -> list[View]:
    import cv2

    views = []
    for c in cams:
        path = Path(image_dir) / c["image"]
        img = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if img is None:
            from twinkit import InputError

            raise InputError(f"{path}: cannot read the photo for dense matching; restore the file or re-run sfm")
        h, w = img.shape[:2]
        K = np.asarray(c["K"], float).copy()
        # undistort with the SfM radial term (SIMPLE_RADIAL / RADIAL), to the same pinhole K
        params = c.get("params", [])
        model = c.get("model", "")
        dist = None
        if model in ("SIMPLE_RADIAL", "RADIAL") and len(params) >= 4 and abs(params[3]) > 1e-9:
            dist = np.array([params[3], params[4] if model == "RADIAL" else 0.0, 0, 0], float)
        s = min(1.0, max_px / max(w, h))
        if dist is not None:
            img = cv2.undistort(img, K, dist)
        if s < 1.0:
            img = cv2.resize(img, (int(round(w * s)), int(round(h * s))), interpolation=cv2.INTER_AREA)
            K[:2] *= s
            K[0, 2] = (c["K"][0][2] + 0.5) * s - 0.5
            K[1, 2] = (c["K"][1][2] + 0.5) * s - 0.5
        rgb = img[:, :, ::-1].copy()
        gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY).astype(np.float32) / 255.0
        views.append(View(c["image"], K, np.asarray(c["R_world_from_camera"], float),
                          np.asarray(c["center"], float), gray, rgb))
    return views


def depth_ranges(views: list[View], sparse: np.ndarray, vis: dict[str, np.ndarray], max_depth: float) -> None:
    for v in views:
        idx = vis.get(v.name)
        P = sparse[idx] if idx is not None and len(idx) >= 10 else sparse
        Xc = v.to_cam(P)
        z = Xc[:, 2]
        h, w = v.gray.shape
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = Xc @ v.K.T
            u, vv = uv[:, 0] / z, uv[:, 1] / z
        z = z[(z > 1e-6) & (u >= 0) & (u < w) & (vv >= 0) & (vv < h)]
        if len(z) < 5:
            v.dmin, v.dmax = 0.0, 0.0
            continue
        lo, hi = np.quantile(z, [0.01, 0.99])
        v.dmin, v.dmax = float(lo * 0.75), float(hi * 1.3)
        v.pts_cam = Xc[(Xc[:, 2] > 1e-6) & (Xc[:, 2] < v.dmax)]
        if max_depth > 0:
            v.dmax = min(v.dmax, max_depth)
            v.dmin = min(v.dmin, 0.5 * v.dmax)


def near_limit_from_ground(views: list[View], normal, ground_z: float) -> None:
    """Lower each view's near depth limit to the nearest ground it sees: the SfM points of a street photo
    are mostly far (the near road has few features), so their depth range cuts off the road in front of
    the photo. The ground plane (``normal`` . X = ``normal`` . (0, 0, ground_z)) met by the rays of the
    photo's bottom edge gives that depth."""
    nrm = np.asarray(normal, float)
    nrm = nrm / np.linalg.norm(nrm)
    off = nrm @ np.array([0.0, 0.0, float(ground_z)])
    for v in views:
        if v.dmax <= 0:
            continue
        h, w = v.gray.shape
        height = float(nrm @ v.C - off)
        if height <= 0:
            continue
        us = np.linspace(0, w - 1, 9)
        pix = np.stack([np.concatenate([us, us, np.zeros(3), np.full(3, w - 1.0)]),
                        np.concatenate([np.full(9, h - 1.0), np.full(9, h * 0.75),
                                        np.linspace(h / 2, h - 1, 3), np.linspace(h / 2, h - 1, 3)]),
                        np.ones(24)], 1)
        rays = pix @ np.linalg.inv(v.K).T @ v.R_wc.T  # world directions with camera z = 1
        down = -(rays @ nrm)
        z = height / down[down > 1e-6]  # camera depth where the ray meets the ground
        if len(z):
            v.dmin = float(min(v.dmin, 0.8 * z.min()))


def pair_angles(sparse: np.ndarray, shared: np.ndarray, C_a: np.ndarray, C_b: np.ndarray) -> np.ndarray:
    """Triangulation angle (degrees) of each shared SfM point between two camera centres."""
    P = sparse[shared]
    a = P - C_a
    b = P - C_b
    cos = np.sum(a * b, 1) / np.maximum(np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-12)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def scale_weight(P: np.ndarray, r: View, n: View) -> np.ndarray:
    """Per point, how alike its size is in the two photos (Goesele et al. 2007's scale term, made
    symmetric): 1 while the pixel footprints differ by at most 1.25x, falling with the square of the ratio
    beyond. A photo 12 m further along a walk sees the wall beside the other photo 3-4x smaller, and a
    matching window cannot compare such patches."""
    fr = np.linalg.norm(P - r.C, axis=1) / float(r.K[0, 0])
    fn = np.linalg.norm(P - n.C, axis=1) / float(n.K[0, 0])
    ratio = np.maximum(fr, fn) / np.maximum(np.minimum(fr, fn), 1e-12)
    return np.minimum(1.0, (1.25 / ratio) ** 2)


def choose_neighbors(views: list[View], vis: dict[str, np.ndarray], opt: DenseOptions,
                     sparse: np.ndarray | None = None) -> dict[int, list[int]]:
    """Up to ``opt.neighbors`` photos per photo to match against.

    With the SfM points (``sparse``, site frame), a pair is scored by the triangulation angles of the points
    both photos see, as MVSNet's view selection does: each shared point adds exp(-(a - 5)^2 / 2 s^2) with
    s = 1 degree below 5 degrees and 10 above, times how alike the point's size is in both photos
    (``scale_weight``), so many well-triangulated shared points seen at a similar scale win. A pair needs
    at least ``min_shared`` such points, a median angle under ``max_angle_deg``, a 90th percentile of at
    least ``min_angle_deg`` (some of the shared surface is triangulated well enough to give depth) and
    viewing directions within 50 degrees. The angles are the real ones of the shared surface: a photo set
    walked forward has small angles ahead and large ones on the walls beside the walk, which a single
    angle at the photo's middle depth gets wrong (on Lund it left most photos one neighbour).
    Without the SfM points: that single-angle estimate (baseline at the middle of the photo's depth range).
    """
    out = {}
    sets = {v.name: vis.get(v.name, np.zeros(0, np.int64)) for v in views}
    for i, r in enumerate(views):
        depth = 0.5 * (r.dmin / 0.75 + r.dmax / 1.3) if r.dmax > 0 else 10.0
        cand = []
        for j, n in enumerate(views):
            if j == i:
                continue
            dir_ang = np.degrees(np.arccos(np.clip(r.R_wc[:, 2] @ n.R_wc[:, 2], -1, 1)))
            if dir_ang > 50:
                continue
            shared = np.intersect1d(sets[r.name], sets[n.name], assume_unique=False)
            if sparse is not None and len(sparse):
                if len(shared) < opt.min_shared:
                    continue
                ang = pair_angles(sparse, shared, r.C, n.C)
                if np.median(ang) > opt.max_angle_deg or np.percentile(ang, 90) < opt.min_angle_deg:
                    continue
                g = np.where(ang <= 5.0, np.exp(-((ang - 5.0) ** 2) / 2.0), np.exp(-((ang - 5.0) ** 2) / 200.0))
                cand.append((float(np.sum(g * scale_weight(sparse[shared], r, n))), j))
            else:
                b = float(np.linalg.norm(n.C - r.C))
                ang1 = np.degrees(2 * np.arctan2(b / 2, depth))
                if ang1 < opt.min_angle_deg or ang1 > opt.max_angle_deg:
                    continue
                cand.append((len(shared) * np.exp(-((ang1 - 10.0) / 10.0) ** 2), j))
        cand.sort(reverse=True)
        out[i] = [j for _, j in cand[: opt.neighbors]]
    return out


def _box(img, k):
    import cv2

    return cv2.boxFilter(img, -1, (k, k), normalize=True, borderType=cv2.BORDER_REFLECT)


def _ncc_cost(r: View, warped: np.ndarray, stats, k: int) -> np.ndarray:
    mr, vr = stats
    valid = _box((warped >= 0).astype(np.float32), k) > 0.999
    warped = np.maximum(warped, 0)
    mn = _box(warped, k)
    vn = np.maximum(_box(warped * warped, k) - mn * mn, 0)
    cov = _box(warped * r.gray, k) - mr * mn
    ncc = cov / np.sqrt(vr * vn + 1e-8)
    return np.where(valid & (vn > 1e-5), 1.0 - ncc, 2.0).astype(np.float32)


AGG = "min"


def _aggregate(per: np.ndarray) -> np.ndarray:
    """Best neighbour's cost (a neighbour that cannot see the pixel at this depth is ignored, so the
    hypotheses are not biased towards depths that stay inside every neighbour's frame)."""
    if AGG == "min" or len(per) < 2:
        return per.min(0)
    part = np.partition(per, 1, axis=0)
    return np.where(part[1] < 1.5, 0.5 * (part[0] + part[1]), part[0] + 0.1)


def _wta(cost: np.ndarray, inv: np.ndarray):
    """Winner takes all over axis 0 with a parabola; ``inv`` (P,) or (P, h, w) inverse depths per slice."""
    P, h, w = cost.shape
    best = np.argmin(cost, axis=0)
    ii, jj = np.indices((h, w))
    c0 = cost[best, ii, jj]
    lo = np.clip(best - 1, 0, P - 1)
    hi = np.clip(best + 1, 0, P - 1)
    cl, ch = cost[lo, ii, jj], cost[hi, ii, jj]
    den = cl - 2 * c0 + ch
    off = np.where((best > 0) & (best < P - 1) & (den > 1e-6), 0.5 * (cl - ch) / np.maximum(den, 1e-6), 0.0)
    off = np.clip(off, -0.5, 0.5)
    if inv.ndim == 1:
        step = inv[1] - inv[0]
        invd = inv[best] + off * step
    else:
        step = inv[1] - inv[0]
        invd = inv[best, ii, jj] + off * step
    interior = (best > 0) & (best < P - 1)
    return invd, 1.0 - c0, interior


def plane_sweep(r: View, nbrs: list[View], opt: DenseOptions) -> tuple[np.ndarray, np.ndarray]:
    """Depth (0 = unknown) and NCC score for the reference view: a coarse homography sweep at half
    resolution, then a per-pixel refinement at full resolution (remap by the hypothesised depth)."""
    import cv2

    h, w = r.gray.shape
    k = int(opt.window_px) | 1
    rel = [(n.R_cw @ r.R_wc, n.R_cw @ (r.C - n.C), n) for n in nbrs]
    invd_s, dinv = _coarse_sweep(r, rel, opt, k)
    invd0 = cv2.resize(invd_s.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR).astype(np.float64)
    return _refine_sweep(r, rel, invd0, 1.5 * dinv, opt, k)


def _sweep_planes(r: View, opt: DenseOptions, Kr: np.ndarray, rel: list) -> tuple[list, float, float]:
    """The coarse sweep's planes (normal in the reference camera frame, 1 / offset), the widest baseline's
    parallax in pixels per unit of 1 / depth, and the inverse-depth step of the sweep.

    Plane families (Gallup et al.): fronto-parallel, the ground, and the two street sides; offsets d
    (n . X = d) from the SfM points the photo sees."""
    up_cam = r.R_cw @ np.asarray(opt.up, float)
    fwd = r.R_wc[:, 2] - np.asarray(opt.up, float) * (r.R_wc[:, 2] @ np.asarray(opt.up, float))
    fam = [np.array([0.0, 0.0, 1.0])]
    if np.linalg.norm(fwd) > 0.3:
        side = np.cross(fwd, np.asarray(opt.up, float))
        side_cam = r.R_cw @ (side / np.linalg.norm(side))
        fam += [-up_cam, side_cam, -side_cam]
    planes = []
    f_c = 0.5 * (Kr[0, 0] + Kr[1, 1])
    max_parallax = f_c * max(float(np.linalg.norm(n.C - r.C)) for _, _, n in rel)  # px per unit of 1/depth
    dinv = opt.plane_step_px / max_parallax  # inverse-depth step of the coarse sweep
    for nrm in fam:
        if r.pts_cam is not None and len(r.pts_cam) >= 10:
            dd = r.pts_cam @ nrm
            dd = dd[dd > 1e-3]
            if len(dd) < 5:
                continue
            lo, hi = np.quantile(dd, [0.01, 0.99])
            lo, hi = lo * 0.75, hi * 1.3
        else:
            lo, hi = r.dmin, r.dmax
        if nrm is not fam[0]:
            lo = max(lo, 0.05 * r.dmax / 40.0)
        # one plane per ``plane_step_px`` of parallax at the coarse scale for the widest baseline
        span = abs(1.0 / lo - 1.0 / hi) * max_parallax
        cap = opt.planes if nrm is fam[0] else max(16, opt.planes // 2)
        npl = int(np.clip(np.ceil(span / opt.plane_step_px), 8, cap))
        for idep in np.linspace(1.0 / lo, 1.0 / hi, npl):
            planes.append((nrm, idep))
    return planes, max_parallax, dinv


def _coarse_sweep(r: View, rel: list, opt: DenseOptions, k: int) -> tuple[np.ndarray, float]:
    """Inverse depth per pixel at ``coarse_scale`` (homography warps of every plane, best neighbour's NCC,
    winner takes all) and the sweep's inverse-depth step."""
    import cv2

    f = float(opt.coarse_scale)

    def _scaled(gray, K):
        return (gray, K) if f >= 1.0 else scaled_view(gray, K, f)

    g_r, Kr = _scaled(r.gray, r.K)
    hs, ws = g_r.shape
    small = View(r.name, Kr, r.R_wc, r.C, g_r, r.rgb)
    ks = k if f >= 1.0 else max(5, int(k * f) | 1)
    mr = _box(g_r, ks)
    stats_s = (mr, np.maximum(_box(g_r * g_r, ks) - mr * mr, 0))
    g_n, Kn_s = [], []
    for _, _, n in rel:
        g, K2 = _scaled(n.gray, n.K)
        g_n.append(g)
        Kn_s.append(K2)
    Kinv = np.linalg.inv(Kr)
    planes, _, dinv = _sweep_planes(r, opt, Kr, rel)
    cost = np.empty((len(planes), hs, ws), np.float32)
    per = np.empty((len(rel), hs, ws), np.float32)
    us, vs = np.meshgrid(np.arange(ws, dtype=np.float64), np.arange(hs, dtype=np.float64))
    rays_s = np.stack([us, vs, np.ones_like(us)], -1) @ Kinv.T
    zmin, zmax = 0.5 * r.dmin, r.dmax
    for di, (nrm, idep) in enumerate(planes):
        inv_z = rays_s @ nrm * idep  # 1 / depth where the pixel's ray meets this plane
        hit = (inv_z > 1.0 / zmax) & (inv_z < 1.0 / zmin)
        if not hit.any():
            cost[di] = 2.0
            continue
        for ni, (R_nr, t_nr, _) in enumerate(rel):
            H = Kn_s[ni] @ (R_nr + np.outer(t_nr, nrm) * idep) @ Kinv
            warped = cv2.warpPerspective(g_n[ni], H, (ws, hs), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                         borderMode=cv2.BORDER_CONSTANT, borderValue=-1.0)
            per[ni] = _ncc_cost(small, warped, stats_s, ks)
        cost[di] = np.where(hit, _aggregate(per), 2.0)
    best = np.argmin(cost, axis=0)
    del cost
    N = np.array([p[0] for p in planes])[best]
    ID = np.array([p[1] for p in planes])[best]
    ndot = np.sum(rays_s * N, -1)
    return np.where(ndot > 1e-6, ID * ndot, 1.0 / r.dmax), dinv  # 1/depth = (n . ray) / d


def _refine_sweep(r: View, rel: list, invd0: np.ndarray, width: float, opt: DenseOptions,
                  k: int) -> tuple[np.ndarray, np.ndarray]:
    """Full resolution: ``refine_passes`` of 9 per-pixel inverse-depth hypotheses around ``invd0`` (within
    +-``width``, narrowing), scored by remapping the neighbours; weak, textureless or edge-of-search pixels
    dropped. Returns (depth float32, 0 = unknown; NCC score float32)."""
    import cv2

    h, w = r.gray.shape
    mr = _box(r.gray, k)
    stats = (mr, np.maximum(_box(r.gray * r.gray, k) - mr * mr, 0))
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    rays = np.stack([u, v, np.ones_like(u)], -1) @ np.linalg.inv(r.K).T  # (h, w, 3), z = 1
    invd = invd0
    for _pass in range(opt.refine_passes):
        offs = np.linspace(-width, width, 9)
        hyp = np.empty((len(offs), h, w), np.float64)
        fcost = np.empty((len(offs), h, w), np.float32)
        per = np.empty((len(rel), h, w), np.float32)
        for oi, o in enumerate(offs):
            idep = np.clip(invd + o, 1e-6, None)
            hyp[oi] = idep
            X = rays / idep[..., None]
            for ni, (R_nr, t_nr, n) in enumerate(rel):
                Xn = X @ R_nr.T + t_nr
                z = Xn[..., 2]
                with np.errstate(divide="ignore", invalid="ignore"):
                    uv = Xn @ n.K.T
                    mu = np.where(z > 1e-6, uv[..., 0] / z, -10).astype(np.float32)
                    mv = np.where(z > 1e-6, uv[..., 1] / z, -10).astype(np.float32)
                warped = cv2.remap(n.gray, mu, mv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                                   borderValue=-1.0)
                per[ni] = _ncc_cost(r, warped, stats, k)
            fcost[oi] = _aggregate(per)
        invd, score, interior = _wta(fcost, hyp)
        width = width * 1.5 / 4.0
    depth = 1.0 / np.maximum(invd, 1e-9)
    textured = stats[1] > 1e-4
    ok = textured & (score >= opt.min_ncc) & interior & (depth > r.dmin) & (depth < r.dmax)
    depth = np.where(ok, depth, 0.0).astype(np.float32)
    return depth, score.astype(np.float32)


def ground_planes(r: View, opt: DenseOptions, radius_m: float = 20.0) -> list:
    """The ground under a photo as planes (n, c) of its camera frame (n . X = c, n = the world's up, facing the
    camera from below): horizontal, at the heights below the camera of the lowest SfM points it sees within
    ``radius_m`` (their 75th, 85th and 95th percentile of depth below it: the ground, not a mismatch under
    it). Per photo, not the region of interest's one ground plane (``near_limit_from_ground``): a walk of
    hundreds of metres climbs and turns, and the ground just ahead of each photo is what counts. An empty
    list without 10 such points."""
    up = np.asarray(opt.up, float)
    up_cam = r.R_cw @ (up / np.linalg.norm(up))
    if r.pts_cam is None or len(r.pts_cam) < 10:
        return []
    below = -(r.pts_cam @ up_cam)  # height of each point under the camera
    horiz = np.linalg.norm(r.pts_cam - np.outer(r.pts_cam @ up_cam, up_cam), axis=1)
    b = below[(horiz <= radius_m) & (below > 0)]
    if len(b) < 10:
        return []
    return [(up_cam.astype(np.float32), -float(h)) for h in np.percentile(b, [75, 85, 95])]


def patchmatch_view(r: View, nbrs: list[View], opt: DenseOptions, pm=None) -> tuple[np.ndarray, np.ndarray]:
    """Depth (0 = unknown) and NCC of the reference view by PatchMatch (twinkit_photo.patchmatch); sets
    ``r.normal`` (world, facing the photo) where a depth was kept."""
    from .patchmatch import PMOptions, patchmatch

    pm = pm or PMOptions(threads=opt.threads)
    rel = [(n.gray, n.K, n.R_cw @ r.R_wc, n.R_cw @ (r.C - n.C)) for n in nbrs]
    depth, n_cam, score, r.planes = patchmatch(r.gray, r.K, rel, r.dmin, r.dmax, pm,
                                               planes=ground_planes(r, opt) if opt.ground_planes else ())
    _set_normals(r, depth, n_cam)
    return depth, score


def _set_normals(r: View, depth, n_cam) -> None:
    nrm = n_cam.reshape(-1, 3) @ r.R_wc.T
    nrm = nrm.reshape(n_cam.shape)
    nrm[depth <= 0] = np.nan
    r.normal = nrm


def patchmatch_geom_view(r: View, nbrs: list[View], nbr_depths: list[np.ndarray], opt: DenseOptions,
                         pm=None) -> tuple[np.ndarray, np.ndarray]:
    """The geometric pass of ``r`` (after ``patchmatch_view`` of every photo): its planes refined with the
    neighbours' photometric depth maps ``nbr_depths`` as a second cost (twinkit_photo.patchmatch); a neighbour
    whose map is None (it had no usable neighbour of its own) is judged by the photos alone."""
    from .patchmatch import PMOptions, patchmatch

    pm = pm or PMOptions(threads=opt.threads)
    rel = [(n.gray, n.K, n.R_cw @ r.R_wc, n.R_cw @ (r.C - n.C)) for n in nbrs]
    depth, n_cam, score, r.planes = patchmatch(r.gray, r.K, rel, r.dmin, r.dmax, pm, init=r.planes,
                                               geo=list(nbr_depths))
    _set_normals(r, depth, n_cam)
    return depth, score


def backproject(v: View, depth: np.ndarray) -> np.ndarray:
    h, w = depth.shape
    u, vv = np.meshgrid(np.arange(w), np.arange(h))
    rays = np.stack([u, vv, np.ones_like(u)], -1).reshape(-1, 3) @ np.linalg.inv(v.K).T
    Xc = rays * depth.reshape(-1, 1)
    return (Xc @ v.R_wc.T + v.C).reshape(h, w, 3)


def depth_normals(v: View, pts: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """Normals (world) from neighbouring back-projected points, facing the camera; NaN where undefined."""
    dx = np.zeros_like(pts)
    dy = np.zeros_like(pts)
    dx[:, 1:-1] = pts[:, 2:] - pts[:, :-2]
    dy[1:-1] = pts[2:] - pts[:-2]
    nrm = np.cross(dx, dy)
    ln = np.linalg.norm(nrm, axis=-1, keepdims=True)
    good = np.zeros(depth.shape, bool)
    good[1:-1, 1:-1] = ((depth[1:-1, 2:] > 0) & (depth[1:-1, :-2] > 0) & (depth[2:, 1:-1] > 0)
                        & (depth[:-2, 1:-1] > 0) & (depth[1:-1, 1:-1] > 0))
    nrm = nrm / np.maximum(ln, 1e-12)
    tocam = v.C - pts
    flip = np.sum(nrm * tocam, -1) < 0
    nrm[flip] *= -1
    nrm[~good] = np.nan
    return nrm


def fuse(views: list[View], opt: DenseOptions, progress=None):
    """Consistent points of every depth map: xyz, rgb, normals, source view index."""
    out_xyz, out_rgb, out_n, out_src = [], [], [], []
    it = range(len(views)) if progress is None else progress(range(len(views)))
    for i in it:
        v = views[i]
        if v.depth is None:
            continue
        d = v.depth
        valid = d > 0
        if not valid.any():
            continue
        pts = backproject(v, d)
        nrm = v.normal if v.normal is not None else depth_normals(v, pts, d)
        P = pts[valid]
        cnt = np.zeros(len(P), np.int32)
        could = np.zeros(len(P), np.int32)  # other photos that could confirm the point (confirm_max_scale)
        z_ref = d[valid]
        ratio_sum = np.ones(len(P), np.float64)  # this view's own depth counts once (ratio 1)
        min_ang = opt.min_triangulation_deg
        best_cos = np.ones(len(P), np.float64) if min_ang > 0 else None
        if best_cos is not None:
            ray_i = P - v.C
            ray_i /= np.maximum(np.linalg.norm(ray_i, axis=1, keepdims=True), 1e-12)
        for j, o in enumerate(views):
            if j == i or o.depth is None:
                continue
            Xc = o.to_cam(P)
            z = Xc[:, 2]
            front = z > 1e-6
            uv = (Xc @ o.K.T)
            with np.errstate(divide="ignore", invalid="ignore"):
                u = np.round(uv[:, 0] / z).astype(np.int64, copy=False) if front.any() else None
                vv = np.round(uv[:, 1] / z).astype(np.int64, copy=False) if front.any() else None
            if u is None:
                continue
            hh, ww = o.depth.shape
            inside = front & (u >= 0) & (u < ww) & (vv >= 0) & (vv < hh)
            dz = np.zeros(len(P), np.float32)
            dz[inside] = o.depth[vv[inside], u[inside]]
            ok = inside & (dz > 0) & (np.abs(dz - z) < opt.rel_tol * z)
            cnt += ok
            if opt.confirm_max_scale > 0:
                could += (inside & (z > o.dmin) & ((o.dmax <= 0) | (z < o.dmax))
                          & (z <= opt.confirm_max_scale * z_ref))
            if best_cos is not None and ok.any():
                k = np.flatnonzero(ok)
                ray_j = P[k] - o.C
                c = np.sum(ray_i[k] * ray_j, 1) / np.maximum(np.linalg.norm(ray_j, axis=1), 1e-12)
                best_cos[k] = np.minimum(best_cos[k], c)
            ratio_sum[ok] += dz[ok] / z[ok]
        need = opt.min_consistent
        if opt.confirm_max_scale > 0:
            need = np.minimum(opt.min_consistent, np.maximum(could, 1))
        keep = cnt >= need
        if best_cos is not None:
            keep &= best_cos <= np.cos(np.radians(min_ang))
        if opt.average_depths:
            # average the agreeing depth maps: the other view's depth over the predicted one is, for the
            # small baselines of neighbouring photos, the same ratio along this view's ray; noise falls ~1/sqrt(n)
            P = v.C + (P - v.C) * (ratio_sum / (cnt + 1))[:, None]
        n = nrm[valid][keep]
        good = np.isfinite(n).all(1)
        out_xyz.append(P[keep][good])
        out_rgb.append(v.rgb[valid][keep][good])
        out_n.append(n[good])
        out_src.append(np.full(int(good.sum()), i, np.int32))
    if not out_xyz:
        return np.zeros((0, 3)), np.zeros((0, 3), np.uint8), np.zeros((0, 3)), np.zeros(0, np.int32)
    return np.concatenate(out_xyz), np.concatenate(out_rgb), np.concatenate(out_n), np.concatenate(out_src)


def voxel_merge(xyz, rgb, nrm, voxel: float):
    """Average points, colours and normals per voxel (duplicates from overlapping depth maps)."""
    if voxel <= 0 or len(xyz) == 0:
        return xyz, rgb, nrm
    key = np.floor((xyz - xyz.min(0)) / voxel).astype(np.int64)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    m = len(cnt)
    sx = np.zeros((m, 3))
    np.add.at(sx, inv, xyz)
    sc = np.zeros((m, 3))
    np.add.at(sc, inv, rgb.astype(float))
    sn = np.zeros((m, 3))
    np.add.at(sn, inv, nrm)
    ln = np.linalg.norm(sn, axis=1, keepdims=True)
    return sx / cnt[:, None], np.clip(np.round(sc / cnt[:, None]), 0, 255).astype(np.uint8), sn / np.maximum(ln, 1e-12)

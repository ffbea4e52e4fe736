"""CPU PatchMatch multi-view stereo (numpy + OpenCV, vectorised over all pixels at once).

Every pixel of the reference photo carries a plane (a normal n and an offset c with n . X = c in the
reference camera frame), so slanted surfaces -- the road seen at a grazing angle, a façade seen
obliquely -- are matched with windows that follow them, not with fronto-parallel squares. A plane maps
the reference window into a neighbour photo by the homography

    H = K_n (R + t n^T / c) K_r^-1 = H_0 + (K_n t) (K_r^-T n / c)^T,

so the part H_0 q of every window sample q is computed once per neighbour and each hypothesis adds a
rank-one term: a few multiply-adds per sample, then one bilinear lookup (``cv2.remap``).

Cost: one minus the zero-mean NCC of the window (``window`` x ``window`` samples, ``dilation`` pixels
apart), per neighbour; the pixel's cost is the mean of its best ``top_k`` neighbours (a neighbour that
does not see the pixel -- occluded, out of frame, or looking along the walk where nothing moves --
does not vote).

Search (Bleyer et al. 2011; Schönberger et al. 2016; Xu & Tao 2019 for the adaptive sampling):
random planes to start, then per iteration every pixel tries
  * the planes of its best-cost pixel among those 1, 3 and 9 pixels away in each of four directions
    (propagation: a good plane spreads along the whole surface it belongs to within a few iterations),
  * its own plane perturbed (depth and normal, by amounts shrinking with the iterations),
  * a fresh random plane,
and keeps the cheapest. This runs coarse to fine: at half the working resolution first (planes do not
depend on the resolution, so they carry over as they are), then at the working resolution.

A geometric pass (Schönberger et al. 2016) follows once every photo has its map: the planes are refined
again at the working resolution with the forward-backward reprojection error against each neighbour's map
added to that neighbour's cost (``patchmatch(init=..., geo=...)``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class PMOptions:
    window: int = 5  # samples per side of the matching window
    dilation: int = 2  # pixels between window samples (5 x 5 samples over 9 x 9 pixels)
    sparse_window: bool = True  # only the window's checkerboard samples (13 of 5 x 5; Galliani et al. 2015)
    iters_coarse: int = 4
    iters_fine: int = 3
    top_k: int = 2  # the pixel's cost: mean of its best top_k neighbours
    min_ncc: float = 0.5  # keep a pixel whose aggregated NCC reaches this
    min_texture: float = 1e-4  # reference window variance (gray 0..1) below this: no depth
    seed: int = 0
    threads: int = 2
    geom_weight: float = 0.3  # geometric pass: cost += weight * min(forward-backward error px, geom_max_px)
    geom_max_px: float = 3.0


class _Level:
    """One resolution: the reference window samples and the neighbours' constant homography parts.
    Arrays are sample-major, (S, P): S window samples of P pixels, float32."""

    def __init__(self, ref_gray, K_r, nbrs, opt: PMOptions, geo=None):
        """``geo``: per neighbour its depth map at this resolution (0 = no depth there; None = no map), for the
        geometric term."""
        self.h, self.w = h, w = ref_gray.shape
        self.K = K_r
        self.Kinv = np.linalg.inv(K_r)
        r = opt.window // 2
        oy, ox = np.mgrid[-r:r + 1, -r:r + 1]
        keep = ((ox + oy) % 2 == 0) if opt.sparse_window else np.ones(ox.shape, bool)  # checkerboard: half the samples
        ox = (ox[keep] * opt.dilation).astype(np.float32)
        oy = (oy[keep] * opt.dilation).astype(np.float32)
        self.S = len(ox)
        v, u = np.mgrid[0:h, 0:w].astype(np.float32)
        u, v = u.ravel(), v.ravel()
        self.qx = u[None, :] + ox[:, None]  # (S, P) window sample coordinates in the reference
        self.qy = v[None, :] + oy[:, None]
        # reference samples (clamped at the border: a window that leaves the photo repeats its edge)
        ref = _remap(np.ascontiguousarray(ref_gray, np.float32), self.qx, self.qy, h, w, border=True)
        ref = ref - ref.mean(0, keepdims=True)
        var = (ref * ref).mean(0)
        self.textured = var > opt.min_texture
        self.ref_hat = (ref / np.sqrt((ref * ref).sum(0, keepdims=True) + 1e-12)).astype(np.float32)
        self.rays = (np.stack([u, v, np.ones_like(u)], 1) @ self.Kinv.T).astype(np.float32)  # (P, 3), z = 1
        self.nb = []
        for gray_n, K_n, R_nr, t_nr in nbrs:
            H0 = (K_n @ R_nr @ self.Kinv).astype(np.float32)
            a = (K_n @ t_nr).astype(np.float32)
            base = [H0[i, 0] * self.qx + H0[i, 1] * self.qy + H0[i, 2] for i in range(3)]
            self.nb.append((np.ascontiguousarray(gray_n, np.float32), base, a))
        self.geo = None
        if geo is not None:
            # a neighbour without a map (None) is judged by the photos alone
            self.geo = [None if D is None else (np.ascontiguousarray(D, np.float32), np.asarray(K_n, np.float32),
                                                np.asarray(R_nr, np.float32), np.asarray(t_nr, np.float32))
                        for D, (_g, K_n, R_nr, t_nr) in zip(geo, nbrs)]
            self.pix = np.stack([u, v], 1)
            self.geom_weight, self.geom_max = float(opt.geom_weight), float(opt.geom_max_px)
        self.Kinv32 = self.Kinv.astype(np.float32)

    def depth(self, n, c):
        """Depth along each pixel's ray where it meets its plane (n . X = c)."""
        den = (self.rays * n).sum(1)
        den = np.where(np.abs(den) > 1e-9, den, 1e-9)
        return c / den

    def cost(self, n, c, top_k: int):
        """Aggregated cost (P,) of the planes (n (P, 3), c (P,)), 2 where too few neighbours see the window."""
        b = (n @ self.Kinv32) / c[:, None]  # K^-T n / c as a row: H q = H_0 q + (K_n t) (b . q)
        s = b[:, 0] * self.qx + b[:, 1] * self.qy + b[:, 2]  # (S, P)
        costs = np.empty((len(self.nb), s.shape[1]), np.float32)
        for j, (gray_n, base, a) in enumerate(self.nb):
            z = base[2] + a[2] * s
            iz = np.where(z > 1e-6, 1.0 / np.maximum(z, 1e-6), -1e6).astype(np.float32)  # behind: far outside
            x = (base[0] + a[0] * s) * iz
            y = (base[1] + a[1] * s) * iz
            smp = _remap(gray_n, x, y, self.h, self.w, border=False)  # -1 outside
            full = smp.min(0) >= 0
            s1 = smp.sum(0)
            var = (smp * smp).sum(0) - s1 * s1 / self.S
            num = (self.ref_hat * smp).sum(0)  # ref_hat is zero-mean: the neighbour's mean drops out
            ncc = num / np.sqrt(np.maximum(var, 1e-12))
            costs[j] = np.where(full & (var > self.S * 1e-5), 1.0 - ncc, 2.0)
            if self.geo is not None and self.geo[j] is not None:
                costs[j] = np.where(costs[j] < 2.0, costs[j] + self.geom_weight * self._fb_error(j, n, c), 2.0)
        k = min(top_k, len(costs))
        if k < len(costs):
            costs = np.partition(costs, k - 1, axis=0)[:k]
        out = costs.mean(0)
        return np.where(self.textured, out, 2.0).astype(np.float32)

    def _fb_error(self, j, n, c):
        """Forward-backward reprojection error (px, at most geom_max) of each pixel's plane against neighbour j's
        depth map: the pixel goes out at its plane's depth, comes back at the depth the neighbour saw there
        (Schönberger et al. 2016's geometric consistency). geom_max where the neighbour has no depth there."""
        D, K_n, R_nr, t_nr = self.geo[j]
        hn, wn = D.shape
        X = self.rays * self.depth(n, c)[:, None]
        Xn = X @ R_nr.T + t_nr
        z = Xn[:, 2]
        zs = np.where(z > 1e-6, z, 1e-6)
        un = K_n[0, 0] * Xn[:, 0] / zs + K_n[0, 2]
        vn = K_n[1, 1] * Xn[:, 1] / zs + K_n[1, 2]
        iu, iv = np.rint(un).astype(np.int64), np.rint(vn).astype(np.int64)
        ok = (z > 1e-6) & (iu >= 0) & (iu < wn) & (iv >= 0) & (iv < hn)
        dn = np.zeros(len(z), np.float32)
        dn[ok] = D[iv[ok], iu[ok]]
        ok &= dn > 0
        back = np.stack([(un - K_n[0, 2]) / K_n[0, 0], (vn - K_n[1, 2]) / K_n[1, 1], np.ones_like(un)], 1) * dn[:, None]
        Xr = (back - t_nr) @ R_nr  # R_nr^T (X_n - t)
        zr = np.where(Xr[:, 2] > 1e-6, Xr[:, 2], 1e-6)
        ur = self.K[0, 0] * Xr[:, 0] / zr + self.K[0, 2]
        vr = self.K[1, 1] * Xr[:, 1] / zr + self.K[1, 2]
        err = np.hypot(ur - self.pix[:, 0], vr - self.pix[:, 1])
        return np.where(ok & (Xr[:, 2] > 1e-6), np.minimum(err, self.geom_max), self.geom_max).astype(np.float32)


def _remap(img, x, y, h, w, border: bool):
    """Bilinear samples of img at float pixel coordinates x, y shaped (S, h*w); -1 outside unless border."""
    import cv2

    S = x.shape[0]
    mx = x.reshape(S * h, w)
    my = y.reshape(S * h, w)
    out = cv2.remap(img, mx, my, cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE if border else cv2.BORDER_CONSTANT, borderValue=-1.0)
    return out.reshape(S, h * w)


def _random_normals(P, rays, rng):
    n = rng.standard_normal((P, 3)).astype(np.float32)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    view = -rays / np.linalg.norm(rays, axis=1, keepdims=True)
    dot = (n * view).sum(1, keepdims=True)
    n = np.where(dot < 0, -n, n)  # face the camera
    dot = np.abs(dot)
    n = np.where(dot < 0.17, n + 0.5 * view, n)  # not too grazing
    return (n / np.linalg.norm(n, axis=1, keepdims=True)).astype(np.float32)


def _random_planes(P, rays, inv_lo, inv_hi, rng):
    """Random planes: depth uniform in inverse depth, a normal within about 80 degrees of facing the camera."""
    idep = (inv_hi + (inv_lo - inv_hi) * rng.random(P)).astype(np.float32)
    n = _random_normals(P, rays, rng)
    X = rays / idep[:, None]
    return n, (n * X).sum(1).astype(np.float32)


def _perturb(n, c, rays, depth, scale: float, inv_lo, inv_hi, rng, move_depth=True, move_normal=True):
    """The planes moved a little: inverse depth by up to +-scale of itself, the normal by about scale radians."""
    P = len(c)
    idep = 1.0 / np.maximum(depth, 1e-6)
    if move_depth:
        idep = np.clip(idep * (1.0 + (rng.random(P) - 0.5) * 2 * scale), inv_hi, inv_lo)
    n2 = n
    if move_normal:
        n2 = n + (scale * rng.standard_normal((P, 3))).astype(np.float32)
        view = -rays / np.linalg.norm(rays, axis=1, keepdims=True)
        n2 = np.where((n2 * view).sum(1, keepdims=True) < 0.05, n, n2)
        n2 = n2 / np.linalg.norm(n2, axis=1, keepdims=True)
    X = rays / idep[:, None].astype(np.float32)
    return n2.astype(np.float32), (n2 * X).sum(1).astype(np.float32)


def _neighbour_best(cost, field, h, w):
    """Per pixel and direction (right, left, down, up): the field (P, 4) of the cheapest pixel among those
    1, 3 and 9 pixels away in that direction (itself where none is cheaper)."""
    C = cost.reshape(h, w)
    F_ = field.reshape(h, w, -1)
    out = []
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        best_c = np.full((h, w), 9.0, np.float32)
        best_f = F_.copy()
        for d in (1, 3, 9):
            sy, sx = dy * d, dx * d
            if abs(sy) >= h or abs(sx) >= w:
                continue
            cs = np.full((h, w), 9.0, np.float32)
            fs = np.zeros_like(F_)
            ys = slice(max(0, -sy), h - max(0, sy))
            yd = slice(max(0, sy), h - max(0, -sy))
            xs = slice(max(0, -sx), w - max(0, sx))
            xd = slice(max(0, sx), w - max(0, -sx))
            cs[ys, xs] = C[yd, xd]  # the pixel (y + sy, x + sx)
            fs[ys, xs] = F_[yd, xd]
            better = cs < best_c
            best_c = np.where(better, cs, best_c)
            best_f = np.where(better[..., None], fs, best_f)
        out.append(best_f.reshape(field.shape))
    return out


def _run_level(L: _Level, n, c, cost, iters: int, opt: PMOptions, inv_lo, inv_hi, rng, first_scale: float,
               random: bool):
    P = L.h * L.w
    scale = first_scale
    dnear, dfar = 1.0 / inv_lo, 1.0 / inv_hi
    for _it in range(iters):
        field = np.concatenate([n, c[:, None]], 1)
        cands = _neighbour_best(cost, field, L.h, L.w)
        depth = L.depth(n, c)
        if random:  # a fresh plane, and the plane perturbed
            n_r, c_r = _random_planes(P, L.rays, inv_lo, inv_hi, rng)
            cands.append(np.concatenate([n_r, c_r[:, None]], 1))
            n_p, c_p = _perturb(n, c, L.rays, depth, scale, inv_lo, inv_hi, rng)
            cands.append(np.concatenate([n_p, c_p[:, None]], 1))
        else:  # refinement: depth and normal perturbed separately
            for md, mn in ((True, False), (False, True)):
                n_p, c_p = _perturb(n, c, L.rays, depth, scale, inv_lo, inv_hi, rng, md, mn)
                cands.append(np.concatenate([n_p, c_p[:, None]], 1))
        for f in cands:
            n, c, cost = _keep_better(L, n, c, cost, f[:, :3], f[:, 3], opt.top_k, dnear, dfar)
        scale *= 0.5
    return n, c, cost


def _keep_better(L: _Level, n, c, cost, n_try, c_try, top_k: int, dnear: float, dfar: float):
    """Per pixel, the tried plane where it costs less than the current one and its depth is in range."""
    d = L.depth(n_try, c_try)
    cst = L.cost(n_try, c_try, top_k)
    better = (cst < cost) & (d > dnear) & (d < dfar)
    return (np.where(better[:, None], n_try, n), np.where(better, c_try, c), np.where(better, cst, cost))


def patchmatch(ref_gray, K_r, nbrs, dmin: float, dmax: float, opt: PMOptions, planes=(), init=None, geo=None):
    """Depth (h, w; 0 = none), normals (h, w, 3, reference camera frame, facing it) and NCC (h, w) of the
    reference photo. ``nbrs``: (gray, K, R_nr, t_nr) per neighbour, X_n = R_nr X_r + t_nr. ``planes``: (n, c)
    planes of the scene known beforehand (the ground under the camera), tried at every pixel after the random
    start; a random normal is never as grazing as the street seen far ahead from eye height.

    The geometric pass (``init`` and ``geo`` given): ``init`` = (normals (h, w, 3), offsets (h, w)) of this photo's
    photometric pass, ``geo`` the neighbours' depth maps (same order as ``nbrs``, the working resolution); the
    planes are refined at the working resolution with the cost plus ``geom_weight`` times the forward-backward
    reprojection error against those maps, so each map settles on the depth its neighbours agree with where
    the photos alone leave it ambiguous. A depth is kept where the plane's photometric NCC alone reaches
    ``min_ncc``. The planes (n, c) come back as the fourth value of either pass."""
    import cv2

    cv2.setNumThreads(max(1, int(opt.threads)))
    rng = np.random.default_rng(int(opt.seed))
    inv_lo, inv_hi = 1.0 / dmin, 1.0 / dmax  # inverse depth: near (large) .. far (small)
    h, w = ref_gray.shape
    if init is not None:
        Lf = _Level(ref_gray, K_r, nbrs, opt, geo=geo)
        n = np.ascontiguousarray(np.asarray(init[0], np.float32).reshape(-1, 3))
        c = np.ascontiguousarray(np.asarray(init[1], np.float32).reshape(-1))
        cost = Lf.cost(n, c, opt.top_k)
        n, c, cost = _run_level(Lf, n, c, cost, opt.iters_fine, opt, inv_lo, inv_hi, rng, 0.06, False)
        Lf.geo = None  # the acceptance test is photometric
        return _finish(Lf, n, c, Lf.cost(n, c, opt.top_k), dmin, dmax, opt, h, w)
    f = 0.5
    hs, ws = int(round(h * f)), int(round(w * f))

    from .dense import scaled_view

    def _half(gray, K):
        return scaled_view(gray, K, f)

    # coarse: half resolution, random planes to start
    g_r, Kc = _half(ref_gray, K_r)
    Lc = _Level(g_r, Kc, [(*_half(g, K), R, t) for g, K, R, t in nbrs], opt)
    n, c = _random_planes(hs * ws, Lc.rays, inv_lo, inv_hi, rng)
    cost = Lc.cost(n, c, opt.top_k)
    for pn, pc in planes:  # known planes, where they match better
        n, c, cost = _keep_better(Lc, n, c, cost, np.broadcast_to(np.asarray(pn, np.float32), n.shape).copy(),
                                  np.full(len(c), pc, np.float32), opt.top_k, dmin, dmax)
    n, c, cost = _run_level(Lc, n, c, cost, opt.iters_coarse, opt, inv_lo, inv_hi, rng, 0.5, True)
    del Lc
    # fine: the planes carry over as they are (nearest upsampling)
    Lf = _Level(ref_gray, K_r, nbrs, opt)
    iy = np.clip(np.round((np.arange(h) + 0.5) * f - 0.5).astype(int), 0, hs - 1)
    ix = np.clip(np.round((np.arange(w) + 0.5) * f - 0.5).astype(int), 0, ws - 1)
    idx = (iy[:, None] * ws + ix[None, :]).ravel()
    n, c = n[idx], c[idx]
    cost = Lf.cost(n, c, opt.top_k)
    n, c, cost = _run_level(Lf, n, c, cost, opt.iters_fine, opt, inv_lo, inv_hi, rng, 0.06, False)
    return _finish(Lf, n, c, cost, dmin, dmax, opt, h, w)


def _finish(Lf, n, c, cost, dmin, dmax, opt: PMOptions, h, w):
    depth = Lf.depth(n, c)
    ok = (cost <= 1.0 - opt.min_ncc) & (depth > dmin) & (depth < dmax)
    depth = np.where(ok, depth, 0.0)
    return (depth.reshape(h, w).astype(np.float32), n.reshape(h, w, 3).astype(np.float32),
            (1.0 - cost).reshape(h, w).astype(np.float32), (n.reshape(h, w, 3), c.reshape(h, w)))

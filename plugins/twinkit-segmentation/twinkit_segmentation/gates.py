"""Gates of the geometric cues by what the capture resolves at each vertex (docs/segmentation.md
"Cue gates").

A cue reads shapes off the mesh; the mesh only shows a shape where the scan sampled it densely and
cleanly enough. Per mesh vertex, from the cloud (points.ply):

- ``support_m``: the distance from the vertex to the nearest point, averaged over the vertices of a
  ``cell_m`` grid cell (a mesh interpolated across a scan-line gap of g is on average g/4 from the
  points; a surface sampled at spacing s, s/2 or less);
- ``noise_m``: the scatter of the cloud about a plane, sqrt of the smallest eigenvalue of the
  covariance of the vertex's ``k`` nearest points, median over the up-facing vertices of a
  ``noise_cell_m`` cell (the sensor's noise at that range; the curb's own step or a wall's base is
  a small share of such a cell); unmeasured where the k points lie along one scan line (their
  middle spread under ``spread`` of their radius);
- ``flat_share``: the share of the up-facing vertices of a ``cell_m`` cell where the scatter is
  measured (the ground is sampled both ways): a spinning sensor's rings, far apart on the road,
  resolve no step across them.

The gates (each a mechanism, thresholds from the cue's own lengths):

- ``curb``: a step of ``min_curb_m`` stands out of the noise at 3 sigma (``3 * noise <= min_curb_m``)
  and the ground around it is sampled both ways (``flat_share >= 0.5``). (A support test,
  ``support <= step_radius_m / 4``, changed nothing on the real sweeps and is not applied.) The gate acts
  on the step cells (a curb found where the scan resolves one), not on the band beside them, which may lie
  in a parked car's scan shadow;
- ``column`` and ``mounted``: the scan samples finer than a post is wide (spacing <= ``column_width_m``,
  i.e. ``support <= column_width_m / 2``, support being about half the spacing): where it samples
  coarser, any sparse facade breaks into fragments as narrow as a post and a thin slice says nothing
  (backproject also keeps both off on a capture whose ground is sampled in rings, not patches:
  ``furniture_min_two_way_share``);
- ``low``, ``narrow`` and ``slender``: an object's top and width are measured where its surface is
  sampled at spacing ``slice_m`` or finer (``support <= slice_m / 2``); ``low`` also needs the
  capture to reach twice ``low_top_m`` up within 10 m (:func:`reach_gate`): a top under 2.5 m is the
  object's own only where the scan saw higher things around it.

``support_m`` is pooled over ``support_cell_m`` (about a post's reach), the flat share over
``cell_m``; ``capture_quality`` costs one k-nearest query of the mesh's vertices in the cloud.

``ground``, ``raised`` and ``high`` read heights only and are never gated.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twinkit.ranges import param
from twinkit.surface.density import TWO_WAY_SPREAD

GATED = ("curb", "column", "mounted", "low", "narrow", "slender")
#: the cues that favour pole, light and sign, gated by the 3D classifier's word (:func:`geometry_gate`)
FURNITURE_CUES = ("column", "mounted")


@dataclass
class GateOptions:
    k: int = param(16, ge=4, help="Points per vertex for the local noise (plane fit).")
    spread: float = param(TWO_WAY_SPREAD, gt=0,
                          help="The k points measure a plane when their second spread (sqrt of the middle "
                               "eigenvalue) is at least this share of their radius (a uniform disc: 0.5; one scan "
                               "line: ~0); else the noise there is unmeasured (inf).")
    cell_m: float = param(2.0, gt=0, help="Grid cell (m) over which the flat share is pooled.")
    support_cell_m: float = param(0.5, gt=0,
                                  help="Grid cell (m) over which the support (nearest point distance) is pooled: "
                                       "finer than a car, about a post's reach.")
    noise_cell_m: float = param(10.0, gt=0,
                                help="Grid cell (m) over which the noise is pooled (median): the sensor's noise "
                                     "varies with range, not from one curb or wall base to the next.")


def capture_quality(points: np.ndarray, vertices: np.ndarray, up: np.ndarray | None = None,
                    opt: GateOptions | None = None, threads: int = 1) -> dict:
    """Per vertex (n,) float64, pooled over the vertex's ``cell_m`` grid cell (site frame, metres):
    ``support_m`` (mean distance of the cell's vertices to their nearest point), ``noise_m`` (the median
    plane-fit scatter of the up-facing vertices where it is measured, over a ``noise_cell_m`` cell: the
    sensor's noise, not the structure beside it; inf where none is), ``flat_share`` (share of the
    cell's up-facing vertices whose k points spread both ways). ``points`` (m, 3), ``vertices`` (n, 3);
    ``up`` (n,) bool up-facing (default all)."""
    from scipy.spatial import cKDTree

    opt = opt or GateOptions()
    pts = np.asarray(points, np.float64)
    v = np.asarray(vertices, np.float64)
    k = int(min(opt.k, len(pts)))
    if k < 3 or not len(v):
        inf = np.full(len(v), np.inf)
        return {"support_m": inf, "noise_m": inf, "flat_share": np.zeros(len(v)), "point_noise_m": inf,
                "nearest_m": inf}
    d, idx = cKDTree(pts).query(v, k=k, workers=max(1, threads))
    d1, rk = d[:, 0], d[:, -1]
    scatter = np.zeros(len(v))
    for s in range(0, len(v), 50000):
        nb = pts[idx[s:s + 50000]]
        nb = nb - nb.mean(axis=1, keepdims=True)
        ev = np.sqrt(np.maximum(np.linalg.eigvalsh(np.einsum("nki,nkj->nij", nb, nb) / k), 0.0))
        # a plane's scatter is measurable where the k points spread both ways (a patch, not one scan line)
        scatter[s:s + 50000] = np.where(ev[:, 1] >= opt.spread * rk[s:s + 50000], ev[:, 0], np.inf)
    cell = np.floor(v[:, :2] / opt.cell_m).astype(np.int64)
    _, cid = np.unique(cell, axis=0, return_inverse=True)
    cid = cid.ravel()
    nc = int(cid.max()) + 1
    use = np.ones(len(v), bool) if up is None else np.asarray(up, bool)
    scell = np.floor(v[:, :2] / opt.support_cell_m).astype(np.int64)
    _, sid = np.unique(scell, axis=0, return_inverse=True)
    sid = sid.ravel()
    support = (np.bincount(sid, weights=d1) / np.maximum(np.bincount(sid), 1))[sid]
    n_up = np.bincount(cid[use], minlength=nc)
    fin = use & np.isfinite(scatter)
    flat = np.bincount(cid[fin], minlength=nc) / np.maximum(n_up, 1)
    ncell = np.floor(v[:, :2] / opt.noise_cell_m).astype(np.int64)
    _, nid = np.unique(ncell, axis=0, return_inverse=True)
    nid = nid.ravel()
    noise = _cell_quantile(nid, scatter, fin, int(nid.max()) + 1, 0.5)
    return {"support_m": support, "noise_m": noise[nid], "flat_share": flat[cid], "point_noise_m": scatter,
            "nearest_m": d1}


def _cell_quantile(cid: np.ndarray, x: np.ndarray, use: np.ndarray, nc: int, q: float) -> np.ndarray:
    """(nc,) the ``q`` quantile (nearest rank) of ``x`` over the ``use`` entries of each cell (inf where none)."""
    out = np.full(nc, np.inf)
    sel = np.nonzero(use)[0]
    if not len(sel):
        return out
    order = sel[np.lexsort((x[sel], cid[sel]))]
    c = cid[order]
    starts = np.r_[0, np.nonzero(np.diff(c))[0] + 1]
    ends = np.r_[starts[1:], len(c)]
    pick = starts + ((ends - starts - 1) * q).astype(np.int64)
    out[c[starts]] = x[order][pick]
    return out


def cue_gates(quality: dict, opt, curb_sigmas: float = 3.0, min_flat_share: float = 0.5) -> dict:
    """Per gated cue (``GATED``) an (n,) bool: the capture at the vertex resolves what the cue reads.
    ``opt``: the :class:`twinkit_segmentation.context.ContextOptions` whose lengths set the thresholds
    (module docstring); ``quality`` from :func:`capture_quality`. The ``curb`` gate says where a curb
    *step* can be measured (``geometric_context(step_gate=...)`` keeps only such steps): the band beside
    a measured step may itself lie in a scan shadow."""
    sup, noise, flat = quality["support_m"], quality["noise_m"], quality["flat_share"]
    post = sup <= opt.column_width_m / 2.0
    shape = sup <= opt.slice_m / 2.0
    step = (curb_sigmas * noise <= opt.min_curb_m) & (flat >= min_flat_share)
    return {"curb": step, "column": post, "mounted": post, "low": shape, "narrow": shape, "slender": shape}


def geometry_gate(p_geom: np.ndarray, min_share: float) -> np.ndarray:
    """(n,) bool: the 3D classifier (``p_geom`` (n, 19) votes, zero rows where it has no support) leaves
    street furniture open at the vertex (pole, light and sign together at least ``min_share`` of its
    votes), or does not speak there."""
    from twinkit.cityscapes import STREET_FURNITURE

    from .fusion import normalise

    p, speaks = normalise(p_geom)
    return ~speaks | (p[:, list(STREET_FURNITURE)].sum(axis=1) >= min_share)


def reach_gate(vertices: np.ndarray, height: np.ndarray, opt, radius_m: float = 10.0, cell_m: float = 2.0) -> np.ndarray:
    """(n,) bool: the capture reaches at least ``2 * opt.low_top_m`` above the ground within ``radius_m``
    of the vertex (the highest mesh vertex there, ``height`` (n,) above the local ground, metres), so
    an object whose top is under ``low_top_m`` ends there, not at the scan's upper edge (a spinning
    sensor looks at most a few degrees up: a facade 15 m away ends 2-3 m up in its scan)."""
    from scipy.ndimage import maximum_filter

    v = np.asarray(vertices, np.float64)
    if not len(v):
        return np.zeros(0, bool)
    c = np.floor((v[:, :2] - v[:, :2].min(axis=0)) / cell_m).astype(np.int64)
    top = np.full(tuple(c.max(axis=0) + 1), -np.inf)
    np.maximum.at(top, (c[:, 0], c[:, 1]), np.asarray(height, np.float64))
    k = max(1, int(round(radius_m / cell_m)))
    fp = np.add.outer(np.arange(-k, k + 1) ** 2, np.arange(-k, k + 1) ** 2) <= k * k
    reach = maximum_filter(top, footprint=fp, mode="constant", cval=-np.inf)[c[:, 0], c[:, 1]]
    return reach >= 2.0 * opt.low_top_m


def gate_summary(ctx_masks: dict, gates: dict) -> dict:
    """Per gated cue: vertices the cue marks, and the share of them the gate lets through."""
    out = {}
    for c, g in gates.items():
        m = ctx_masks.get(c)
        if m is None:
            continue
        n = int(m.sum())
        out[c] = {"vertices": n, "passed": int((m & g).sum()), "share_passed": round(float((m & g).sum()) / max(n, 1), 4)}
    return out

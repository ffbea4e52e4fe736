"""Fusion of the label sources by what each is worth (docs/segmentation.md "Fusion").

Per vertex, each source gives a class distribution over the 19 trainIds:

- the views (``vertex_votes.npy`` blended per segment, :func:`backproject_parts.vote_distribution`), with a
  coverage: how many views saw the vertex;
- the geometry (``geometry_votes.npy`` (n, 19) float32 from a 3D classifier, rows of zeros where it
  has no support: no point near the vertex);
- the file's classes and the geometric cues, as multiplicative priors (``context.fuse_with_context``).

The views and the geometry are combined as a weighted sum of log-probabilities,

    log p(c) = a_v * cov(n) * log p_views(c) + a_g * [support] * log p_geom(c) + const,
    cov(n) = 1 - exp(-n / n0),

with ``a_v``, ``a_g`` and ``n0`` per capture kind (``coloured``: the cloud has colours, the views
see photos-like textures; ``colourless``: grey renders of the geometry). Where a kind has a views'
reliability ``R`` (19 x 19, ``R[k, c]`` = how often a vertex the views call ``k`` is truly ``c``,
counted on generated truth), ``p_views`` is first read through it (``p_views @ R``): a grey render of
a sparse tree crown that the 2D model calls building then speaks for building *or* vegetation, as
often as each was the truth. A vertex no view saw takes
the geometry alone; a vertex the geometry does not reach keeps the views alone, with the weight 1 the
cues and the file's prior were tuned with. The weights are fitted by :func:`calibrate` (class-balanced log-loss
against generated ground truth, ``python -m twinkit_segmentation.fusion calibrate``) and shipped as
``fusion_weights.json`` with the recipe that made them.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from twinkit.cityscapes import N_CLASSES

#: the calibrated weights shipped with the plugin (written by ``calibrate``)
WEIGHTS_FILE = Path(__file__).with_name("fusion_weights.json")
KINDS = ("coloured", "colourless")
#: probability floor inside the logarithms (a class a source never voted keeps a finite cost)
EPS = 1e-3


@dataclass
class SourceWeights:
    """The weights of one capture kind: ``views`` (a_v), ``geometry`` (a_g), ``coverage_views`` (n0,
    views for 63 % of the views' weight) and ``view_reliability`` (None, or 19 rows of 19: row ``k`` the
    true classes' shares where the views said ``k``; rows sum to 1)."""
    views: float = 1.0
    geometry: float = 1.0
    coverage_views: float = 2.0
    view_reliability: list | None = None

    def views_at(self, n_views):
        """The views' exponent (as ``n_views``: a number or an array) at a vertex ``n_views`` views saw, the
        geometry speaking there too."""
        return self.views * (1.0 - np.exp(-np.asarray(n_views, np.float64) / max(self.coverage_views, 1e-6)))

    def read_views(self, pv: np.ndarray) -> np.ndarray:
        """The views' distribution (n, 19) read through ``view_reliability`` (unchanged without one)."""
        if self.view_reliability is None:
            return pv
        return pv @ np.asarray(self.view_reliability, np.float64)


@dataclass
class FusionWeights:
    """Per capture kind :class:`SourceWeights`, and how they were made (``recipe``, free-form)."""
    kinds: dict = field(default_factory=lambda: {k: SourceWeights() for k in KINDS})
    recipe: dict = field(default_factory=dict)

    def for_kind(self, kind: str) -> SourceWeights:
        return self.kinds.get(kind, self.kinds.get("coloured", SourceWeights()))

    def to_json(self) -> dict:
        return {"kinds": {k: {a: b for a, b in vars(w).items() if b is not None} for k, w in self.kinds.items()},
                "recipe": self.recipe}


def load_weights(path: Path | str | None = None) -> FusionWeights:
    """The weights of ``path`` (default: the shipped :data:`WEIGHTS_FILE`); defaults (all 1) where the
    file is missing."""
    p = Path(path) if path else WEIGHTS_FILE
    if not p.is_file():
        return FusionWeights(recipe={"note": f"{p.name} missing: uncalibrated defaults"})
    d = json.loads(p.read_text())
    kinds = {k: SourceWeights(**{a: (b if a == "view_reliability" else float(b)) for a, b in v.items()})
             for k, v in d.get("kinds", {}).items()}
    return FusionWeights(kinds=kinds or {k: SourceWeights() for k in KINDS}, recipe=d.get("recipe", {}))


def dump_weights(w: FusionWeights) -> str:
    """``w`` as JSON text, one line per row of a reliability matrix."""
    import re

    text = json.dumps(w.to_json(), indent=1)
    return re.sub(r"\[\s+([-0-9.e,\s]+?)\s+\]", lambda m: "[" + ", ".join(m.group(1).replace(",", " ").split()) + "]",
                  text)


def capture_kind(colors: np.ndarray | None) -> str:
    """``coloured`` when the cloud's colours (n, 3) uint8 vary, else ``colourless`` (absent, or one grey)."""
    if colors is None or not len(colors):
        return "colourless"
    c = np.asarray(colors)
    sample = c[:: max(1, len(c) // 20000)].astype(np.float64)
    return "coloured" if float(sample.std(axis=0).max()) > 2.0 else "colourless"


def normalise(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rows of ``p`` (n, k) scaled to sum 1, zero rows left zero; support (n,) bool: the row had mass)."""
    p = np.asarray(p, np.float64)
    tot = p.sum(axis=1)
    sup = tot > 0
    out = np.zeros_like(p)
    out[sup] = p[sup] / tot[sup, None]
    return out, sup


def source_exponents(w: SourceWeights, n_views: np.ndarray, geom_support: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(views' exponent (n,), geometry's exponent (n,)) for a vertex seen by ``n_views`` (n,) views with
    geometry support ``geom_support`` (n,) bool. Without geometry support the views keep exponent 1
    (the plain vote the cues were tuned with)."""
    a_v = np.where(geom_support, w.views_at(np.asarray(n_views, np.float64)), 1.0)
    a_g = np.where(geom_support, w.geometry, 0.0)
    return a_v, a_g


def fuse_sources(p_views: np.ndarray, n_views: np.ndarray, p_geom: np.ndarray | None,
                 w: SourceWeights) -> tuple[np.ndarray, dict]:
    """The views' (n, 19) and the geometry's (n, 19) distributions fused by :func:`source_exponents`:
    (p (n, 19) float64, rows summing to 1, zero where neither source speaks; info with the counts).
    ``n_views`` (n,): the views that saw each vertex (its vote total with one vote per view)."""
    pv, sv = normalise(p_views)
    if p_geom is None:
        return pv, {"geometry": False, "views_only": int(sv.sum()), "geometry_only": 0, "both": 0, "neither":
                    int((~sv).sum())}
    pg, sg = normalise(p_geom)
    a_v, a_g = source_exponents(w, np.where(sv, n_views, 0.0), sg)
    a_v = np.where(sv, a_v, 0.0)
    logp = a_v[:, None] * np.log(w.read_views(pv) + EPS) + a_g[:, None] * np.log(pg + EPS)
    logp -= logp.max(axis=1, keepdims=True)
    q = np.exp(logp)
    q /= q.sum(axis=1, keepdims=True)
    alone = sv & ~sg
    q[alone] = pv[alone]  # no geometry there: the views' own distribution, exactly
    neither = ~sv & ~sg
    q[neither] = 0.0
    return q, {"geometry": True, "views_only": int((sv & ~sg).sum()), "geometry_only": int((~sv & sg).sum()),
               "both": int((sv & sg).sum()), "neither": int(neither.sum())}


def disagreement(p_views: np.ndarray, p_geom: np.ndarray | None) -> np.ndarray:
    """(n,) bool: vertices where both sources speak and their argmax differs."""
    if p_geom is None:
        return np.zeros(len(p_views), bool)
    sv = np.asarray(p_views).sum(axis=1) > 0
    sg = np.asarray(p_geom).sum(axis=1) > 0
    return sv & sg & (np.asarray(p_views).argmax(axis=1) != np.asarray(p_geom).argmax(axis=1))


def confidence_summary(labels: np.ndarray, conf: np.ndarray, disagree: np.ndarray, low: float) -> dict:
    """Counts for the run's metrics: labelled vertices whose fused winner's probability is under
    ``low``, and those the views and the geometry disagree on."""
    lab = np.asarray(labels) < N_CLASSES
    lowc = lab & (np.asarray(conf) < low)
    return {"low_confidence": int(lowc.sum()), "low_confidence_share": round(float(lowc.mean()) if len(lowc) else 0.0, 4),
            "low_confidence_below": low, "sources_disagree": int(np.asarray(disagree).sum()),
            "sources_disagree_share": round(float(np.mean(disagree)) if len(disagree) else 0.0, 4)}


def confidence_picture(path: Path, vertices: np.ndarray, conf: np.ndarray, labels: np.ndarray,
                       disagree: np.ndarray, low: float, px: int = 800) -> None:
    """A top view (PNG, ``px`` on the long side) of the mesh's vertices (n, 3) site frame: grey where the
    fused label is confident, orange where its probability is under ``low``, red where the views and the
    geometry also disagree; the highest vertex per pixel wins (what a plan view shows)."""
    from PIL import Image

    v = np.asarray(vertices, np.float64)
    lo, hi = v[:, :2].min(axis=0), v[:, :2].max(axis=0)
    span = float(max((hi - lo).max(), 1e-6))
    w, h = [max(1, int(round(px * s / span))) for s in (hi - lo)]
    i = np.clip(((v[:, 0] - lo[0]) / span * px).astype(int), 0, w - 1)
    j = np.clip(((hi[1] - v[:, 1]) / span * px).astype(int), 0, h - 1)
    col = np.full((len(v), 3), 200, np.uint8)
    lowc = (np.asarray(conf) < low) & (np.asarray(labels) < N_CLASSES)
    col[lowc] = (245, 150, 30)
    col[lowc & np.asarray(disagree, bool)] = (220, 30, 30)
    col[np.asarray(labels) >= N_CLASSES] = (60, 60, 60)
    img = np.full((h, w, 3), 255, np.uint8)
    order = np.argsort(v[:, 2])  # the highest last: it is what a plan view sees
    img[j[order], i[order]] = col[order]
    Image.fromarray(img).save(path)


# ----------------------------------------------------------------------------- calibration

#: the fit's log-weights stay within +-LOG_BOUND (a coverage scale of e^12 views is "the views never count")
LOG_BOUND = 12.0
#: the calibration's losses: ``plain`` (every vertex alike) and ``balanced`` (every true class alike, as mIoU counts)
LOSSES = ("plain", "balanced")


def class_balance(gt: np.ndarray) -> np.ndarray:
    """Per vertex weights (n,) that give every true class of ``gt`` (n,) the same total, summing to 1."""
    cnt = np.bincount(gt, minlength=N_CLASSES).astype(np.float64)
    w = 1.0 / cnt[gt]
    return w / w.sum()


def _loss(theta: np.ndarray, lv: np.ndarray, nv: np.ndarray, lg: np.ndarray, sg: np.ndarray, gt: np.ndarray,
          weight: np.ndarray | None = None) -> float:
    a_v, a_g, n0 = np.exp(np.clip(theta, -LOG_BOUND, LOG_BOUND))
    cov = 1.0 - np.exp(-nv / n0)
    logit = (a_v * cov)[:, None] * lv + (a_g * sg)[:, None] * lg
    logit -= logit.max(axis=1, keepdims=True)
    lse = np.log(np.exp(logit).sum(axis=1))
    per = lse - logit[np.arange(len(gt)), gt]
    return float(np.mean(per) if weight is None else per @ weight)


def view_reliability(pv: np.ndarray, gt: np.ndarray, prior: float) -> np.ndarray:
    """``R`` (19, 19): row ``k`` the shares of the true classes over the vertices the views call ``k``
    (soft counts: each vertex counts its views' probability of ``k``), with ``prior`` vertices of the
    identity added to every row, so a class the calibration rarely saw keeps the views' word."""
    counts = np.zeros((N_CLASSES, N_CLASSES))
    np.add.at(counts.T, gt, pv)          # counts[k, c] += pv[i, k] where gt[i] == c
    counts += prior * np.eye(N_CLASSES)
    return counts / counts.sum(axis=1, keepdims=True)


def calibrate(samples: list[dict], max_vertices: int = 60000, seed: int = 0,
              reliability_prior: float | None = None, loss: str = "balanced") -> tuple[SourceWeights, dict]:
    """Fit ``views``, ``geometry`` and ``coverage_views`` of one capture kind by minimising the
    log-loss of the fused distribution against the ground truth, over vertices both sources speak on.
    ``samples``: dicts with ``p_views`` (n, 19), ``n_views`` (n,), ``p_geom`` (n, 19) and ``gt`` (n,)
    uint8 (255 ignored). ``reliability_prior`` (vertices of identity per row): also count the views'
    reliability (:func:`view_reliability`) on the same vertices, first. ``loss``: ``balanced`` (each
    true class weighs alike: :func:`class_balance`) or ``plain`` (the mean over the vertices). Returns
    (weights, fit info: vertices, log-loss before (all 1) and after, the views' weight at 10 views)."""
    from scipy.optimize import minimize

    rng = np.random.default_rng(seed)
    pvs, nv, lg, gt = [], [], [], []
    for s in samples:
        pv, sv = normalise(s["p_views"])
        pg, sg = normalise(s["p_geom"])
        g = np.asarray(s["gt"])
        ok = sv & sg & (g < N_CLASSES)
        idx = np.nonzero(ok)[0]
        if len(idx) > max_vertices // max(len(samples), 1):
            idx = rng.choice(idx, max_vertices // max(len(samples), 1), replace=False)
        pvs.append(pv[idx])
        lg.append(np.log(pg[idx] + EPS))
        nv.append(np.asarray(s["n_views"], np.float64)[idx])
        gt.append(g[idx].astype(np.int64))
    PV, LG, NV, GT = np.concatenate(pvs), np.concatenate(lg), np.concatenate(nv), np.concatenate(gt)
    R = view_reliability(PV, GT, reliability_prior) if reliability_prior is not None else None
    LV = np.log((PV if R is None else PV @ R) + EPS)
    if loss not in LOSSES:
        raise ValueError(f"calibrate: loss {loss!r}; choose from {LOSSES}")
    SG = np.ones(len(GT))
    args = (LV, NV, LG, SG, GT, class_balance(GT) if loss == "balanced" else None)
    theta0 = np.log([1.0, 1.0, 2.0])
    before = _loss(theta0, *args)
    # the coverage scale has flat stretches: started at a few views and at many, the better fit kept
    res = min((minimize(_loss, np.log([1.0, 1.0, n0]), args=args, method="Nelder-Mead",
                        options={"xatol": 1e-3, "fatol": 1e-5, "maxiter": 400}) for n0 in (2.0, 20.0, 100.0)),
              key=lambda r: r.fun)
    a_v, a_g, n0 = (float(x) for x in np.exp(np.clip(res.x, -LOG_BOUND, LOG_BOUND)))
    rel = None if R is None else [[round(float(x), 4) for x in row] for row in R]
    w = SourceWeights(views=round(a_v, 4), geometry=round(a_g, 4), coverage_views=round(n0, 4), view_reliability=rel)
    return (w, {"vertices": int(len(GT)), "loss": loss, "logloss_uncalibrated": round(before, 4),
                "logloss": round(float(res.fun), 4), "reliability_prior": reliability_prior,
                "views_weight_at_10_views": round(float(w.views_at(10.0)), 4)})


def run_sample(run: Path, geometry: str, params=None) -> dict:
    """A calibration sample from a finished run folder: its views' distribution (as backproject
    blends it), the geometry votes file named ``geometry`` (found in the run's step folders) and
    gt_labels.npy."""
    from twinkit_segmentation.params import BackprojectParams
    from twinkit_segmentation.backproject_parts import vote_distribution

    run = Path(run)

    def one(name):
        hits = sorted(run.glob(f"*/{name}"))
        if not hits:
            raise FileNotFoundError(f"{run}: no */{name}")
        return hits[-1]

    params = params or BackprojectParams()
    votes = np.load(one("vertex_votes.npy")).astype(np.float64)
    seg = np.load(one("segments.npy"))
    p, _ = vote_distribution(params, seg, votes)
    from twinkit_segmentation.metrics import _weighted_votes

    n_views = _weighted_votes(votes, params.ignore_classes).sum(axis=1)
    return {"p_views": p, "n_views": n_views, "p_geom": np.load(one(geometry)).astype(np.float64),
            "gt": np.load(one("gt_labels.npy")), "run": str(run)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="Calibrate the fusion's source weights on generated runs.")
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("calibrate", help="fit the weights of one capture kind on finished demo runs")
    c.add_argument("runs", nargs="+", help="run folders (with vertex_votes.npy, segments.npy, gt_labels.npy)")
    c.add_argument("--kind", choices=KINDS, required=True)
    c.add_argument("--geometry", default="geometry_votes.npy", help="the geometry votes' file name in the runs")
    c.add_argument("--out", default=str(WEIGHTS_FILE), help="weights file to update (its other kinds are kept)")
    c.add_argument("--note", default="", help="what the runs are (seed, size, capture), kept in the recipe")
    c.add_argument("--reliability-prior", type=float, default=None,
                   help="also count the views' reliability matrix (docs/segmentation.md \"Fusion\"), with this "
                        "many vertices of the identity per row; omitted: no matrix (the views' word as it is)")
    c.add_argument("--loss", choices=LOSSES, default="balanced",
                   help="balanced: every true class weighs alike in the log-loss, as in mIoU (default); plain: "
                        "every vertex alike, which lets the frequent classes (road, building) decide the weights")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    samples = [run_sample(Path(r), a.geometry) for r in a.runs]
    w, info = calibrate(samples, reliability_prior=a.reliability_prior, loss=a.loss)
    cur = load_weights(a.out) if Path(a.out).is_file() else FusionWeights(kinds={})
    cur.kinds[a.kind] = w
    cur.recipe[a.kind] = {"runs": [str(Path(r)) for r in a.runs], "note": a.note, "geometry": a.geometry,
                          "command": "python -m twinkit_segmentation.fusion calibrate --kind " + a.kind, **info,
                          "seconds": round(time.perf_counter() - t0, 2)}
    Path(a.out).write_text(dump_weights(cur) + "\n")
    print(json.dumps({a.kind: {k: v for k, v in vars(w).items() if k != "view_reliability"}, **info}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["FusionWeights", "SourceWeights", "calibrate", "capture_kind", "confidence_picture", "confidence_summary",
           "disagreement", "fuse_sources", "load_weights"]

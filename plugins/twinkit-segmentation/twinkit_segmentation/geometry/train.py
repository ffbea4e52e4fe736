"""Train the 3D classifier on generated captures and write the shipped model (fixed seeds: reproducible).

    python -m twinkit_segmentation.geometry.train --data DIR [--data DIR2 ...] --out STEM [--val REGEX]

Each capture is an ``.npz`` with ``xyz`` (n, 3) float (site frame, z up, metres), ``label`` (n,) uint8
trainIds (255 = none) and optionally ``intensity`` (n,). Captures whose file stem matches ``--val`` are the
validation set (scored, never fitted); the rest train. Features are cached per capture under ``--cache``.
Writes ``STEM.npz`` + ``STEM.json`` (:mod:`.model`), the JSON holding the recipe and the validation scores.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import re
import sys
import time
from pathlib import Path

import numpy as np

from twinkit.cityscapes import N_CLASSES, NAMES, TERRAIN

from .features import INTENSITY_NAMES, feature_names, point_features
from .model import GeometryModel, save_model

FEATURE_VERSION = 8


def _waves(xy: np.ndarray, rng: np.random.Generator, n: int, wavelength_m: tuple[float, float],
           std_m: float) -> np.ndarray:
    """(k,) a smooth random height field at ``xy`` (k, 2): ``n`` plane waves of random direction, phase and
    wavelength (uniform in ``wavelength_m``), scaled to a standard deviation of about ``std_m``."""
    out = np.zeros(len(xy))
    for _ in range(n):
        ang, lam, ph = rng.uniform(0, 2 * np.pi), rng.uniform(*wavelength_m), rng.uniform(0, 2 * np.pi)
        out += np.sin((xy[:, 0] * np.cos(ang) + xy[:, 1] * np.sin(ang)) * 2 * np.pi / lam + ph)
    return out * std_m * np.sqrt(2.0 / n)


def warp_ground(xyz: np.ndarray, seed: int, max_slope: float = 0.06, max_bow_m: float = 0.5,
                label: np.ndarray | None = None, max_relief_m: float = 0.06, max_rough_m: float = 0.05) -> np.ndarray:
    """``xyz`` (n, 3) with the ground made as uneven as real streets are: a shear ``z += slope . (x, y)``
    (slope up to ``max_slope`` in a random direction), a bowl or dome rising ``max_bow_m`` at most over
    40 m, a relief of street-scale waves (4-20 m: crowned carriageways, gutters, banks; standard deviation
    drawn up to ``max_relief_m``) and, in half the captures, where ``label`` (n,) says terrain, a bumpy
    surface (0.7-3 m waves, up to ``max_rough_m``): grass is bumpy on a verge and flat on a lawn, and a model
    that sees only bumpy grass calls every flat lawn pavement. Every term is a function of (x, y) alone, so vertical things stay vertical. The
    generated sites are flat at the metre scale; real ones are not: on the real Velodyne sweeps the local
    ground's opening sits 2-9 cm below a road and 12-22 cm below grass, against under 1 cm on a generated
    sweep, and grass departs 3.7 cm from its 2 m plane against 0.8 (docs/segmentation.md "3D classifier")."""
    rng = np.random.default_rng([seed, 91])
    p = np.array(xyz, np.float64, copy=True)
    ang = rng.uniform(0, 2 * np.pi)
    slope = rng.uniform(0, max_slope)
    c = p[:, :2].mean(axis=0)
    d = p[:, :2] - c
    bow = rng.uniform(-max_bow_m, max_bow_m) / 40.0 ** 2
    p[:, 2] += slope * (d[:, 0] * np.cos(ang) + d[:, 1] * np.sin(ang)) + bow * (d ** 2).sum(axis=1)
    rel = np.random.default_rng([seed, 92])
    if max_relief_m > 0:
        p[:, 2] += _waves(d, rel, 6, (4.0, 20.0), rel.uniform(0, max_relief_m))
    if max_rough_m > 0 and label is not None and rel.random() < 0.5:
        t = np.asarray(label) == TERRAIN
        if t.any():
            p[t, 2] += _waves(d[t], rel, 8, (0.7, 3.0), rel.uniform(0.01, max_rough_m))
    return p


def capture_features(path: Path, cache: Path | None, turn: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(values (m, k) float32, labels (m,) uint8) of a capture's base points (its ground warped by
    :func:`warp_ground`, seeded by the file name), from the cache when there. ``turn``: the capture is first
    turned about the vertical by an angle drawn from its file name (0-90 degrees): the generated streets run
    along the axes, the features' voxel grids are square to them, and a real street runs any way."""
    tag = ":turned" if turn else ""
    key = hashlib.sha1(f"{path.resolve()}:{path.stat().st_mtime_ns}:{FEATURE_VERSION}:{feature_names()}{tag}".encode()
                       ).hexdigest()[:16]
    cp = cache / f"{path.stem}_{key}.npz" if cache else None
    if cp is not None and cp.exists():
        with np.load(cp) as z:
            return z["values"], z["label"]
    with np.load(path) as z:
        xyz = z["xyz"]
        label = z["label"].astype(np.uint8)
        inten = z["intensity"] if "intensity" in z.files else None
    seed = int(hashlib.sha1(path.stem.encode()).hexdigest()[:8], 16)
    pts = warp_ground(xyz, seed, label=label)
    if turn:
        from .classify import turned

        pts = turned(pts, float(np.random.default_rng([seed, 93]).uniform(0.0, 90.0)))
    f = point_features(pts, inten)
    values, lab = f.values, label[f.base]
    if cp is not None:
        cp.parent.mkdir(parents=True, exist_ok=True)
        np.savez(cp, values=values, label=lab)
    return values, lab


def _drop_intensity(values: np.ndarray, rows: np.ndarray) -> None:
    names = feature_names()
    for n in INTENSITY_NAMES:
        values[rows, names.index(n)] = 0.0 if n == "has_intensity" else 0.5


def roughen(values: np.ndarray, delta: float, scales_m: tuple[float, ...]) -> None:
    """Make ``values`` (m, k) read as if the surfaces were rougher, in place: at each scale of ``scales_m`` the
    roughness ``sqrt(l3)`` times ``10 ** delta``, the scattering ``l3 / l1`` times ``10 ** (2 delta)`` (at most
    ``l2 / l1``, which stays) and the planarity what is left of ``l2 / l1``. Real facades and crowns carry
    detail under a metre that the generated ones lack (docs/segmentation.md "Rough real surfaces")."""
    names = feature_names()
    for s in scales_m:
        r, sc, pl = (names.index(f"{n}_{s:g}") for n in ("rough", "scattering", "planarity"))
        sq = np.maximum(10.0 ** values[:, r].astype(np.float64) - 1e-3, 0.0)
        values[:, r] = np.log10(sq * 10.0 ** delta + 1e-3)
        l2 = values[:, pl] + values[:, sc]
        new = np.minimum(values[:, sc] * 10.0 ** (2 * delta), l2)
        values[:, sc] = new
        values[:, pl] = l2 - new


def score(model: GeometryModel, captures: list[tuple[str, np.ndarray, np.ndarray]], only_classes=None) -> dict:
    """IoU per class (percent), mIoU over the classes present, accuracy and coarse accuracy, pooled over
    ``captures`` [(name, values, labels)], and the mIoU / coarse accuracy of each; ``only_classes`` (trainIds):
    scored on the points of these classes only (a model fitted on them, ``--classes``)."""
    from twinkit_segmentation.metrics import coarse_accuracy, scores

    preds, gts, each = [], [], {}
    for name, values, lab in captures:
        if only_classes is not None:
            mine = np.isin(lab, only_classes)
            values, lab = values[mine], lab[mine]
        pred = model.proba(values).argmax(axis=1).astype(np.uint8)
        s = scores(pred, lab)
        each[name] = {"miou": round(s["miou"], 2), "coarse_accuracy": round(coarse_accuracy(pred, lab)["coarse_accuracy"], 2)}
        preds.append(pred)
        gts.append(lab)
    pred, gt = np.concatenate(preds), np.concatenate(gts)
    s = scores(pred, gt)
    return {"miou": round(s["miou"], 2), "accuracy": round(s["accuracy"], 2),
            "coarse_accuracy": round(coarse_accuracy(pred, gt)["coarse_accuracy"], 2),
            "iou": {k: round(v["iou"], 2) for k, v in s["per_class"].items()}, "captures": each}


def check_scene_scores(model: GeometryModel, seed: int = 0, only_classes=None) -> dict:
    """The model's scores on :func:`.scene.street_capture` (``seed``): recorded in the model's JSON, so that a
    test can check that the shipped file still gives them."""
    from .scene import street_capture

    cap = street_capture(seed)
    f = point_features(cap["xyz"])
    s = score(model, [("street_capture", f.values, cap["label"][f.base])], only_classes)
    return {"seed": seed, "miou": s["miou"], "accuracy": s["accuracy"], "coarse_accuracy": s["coarse_accuracy"],
            "iou": s["iou"]}


def _draw_points(train_caps, per_class: int, rng, rough_rng, rough_shift_max: float, rough_scales_m,
                 only_classes) -> tuple[np.ndarray, np.ndarray]:
    """The training points: per capture and class (of ``only_classes`` when given) at most ``per_class`` drawn by
    ``rng``, each capture roughened first when ``rough_shift_max`` > 0 (:func:`roughen`, deltas from
    ``rough_rng``); (values (n, k) float32, labels (n,) int64)."""
    xs, ys = [], []
    for _, values, lab in train_caps:
        if rough_shift_max > 0:
            values = values.copy()
            roughen(values, float(rough_rng.uniform(0.0, rough_shift_max)), tuple(rough_scales_m))
        for c in np.unique(lab):
            if c >= N_CLASSES or (only_classes is not None and c not in only_classes):
                continue
            idx = np.flatnonzero(lab == c)
            if len(idx) > per_class:
                idx = rng.choice(idx, per_class, replace=False)
            xs.append(values[idx])
            ys.append(lab[idx])
    return np.concatenate(xs).astype(np.float32), np.concatenate(ys).astype(np.int64)


def train(train_caps, *, hidden=(128, 64), epochs=20, per_class=2500, batch=2048, lr=2e-3, weight_decay=1e-4,
          intensity_dropout=0.5, min_points=200, seed=0, rough_shift_max=0.0, rough_scales_m=(0.1, 0.25, 0.6),
          only_classes=None, log=print):
    """Fit the MLP on [(name, values, labels)]; returns (layers, mean, std, classes, recipe dict).
    ``rough_shift_max`` > 0: each capture's surfaces at ``rough_scales_m`` read rougher by a factor
    ``10 ** delta``, ``delta`` drawn per capture from U(0, rough_shift_max) (:func:`roughen`).
    ``only_classes``: trainIds; fit on the points of these classes only (a model that splits a group, such as
    the ground model of :func:`.classify.split_ground`); None = every class."""
    import torch

    torch.manual_seed(seed)
    torch.set_num_threads(1)
    rng = np.random.default_rng(seed)
    x, y = _draw_points(train_caps, per_class, rng, np.random.default_rng([seed, 7]), rough_shift_max,
                        rough_scales_m, only_classes)
    counts = np.bincount(y, minlength=N_CLASSES)
    classes = np.flatnonzero(counts >= min_points)
    keep = np.isin(y, classes)
    x, y = x[keep], y[keep]
    remap = np.full(N_CLASSES, -1, np.int64)
    remap[classes] = np.arange(len(classes))
    y = remap[y]
    drop = rng.random(len(x)) < intensity_dropout
    _drop_intensity(x, drop)
    mean = x.mean(axis=0)
    std = x.std(axis=0) + 1e-3
    xn = torch.from_numpy((x - mean) / std)
    yt = torch.from_numpy(y)
    cnt = np.bincount(y, minlength=len(classes)).astype(np.float64)
    inv = cnt ** -0.5
    w = torch.tensor(inv / (inv * cnt).sum() * cnt.sum(), dtype=torch.float32)
    dims = [x.shape[1], *hidden, len(classes)]
    mods: list = []
    for i in range(len(dims) - 1):
        mods.append(torch.nn.Linear(dims[i], dims[i + 1]))
        if i < len(dims) - 2:
            mods.append(torch.nn.ReLU())
    net = torch.nn.Sequential(*mods)
    opt = torch.optim.Adam(net.parameters(), lr=lr, weight_decay=weight_decay)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, epochs)
    lossf = torch.nn.CrossEntropyLoss(weight=w)
    gen = torch.Generator().manual_seed(seed)
    log(f"training on {len(x)} points, {len(classes)} classes: "
        + ", ".join(f"{NAMES[c]} {int(n)}" for c, n in zip(classes, cnt)))
    for ep in range(epochs):
        perm = torch.randperm(len(xn), generator=gen)
        tot = 0.0
        for a in range(0, len(perm), batch):
            b = perm[a:a + batch]
            opt.zero_grad()
            loss = lossf(net(xn[b]), yt[b])
            loss.backward()
            opt.step()
            tot += float(loss.detach()) * len(b)
        sched.step()
        if ep % 10 == 9 or ep == epochs - 1:
            log(f"epoch {ep + 1}: loss {tot / len(xn):.4f}")
    lin = [m for m in net if isinstance(m, torch.nn.Linear)]
    layers = [(m.weight.detach().numpy().T.copy(), m.bias.detach().numpy().copy()) for m in lin]
    recipe = {"hidden": list(hidden), "epochs": epochs, "per_class_per_capture": per_class, "lr": lr,
              "weight_decay": weight_decay, "intensity_dropout": intensity_dropout, "min_points": min_points,
              "seed": seed, "batch": batch, "optimizer": "Adam + cosine schedule, class weights count^-0.5",
              "training_points": int(len(x)),
              **({"only_classes": [int(c) for c in only_classes]} if only_classes is not None else {}),
              **({"rough_shift_max": rough_shift_max, "rough_scales_m": list(rough_scales_m)} if rough_shift_max > 0 else {}),
              "trained_prior": (np.sqrt(cnt) / np.sqrt(cnt).sum()).round(6).tolist()}
    return layers, mean, std, classes, recipe


#: the prior corrections ``--prior-alphas`` can try (fractions of the full log-prior ratio); the default tries
#: none: measured and not adopted (docs/segmentation.md "Real surfaces and real class shares")
PRIOR_ALPHAS = (0.0, 0.25, 0.5, 0.75, 1.0)


def prior_shift(model: GeometryModel, train_caps, trained_prior, val_caps, log=print,
                alphas: tuple = PRIOR_ALPHAS) -> dict:
    """The class-prior correction of a model trained on class-balanced samples: the log ratio of each class's
    share among all the training captures' base points (as a capture comes) to its share in what the loss saw
    (``trained_prior``, per output class: the per-class draws weighted by the class weights), times the
    alpha of ``alphas`` with the best mIoU on ``val_caps`` (0 without them; alphas (0,): no correction,
    ``model.logit_shift`` None). Balanced training lets
    rare classes (wall, fence, sign) win wherever the shape is ambiguous; on the real sweeps a facade seen
    below the sensor's upper beam is as high as a wall. Sets ``model.logit_shift``; returns the JSON record."""
    natural = np.zeros(len(model.classes))
    for _, _, lab in train_caps:
        natural += np.bincount(lab[lab < N_CLASSES], minlength=N_CLASSES)[model.classes]
    natural = np.maximum(natural, 1.0) / max(natural.sum(), 1.0)
    ratio = np.log(natural) - np.log(np.asarray(trained_prior, np.float64))
    if not any(alphas):
        model.logit_shift = None
        return {"alpha": 0.0, "logit_shift": None,
                "natural_share": {NAMES[c]: round(float(v), 5) for c, v in zip(model.classes, natural)}}
    by_alpha = {}
    for a in alphas if val_caps else (0.0,):
        model.logit_shift = (a * ratio).astype(np.float32)
        by_alpha[a] = score(model, val_caps)["miou"] if val_caps else 0.0
        log(f"prior correction alpha {a}: validation mIoU {by_alpha[a]}")
    best = max(by_alpha, key=lambda a: (by_alpha[a], -a))
    model.logit_shift = (best * ratio).astype(np.float32)
    return {"alpha": best, "logit_shift": [round(float(v), 5) for v in model.logit_shift],
            "natural_share": {NAMES[c]: round(float(v), 5) for c, v in zip(model.classes, natural)},
            "validation_miou_by_alpha": {str(a): m for a, m in by_alpha.items()}}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m twinkit_segmentation.geometry.train", description=__doc__.split("\n")[0])
    ap.add_argument("--data", action="append", required=True, help="folder of capture .npz files (repeatable)")
    ap.add_argument("--out", required=True, help="output stem (STEM.npz, STEM.json)")
    ap.add_argument("--val", default=r"(^|_)(val|seed2\d|seed013[5-9]|seed014\d)", help="regex on the file stem: validation captures")
    ap.add_argument("--cache", default=None, help="feature cache folder")
    ap.add_argument("--epochs", type=int, default=20)
    ap.add_argument("--batch", type=int, default=2048)
    ap.add_argument("--hidden", default="128,64")
    ap.add_argument("--per-class", type=int, default=2500)
    ap.add_argument("--intensity-dropout", type=float, default=0.5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--prior-alphas", default="0",
                    help="comma-separated class-prior corrections to try (fractions of the log ratio of the classes' "
                         "natural to trained shares, e.g. 0,0.25,0.5,0.75,1); the best on the validation captures is "
                         "kept. Default 0: none (train.prior_shift)")
    ap.add_argument("--turn", action="store_true",
                    help="turn each capture about the vertical by an angle drawn from its name before its features "
                         "(the generated streets run along the axes; capture_features)")
    ap.add_argument("--rough-shift", type=float, default=0.0,
                    help="each training capture's surfaces read rougher by 10**delta, delta ~ U(0, this) per capture "
                         "(log10 units; 0 = off; train.roughen)")
    ap.add_argument("--rough-scales", default="0.1,0.25,0.6", help="the shape scales --rough-shift roughens")
    ap.add_argument("--classes", default="",
                    help="comma-separated trainIds: fit and score on the points of these classes only (e.g. 0,1,9 "
                         "for the ground model that splits the ground between road, sidewalk and terrain); "
                         "empty = every class")
    ap.add_argument("--ablate", default="", help="comma-separated feature names held at 0 in training and "
                                                   "validation (an ablation: the model cannot use them)")
    a = ap.parse_args(argv)
    files = [p for d in a.data for p in sorted(Path(d).rglob("*.npz"))]  # in --data order: the draws depend on it
    if not files:
        print(f"no .npz captures under {a.data}", file=sys.stderr)
        return 2
    cache = Path(a.cache) if a.cache else None
    val_re = re.compile(a.val)
    tr: list[tuple[str, np.ndarray, np.ndarray]] = []
    va: list[tuple[str, np.ndarray, np.ndarray]] = []
    t0 = time.perf_counter()
    for f in files:
        values, lab = capture_features(f, cache, turn=a.turn)
        for name in filter(None, a.ablate.split(",")):
            values[:, feature_names().index(name)] = 0.0
        name = f"{f.parent.name}/{f.stem}"
        (va if val_re.search(f.stem) else tr).append((name, values, lab))
        print(f"features {name}: {len(lab)} base points ({time.perf_counter() - t0:.0f} s)", flush=True)
    if not tr:
        print("no training capture (every file matched --val)", file=sys.stderr)
        return 2
    layers, mean, std, classes, recipe = train(tr, hidden=tuple(int(h) for h in a.hidden.split(",")),
                                               epochs=a.epochs, per_class=a.per_class, batch=a.batch,
                                               intensity_dropout=a.intensity_dropout, seed=a.seed,
                                               rough_shift_max=a.rough_shift,
                                               only_classes=[int(c) for c in a.classes.split(",")] if a.classes else None,
                                               rough_scales_m=tuple(float(x) for x in a.rough_scales.split(",")))
    for name in filter(None, a.ablate.split(",")):  # the model ignores an ablated feature whatever a capture gives
        i = feature_names().index(name)
        layers[0][0][i, :] = 0.0
        mean[i], std[i] = 0.0, 1.0
    model = GeometryModel(layers=layers, mean=mean, std=std, classes=classes, feature_names=feature_names())
    only = recipe.get("only_classes")
    prior = prior_shift(model, tr, recipe.pop("trained_prior"), va,
                        alphas=tuple(float(x) for x in a.prior_alphas.split(",")))
    meta = {"recipe": {**recipe, "train_captures": [n for n, _, _ in tr], "val_regex": a.val, "ablated": a.ablate,
                       "turned": bool(a.turn),
                       "feature_version": FEATURE_VERSION}, "prior": prior,
            "validation": score(model, va, only) if va else {}, "training": score(model, tr, only),
            "check_scene": check_scene_scores(model, only_classes=only)}
    npz, js = save_model(Path(a.out), layers, mean, std, classes, feature_names(), meta)
    print(json.dumps({"validation": {k: v for k, v in meta["validation"].items() if k != "captures"}}, indent=1))
    print(f"wrote {npz} ({npz.stat().st_size} B), {js}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

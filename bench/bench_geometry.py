"""Retrain the 3D classifier and its ground model from generated captures and re-score them (issue 44;
docs/segmentation.md "3D classifier", "A ground model").

    python bench/bench_geometry.py [--data DIR] [--skip-data]
    python bench/bench_geometry.py --score-only [--turns 1,2,4,6] [--ground 0,0.995]   # the shipped models on the real scans only

1. Makes the training captures where ``DIR`` lacks them (the shipped recipe: scansim's captures of the
   ``large`` demo site, seeds 100-139 training and 140-147 validation, spinning sweeps in three variants with
   rough surfaces and tall hedges (``--surfaces --tall-hedges``), the other three kinds in one; the same again
   with intensities from each surface's material (``--materials``) for the ground model; the demo-made mobile
   scans and sweeps of ``bench/geometry_data.py``). On 2 cores the first time about 10-12 minutes of captures
   and 20 minutes of features (cached under ``DIR/cache``) per set of 328 captures, then about 6 minutes of
   training for the main model and 1.5 for the ground model; a later run reuses the captures and features
   (each generator skips what it already wrote).
2. Trains with the shipped models' recipes (their JSON) into ``bench/results/geometry_model.{npz,json}`` and
   ``bench/results/ground_model.{npz,json}`` (road, sidewalk and terrain only, ``--classes``).
3. Says whether the retrained arrays equal the shipped ones, and scores both pairs on the generated validation
   captures (from the training JSON) and on the real hand-labelled scans in ``../shared/data/labelled/``
   (point level: each point's class from the classifier, no mesh; the labels are never trained on), with
   one pass and with the step's default turned passes (``classify_cloud(turns=...)``), each without and with
   the ground diffusion (``ground_alpha``, the step's default), with the ground model's split as the step
   makes it on a colourless capture.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results"
LABELLED = ROOT.parent / "shared" / "data" / "labelled" / "semantickitti"
SHIPPED = ROOT / "plugins/twinkit-segmentation/twinkit_segmentation/geometry/geometry_model"
SHIPPED_GROUND = SHIPPED.with_name("ground_model")


def _run(args: list[str]) -> None:
    print("$", " ".join(args), flush=True)
    subprocess.run([sys.executable, *args], cwd=ROOT, check=True)


#: the scansim captures of the shipped model: (kinds, variants, extra flags of ``twinkit_demo_site.captures``)
CAPTURES = (("spinning", "3", ("--surfaces", "--tall-hedges")), ("tls,mobile,aerial", "1", ()))
#: the ground model's: the same with intensities from each surface's material
GROUND_CAPTURES = tuple((k, v, (*f, "--materials")) for k, v, f in CAPTURES)


def check_manifest(folder: Path) -> None:
    """Refuse a capture folder whose spinning sweeps an older recipe made (clean skins, the demo's bushes): the
    generator skips the files its manifest has, so they would be trained on as they are."""
    man = folder / "manifest.json"
    if not man.is_file():
        return
    old = [c["file"] for c in json.loads(man.read_text())["captures"] if c["kind"] == "spinning"
           and not (c.get("surfaces", c["meta"].get("foliage_m", 0) > 0) and c.get("tall_hedges"))]
    if old:
        raise SystemExit(f"{folder}: {len(old)} spinning sweeps ({old[0]} ...) were made without --surfaces "
                         "--tall-hedges (an older recipe); remove them, or give --data a new folder")


def folders(data: Path, ground: bool = False) -> list[Path]:
    """The --data folders of the main model's training (``ground``: the ground model's), in order."""
    sc = data / ("scansim_materials" if ground else "scansim")
    return [sc / "train", sc / "val", data / "demo" / "demo_mobile", data / "demo" / "velo"]


def make_data(data: Path) -> None:
    """The captures the shipped models train on, generated where missing."""
    for ground, recipe in ((False, CAPTURES), (True, GROUND_CAPTURES)):
        train, val = folders(data, ground)[:2]
        for out, seeds in ((train, "100-139"), (val, "140-147")):
            check_manifest(out)
            for kinds, variants, flags in recipe:
                _run(["-m", "twinkit_demo_site.captures", "--out", str(out), "--seeds", seeds,
                      "--kinds", kinds, "--variants", variants, "--size", "large", *flags])
    if not (data / "demo" / "velo").is_dir():
        _run(["bench/geometry_data.py", "--out", str(data / "demo")])


def score_real(model_stem: Path, turns: int = 1, ground_alpha: float = 0.0, ground_stem: Path | None = None
               ) -> list[dict]:
    """Point-level scores of one model on each labelled scan (x, y, z, intensity only go in; ``turns``
    passes turned about the vertical, the ground diffusion's ``ground_alpha`` and the ground model
    ``ground_stem``'s split with the step's weight (None: none), :func:`classify_cloud`)."""
    from plyfile import PlyData

    from twinkit_segmentation.geometry.classify import classify_cloud
    from twinkit_segmentation.geometry.model import load_model
    from twinkit_segmentation.metrics import score_points

    from twinkit_segmentation.geometry.step import ClassifyGeometryParams

    model = load_model(model_stem)
    ground = load_model(ground_stem) if ground_stem is not None else None
    weight = ClassifyGeometryParams().ground_weight
    rows = []
    for ply in sorted(LABELLED.glob("*.ply")):
        v = PlyData.read(str(ply))["vertex"]
        xyz = np.column_stack([v["x"], v["y"], v["z"]]).astype(np.float64)
        truth = np.asarray(v["cs_trainid"]).astype(np.uint8)
        lab = classify_cloud(xyz, np.asarray(v["intensity"], np.float32), model, turns=turns,
                             ground_alpha=ground_alpha, ground_model=ground, ground_weight=weight).point_labels()
        r = score_points(xyz, lab, xyz, truth, upper_bound=False)
        rows.append({"scan": ply.stem, "coarse": r["coarse_accuracy"], "acc": r["accuracy"], "miou": r["miou"],
                     **{c: r["per_class"].get(c, {}).get("iou", float("nan"))
                        for c in ("road", "sidewalk", "building", "vegetation", "terrain", "car", "pole")}})
    return rows


def table(rows: list[dict], title: str) -> str:
    cols = ["coarse", "acc", "miou", "road", "sidewalk", "building", "vegetation", "terrain", "car", "pole"]
    out = [f"\n{title}\n", "| scan | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for r in rows:
        out.append(f"| {r['scan']} | " + " | ".join(f"{r[c]:.1f}" for c in cols) + " |")
    if rows:
        out.append("| mean | " + " | ".join(f"{np.nanmean([r[c] for r in rows]):.1f}" for c in cols) + " |")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=str(RESULTS / "geometry_data"), help="folder of the generated captures")
    ap.add_argument("--skip-data", action="store_true", help="use --data as it is (scansim/{train,val}, "
                                                             "scansim_materials/{train,val}, demo/{demo_mobile,velo} "
                                                             "under it), generate nothing")
    ap.add_argument("--score-only", action="store_true", help="score the shipped models on the real scans, train "
                                                               "nothing")
    ap.add_argument("--turns", default="1,4", help="turned passes to score with (comma-separated)")
    ap.add_argument("--ground", default=None, help="ground diffusion alphas to score with (comma-separated; "
                                                   "default: 0 and the classify_geometry step's default)")
    a = ap.parse_args(argv)
    turns = [int(t) for t in a.turns.split(",")]
    if a.ground is None:
        from twinkit_segmentation.geometry.step import ClassifyGeometryParams

        grounds = [0.0, ClassifyGeometryParams().ground_alpha]
    else:
        grounds = [float(g) for g in a.ground.split(",")]
    settings = [(t, g) for t in turns for g in grounds]

    def title(name, t, g, split=True):
        return (f"{name} models, {t} pass(es), " + (f"ground diffusion {g:g}" if g else "no ground diffusion")
                + ("" if split else ", without the ground model's split") + ", on the real labelled scans (points, %)")

    def score_pair(main_stem, ground_stem, name):
        for t, g in settings:
            print(table(score_real(main_stem, t, g, ground_stem), title(name, t, g)))
        t, g = settings[-1]
        print(table(score_real(main_stem, t, g), title(name, t, g, split=False)))

    if a.score_only:
        score_pair(SHIPPED, SHIPPED_GROUND, "shipped")
        return 0
    data = Path(a.data)
    t0 = time.perf_counter()
    if not a.skip_data:
        make_data(data)
    t_data = time.perf_counter() - t0
    t1 = time.perf_counter()
    same = {}
    for shipped, ground in ((SHIPPED, False), (SHIPPED_GROUND, True)):
        recipe = json.loads(shipped.with_suffix(".json").read_text())["recipe"]
        out = RESULTS / shipped.name
        args = ["-m", "twinkit_segmentation.geometry.train", "--out", str(out), "--cache", str(data / "cache"),
                "--per-class", str(recipe["per_class_per_capture"]), "--epochs", str(recipe["epochs"]),
                "--hidden", ",".join(map(str, recipe["hidden"])), "--val", recipe["val_regex"],
                "--seed", str(recipe["seed"])]
        if recipe.get("turned"):
            args.append("--turn")
        if recipe.get("only_classes"):
            args += ["--classes", ",".join(map(str, recipe["only_classes"]))]
        for f in folders(data, ground):
            args += ["--data", str(f)]
        _run(args)
        a_new, a_old = np.load(out.with_suffix(".npz")), np.load(shipped.with_suffix(".npz"))
        same[shipped.name] = set(a_new.files) == set(a_old.files) and all(
            a_new[k].shape == a_old[k].shape and np.array_equal(a_new[k], a_old[k]) for k in a_new.files)
    t_train = time.perf_counter() - t1
    print(f"\ndata {t_data:.0f} s, training {t_train:.0f} s; retrained arrays equal the shipped ones: {same}")
    pairs = ((SHIPPED, SHIPPED_GROUND, "shipped"),
             (RESULTS / SHIPPED.name, RESULTS / SHIPPED_GROUND.name, "retrained"))
    for main_stem, ground_stem, name in pairs:
        for stem in (main_stem, ground_stem):
            val = json.loads(stem.with_suffix(".json").read_text()).get("validation", {})
            print(f"{name} {stem.name}: generated validation mIoU {val.get('miou', float('nan')):.1f}, "
                  f"coarse {val.get('coarse_accuracy', float('nan')):.1f}, per class {val.get('iou', {})}")
        if LABELLED.is_dir():
            score_pair(main_stem, ground_stem, name)
    if not LABELLED.is_dir():
        print(f"(no {LABELLED}: real scans not scored)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

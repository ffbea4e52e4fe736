"""Benchmark the image models side by side; prints Markdown tables.

    .venv/bin/python plugins/twinkit-efficientvit/bench/bench_image_models.py [--repeats 5]
    .venv/bin/python plugins/twinkit-efficientvit/bench/bench_image_models.py --agreement [--views outputs/demo/11_render_views/renders]

Table 1: seconds per 1024x512 frame (median and best over repeats of one ``predict`` call
on a batch, divided by the batch size; also process CPU seconds per frame, which other
processes on the machine disturb less) at 1 and 2 threads, batch 1 and 4, with peak memory:
"peak RSS" is the process's high-water mark (``VmHWM``: Python + torch + model + inference);
"inference peak" is how far it rose above the resident size right after loading the model.
Each configuration runs in its own subprocess so peaks do not mix.
Frames are lund_street photos cropped to 1024x512 (from ``../shared``; random pixels otherwise).

Table 2 (if the lund_street photos exist): sanity on all 29 photos at 1024x768, the
share of the bottom-centre that is road and of the top rows that is sky/building/vegetation,
and the pixel agreement of each model with ``efficientvit_b0``.

Models: ``efficientvit_b0`` (default: OpenVINO where installed), ``efficientvit_b0_onnxruntime``
(``runtime=onnxruntime``), ``efficientvit_b0_torch`` (``runtime=torch``)
and ``efficientvit_b0_plain`` (torch with ``optimize=false``, to show the effect of BatchNorm folding +
channels-last), ``deeplab_edgetpu_tflite`` if ``ai-edge-litert`` is
installed (fixed 513x513 input; a "batch" is a loop of single invokes), and
``hf_segformer`` only when ``--hf-model`` names a local folder or a reachable model id.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from twinkit import cityscapes

HERE = Path(__file__).resolve()
REPO_ROOT = HERE.parents[3]
LUND = REPO_ROOT / ".." / "shared" / "data" / "photos" / "lund_street"


def _status_kb(field: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    return 0


def _reset_peak() -> bool:
    try:
        Path("/proc/self/clear_refs").write_text("5")  # resets VmHWM to the current RSS
        return True
    except OSError:
        return False


def load_frames(n: int, size=(1024, 512), lund_size=None) -> tuple[np.ndarray, bool]:
    """``n`` frames (h, w) = size[::-1], uint8 RGB: lund photos centre-cropped/resized, or noise."""
    files = sorted(LUND.glob("*.jpg")) if LUND.is_dir() else []
    if not files:
        return np.random.default_rng(0).integers(0, 256, (n, size[1], size[0], 3), dtype=np.uint8), False
    from PIL import Image

    out = []
    for f in (files * (n // len(files) + 1))[:n]:
        im = Image.open(f).convert("RGB")
        if lund_size is not None:
            out.append(np.asarray(im.resize(lund_size, Image.BILINEAR)))
            continue
        w, h = im.size
        scale = size[0] / w
        im = im.resize((size[0], round(h * scale)), Image.BILINEAR)
        top = (im.size[1] - size[1]) // 2
        out.append(np.asarray(im.crop((0, top, size[0], top + size[1]))))
    return np.stack(out), True


def build(model: str, threads: int, batch: int, hf_model: str):
    if model.startswith("efficientvit_b0"):
        from twinkit_efficientvit.efficientvit import EfficientViTParams, build_efficientvit

        runtime = ("torch" if model.endswith(("_torch", "_plain")) else
                   "onnxruntime" if model.endswith("_onnxruntime") else "auto")
        return build_efficientvit(EfficientViTParams(threads=threads, batch_size=batch, device="cpu", runtime=runtime,
                                                     input_long_side_px=1024, optimize=not model.endswith("plain")))
    if model == "deeplab_edgetpu_tflite":
        from twinkit_efficientvit.tflite import DeepLabTFLiteParams, build_deeplab_tflite

        return build_deeplab_tflite(DeepLabTFLiteParams(threads=threads))
    if model == "hf_segformer":
        from twinkit_efficientvit.hf import HFParams, build_hf

        return build_hf(HFParams(model=hf_model, threads=threads, batch_size=batch, device="cpu"))
    raise ValueError(model)


def worker(args) -> None:
    """One configuration in this process; prints one JSON line."""
    if args.threads and args.model != "deeplab_edgetpu_tflite":  # (no torch import for the TFLite model)
        import torch

        torch.set_num_threads(args.threads)
    model = build(args.model, args.threads, args.batch, args.hf_model)
    frames, real = load_frames(args.batch)
    rss_loaded = _status_kb("VmRSS")
    reset = _reset_peak()
    model.predict(frames)  # warm-up (allocator, oneDNN primitive caches)
    times, cpu = [], []
    for _ in range(args.repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        model.predict(frames)
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    peak = _status_kb("VmHWM")
    print(json.dumps({
        "model": args.model, "threads": args.threads, "batch": args.batch,
        "s_per_frame": float(np.median(times)) / args.batch, "s_per_frame_min": min(times) / args.batch,
        "cpu_s_per_frame": float(np.median(cpu)) / args.batch,
        "peak_rss_mb": peak / 1024, "inference_peak_mb": (peak - rss_loaded) / 1024 if reset else float("nan"),
        "real_frames": real,
    }))


def sanity(models: list[str], hf_model: str) -> list[tuple]:
    frames, real = load_frames(29, lund_size=(1024, 768))
    if not real:
        return []
    preds = {}
    for name in models:
        preds[name] = build(name, 2, 4, hf_model).predict(frames)
    ref = preds.get("efficientvit_b0")
    rows = []
    for name, lab in preds.items():
        h, w = lab.shape[1:]
        road = (lab[:, int(0.85 * h):, int(0.4 * w):int(0.6 * w)] == cityscapes.ROAD).mean(axis=(1, 2))
        top = np.isin(lab[:, : int(0.05 * h)], [2, 8, 10]).mean(axis=(1, 2))
        agree = float((lab == ref).mean()) if ref is not None else float("nan")
        rows.append((name, float(road.mean()), float(road.min()), float(top.mean()), float(top.min()), agree))
    return rows


def _image_sets(views_dir: str, max_views: int) -> list[tuple[str, np.ndarray]]:
    """Reference images for the runtime agreement: lund_street (1024x768), berlin_gcp (long side 1024, as the
    model resizes it) and, with ``views_dir``, a renders/ folder's views (its index.json's kept views)."""
    from PIL import Image

    sets = []
    frames, real = load_frames(29, lund_size=(1024, 768))
    if real:
        sets.append(("lund_street photos, 1024x768", frames))
    berlin = sorted((LUND.parent / "berlin_gcp" / "images").glob("*.jpg"))
    if berlin:
        ims = [Image.open(f).convert("RGB") for f in berlin]
        ims = [im.resize((1024, round(im.size[1] * 1024 / im.size[0])), Image.BILINEAR) for im in ims]
        sets += [(f"berlin_gcp {f.name}, {im.size[0]}x{im.size[1]}", np.asarray(im)[None]) for f, im in zip(berlin, ims)]
    if views_dir:
        kept = json.loads((Path(views_dir) / "index.json").read_text())["kept"]
        kept = kept[:: max(1, len(kept) // max_views)][:max_views]
        views = np.stack([np.asarray(Image.open(Path(views_dir) / f"{v['id']}.png").convert("RGB")) for v in kept])
        sets.append((f"{len(views)} views of {views_dir}, {views.shape[2]}x{views.shape[1]}", views))
    return sets


def agreement(views_dir: str, max_views: int) -> list[tuple[str, str, int, float, int]]:
    """(runtime, image set, images, share of pixels whose label differs from torch's, worst image's count) for each
    installed runtime of the exported network (OpenVINO, ONNX Runtime)."""
    from twinkit_efficientvit import onnx_net
    from twinkit_efficientvit.efficientvit import EfficientViTParams, build_efficientvit

    kw = dict(threads=1, batch_size=1, device="cpu")
    torch_model = build_efficientvit(EfficientViTParams(runtime="torch", **kw))
    sets = _image_sets(views_dir, max_views)
    refs = [np.stack([torch_model.predict(im[None])[0] for im in images]) for _, images in sets]
    rows = []
    for backend in [b for b in onnx_net.BACKENDS if onnx_net.available(b)]:
        model = build_efficientvit(EfficientViTParams(runtime=backend, **kw))
        for (name, images), ref in zip(sets, refs):
            differ = np.stack([model.predict(im[None])[0] for im in images]) != ref
            rows.append((backend, name, len(images), float(differ.mean()), int(differ.sum(axis=(1, 2)).max())))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--batches", default="1,4")
    ap.add_argument("--models", default="efficientvit_b0,efficientvit_b0_onnxruntime,efficientvit_b0_torch,"
                                        "efficientvit_b0_plain,deeplab_edgetpu_tflite")
    ap.add_argument("--hf-model", default="", help="also benchmark hf_segformer with this model id/folder")
    ap.add_argument("--no-sanity", action="store_true")
    ap.add_argument("--agreement", action="store_true",
                    help="only the label agreement of each exported runtime (OpenVINO, ONNX Runtime) vs torch on "
                         "the reference images")
    ap.add_argument("--views", default="", help="with --agreement: also a renders/ folder's views")
    ap.add_argument("--max-views", type=int, default=400, help="with --views: at most this many, spread evenly")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--model", default="", help=argparse.SUPPRESS)
    ap.add_argument("--batch", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--threads-one", dest="threads_one", type=int, default=1, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        args.threads = args.threads_one
        worker(args)
        return 0

    if args.agreement:
        print("\n### Labels, each runtime against torch (share of pixels whose argmax differs; limit 0.1 %)\n")
        print("| runtime | images | count | pixels differing | most in one image |")
        print("|---|---|---:|---:|---:|")
        for backend, name, count, share, worst in agreement(args.views, args.max_views):
            print(f"| {backend} | {name} | {count} | {100 * share:.4f} % | {worst} |")
        return 0
    models = [m for m in args.models.split(",") if m]
    if "deeplab_edgetpu_tflite" in models:
        from twinkit_efficientvit.tflite import litert_available

        if not litert_available():
            print("(ai-edge-litert is not installed: deeplab_edgetpu_tflite skipped)", file=sys.stderr)
            models.remove("deeplab_edgetpu_tflite")
    if args.hf_model:
        models.append("hf_segformer")
    load_before = os.getloadavg()[0]
    rows = []
    for model in models:
        for threads in [int(t) for t in args.threads.split(",")]:
            for batch in [int(b) for b in args.batches.split(",")]:
                cmd = [sys.executable, str(HERE), "--worker", "--model", model, "--batch", str(batch),
                       "--threads-one", str(threads), "--repeats", str(args.repeats), "--hf-model", args.hf_model]
                res = subprocess.run(cmd, capture_output=True, text=True)
                line = next((ln for ln in res.stdout.splitlines() if ln.startswith("{")), None)
                if res.returncode or line is None:
                    print(f"{model} threads={threads} batch={batch} failed:\n{res.stderr[-2000:]}", file=sys.stderr)
                    continue
                rows.append(json.loads(line))
                print(f"  done: {model} threads={threads} batch={batch}", file=sys.stderr)

    import torch

    cpu = platform.processor() or platform.machine()
    print(f"\n### Image models, seconds per 1024x512 frame (CPU: {os.cpu_count()} cores {cpu}; torch {torch.__version__}; "
          f"median of {args.repeats}; frames: {'lund_street photos' if rows and rows[0]['real_frames'] else 'random'})\n")
    print(f"1-minute load average before / after: {load_before:.2f} / {os.getloadavg()[0]:.2f} "
          f"(well above 0 means other processes shared the cores: trust 'best' and, for 1 thread, 'CPU s / frame' (process CPU time, summed over threads) more than the median)\n")
    print("| model | input to network | threads | batch | s / frame (median) | s / frame (best) | CPU s / frame | peak RSS MB | inference peak MB |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        net_in = "513x513 (stretched)" if r["model"] == "deeplab_edgetpu_tflite" else "1024x512"
        print(f"| {r['model']} | {net_in} | {r['threads']} | {r['batch']} | {r['s_per_frame']:.3f} | "
              f"{r['s_per_frame_min']:.3f} | {r['cpu_s_per_frame']:.3f} | {r['peak_rss_mb']:.0f} | {r['inference_peak_mb']:.0f} |")
    if not args.no_sanity:
        san = sanity([m for m in models if m != "efficientvit_b0_plain"], args.hf_model)
        if san:
            print("\n### lund_street sanity (29 photos, 1024x768)\n")
            print("| model | bottom-centre road (mean / worst) | top rows sky+building+vegetation (mean / worst) | pixels equal to efficientvit_b0 |")
            print("|---|---|---|---:|")
            for name, rm, rmin, tm, tmin, agree in san:
                print(f"| {name} | {rm:.3f} / {rmin:.3f} | {tm:.3f} / {tmin:.3f} | {agree:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

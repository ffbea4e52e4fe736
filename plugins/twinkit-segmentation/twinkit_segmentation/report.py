"""twinkit-segmentation's sections of the run report: sample views next to their 2D predictions (a
contact sheet, label pictures in CityScapes colours), the segmentation metrics tables and the labels'
confidence (backproject's confidence.png: where the fused label is unsure, where the sources disagree).

Registered through ``twinkit_register_report_sections`` (plugin.py exposes the hook implementation).
"""
from __future__ import annotations

import hashlib
import os
import re
from pathlib import Path
from typing import Any

from twinkit import hookimpl

CONTACT_ROWS = 6
#: bump when the contact sheet would come out differently for the same pictures (part of its cache key)
CONTACT_VERSION = "3"


@hookimpl
def twinkit_register_report_sections(register):
    register("samples", sec_contact, title="Sample views and 2D predictions", order=600)
    register("segmetrics", sec_seg_metrics, title="Segmentation metrics", order=800)
    register("confidence", sec_confidence, title="Label confidence", order=810)


_IMG_EXT = (".png", ".jpg", ".jpeg", ".webp")


def _colourise(im, lut):
    """A label image (mode L/P/I of trainIds) in CityScapes colours; other images unchanged."""
    import numpy as np
    from PIL import Image

    if im.mode in ("L", "I", "I;16", "P"):
        a = np.asarray(im if im.mode != "P" else im.convert("L"))
        if a.max() < 256 and (np.isin(np.unique(a), list(range(19)) + [255]).all()):
            return Image.fromarray(lut[a.astype(np.int64).clip(0, 255)])
    return im.convert("RGB")


def _role(d: Path) -> int:
    """1 for a folder of predictions / labels / ground truth (by its name), 0 for one of views."""
    n = d.name.lower()
    if any(k in n for k in ("pred", "seg", "mask", "label", "gt", "truth")):
        return 1
    return 0


def _image_folders(ctx) -> tuple[dict[Path, dict[str, Path]], dict[Path, dict]]:
    """The run's picture folders below the step folders: folder -> {file stem: file}, folder -> its step."""
    dirs: dict[Path, dict[str, Path]] = {}
    owner: dict[Path, dict] = {}
    for s, f in ((s, f) for s in ctx.steps for f in s["files"]):
        if f.suffix.lower() in _IMG_EXT and f.parent != s["dir"]:
            dirs.setdefault(f.parent, {})[f.stem] = f
            owner[f.parent] = s
    return dirs, owner


def _sheet_columns(dirs: dict[Path, dict[str, Path]]) -> list[Path]:
    """The contact sheet's columns: the views folder, then the label folders sharing its stems
    (predictions first); [] when there is nothing to pair."""
    views = [d for d in dirs if _role(d) == 0]
    if not views:
        return []

    # prefer rendered views when they have predictions; else the photos
    def score(d):
        matches = sum(1 for o in dirs if o != d and _role(o) == 1 and set(dirs[o]) & set(dirs[d]))
        return (matches, "render" in d.name.lower() or "view" in d.name.lower(), len(dirs[d]))

    vdir = max(views, key=score)
    others = [d for d in dirs if d != vdir and _role(d) == 1 and set(dirs[d]) & set(dirs[vdir])]
    others.sort(key=lambda d: (0 if "pred" in d.name.lower() else 1, str(d)))
    if not others:
        return []
    return [vdir] + others


def _draw_sheet(cols: list[Path], stems: list[str], dirs: dict[Path, dict[str, Path]], owner: dict[Path, dict], lut):
    """The contact sheet (PIL RGB image): a row per stem, a column per folder, 320 px wide cells,
    label pictures in CityScapes colours (``lut``)."""
    from PIL import Image, ImageDraw

    tw = 320
    cells = []
    th = 0
    for st in stems:
        row = []
        for d in cols:
            f = dirs[d].get(st)
            if f is None:
                row.append(None)
                continue
            with Image.open(f) as im:
                im = _colourise(im, lut) if _role(d) == 1 else im.convert("RGB")
                im = im.resize((tw, max(1, round(im.height * tw / im.width))), Image.NEAREST if _role(d) else Image.BILINEAR)
            th = max(th, im.height)
            row.append(im)
        cells.append(row)
    pad, head = 6, 22
    sheet = Image.new("RGB", (len(cols) * (tw + pad) + pad, head + len(stems) * (th + pad + 16) + pad), "white")
    draw = ImageDraw.Draw(sheet)
    for j, d in enumerate(cols):
        draw.text((pad + j * (tw + pad), 5), f"{owner[d].get('folder')}/{d.name}", fill=(0, 0, 0))
    for i, row in enumerate(cells):
        y = head + i * (th + pad + 16)
        draw.text((pad, y), stems[i], fill=(60, 60, 60))
        for j, im in enumerate(row):
            if im is not None:
                sheet.paste(im, (pad + j * (tw + pad), y + 14))
    return sheet


def sec_contact(ctx) -> str:
    """Sample views next to their 2D predictions (and ground truth), paired by file stem."""
    import numpy as np

    dirs, owner = _image_folders(ctx)
    cols = _sheet_columns(dirs)
    if not cols:
        return ""
    vdir, others = cols[0], cols[1:]
    stems = sorted(set(dirs[vdir]) & set().union(*(set(dirs[o]) for o in others)))
    if len(stems) > CONTACT_ROWS:
        idx = np.linspace(0, len(stems) - 1, CONTACT_ROWS).round().astype(int)
        stems = [stems[i] for i in idx]
    parts = [f"{CONTACT_VERSION}|contact"] + [f"{d}|{st}|{ctx.file_key(dirs[d][st])}" for st in stems for d in cols
                                              if st in dirs[d]]
    cached = ctx.cache_dir / f"contact-{hashlib.sha256(chr(10).join(parts).encode()).hexdigest()[:20]}.jpg"
    cap = (f"{len(stems)} sample views ({ctx.esc(owner[vdir].get('folder'))}/{ctx.esc(vdir.name)}) with "
           + ", ".join(f"{ctx.esc(owner[o].get('folder'))}/{ctx.esc(o.name)}" for o in others))
    html_out = "<div class=\"figs\">" + ctx.figure("img/contact_sheet.jpg", cap, ctx.legend()) + "</div>"
    if cached.is_file():
        ctx.touch(cached)
        ctx.add_image(cached, "contact_sheet.jpg")
        return html_out
    sheet = _draw_sheet(cols, stems, dirs, owner, ctx.palette())
    cached.parent.mkdir(parents=True, exist_ok=True)
    tmp = cached.with_name(f".{cached.stem}.{os.getpid()}.tmp.jpg")
    sheet.save(tmp, quality=88)
    tmp.replace(cached)
    ctx.add_image(cached, "contact_sheet.jpg")
    return html_out


_SCORE_KEY = re.compile(r"(^|[_\-. ])(iou|f1)($|[_\-. ])", re.I)


def _is_score(k: Any) -> bool:
    return bool(_SCORE_KEY.search(str(k)))


def _per_class_tables(d: Any, path: str = "", parent: Any = None) -> list[tuple[str, dict, dict]]:
    """Every table of class -> {iou, f1, ...} (a dict of dicts, or a list of rows) inside a JSON document,
    as (where, the numbers next to it (mIoU, accuracy...), the table)."""
    def scalars(x):
        return {k: v for k, v in x.items() if isinstance(v, (int, float)) and not isinstance(v, bool)} \
            if isinstance(x, dict) else {}

    if isinstance(d, dict):
        vals = list(d.values())
        if vals and all(isinstance(v, dict) for v in vals) and sum(
                any(_is_score(k) for k in v) for v in vals) >= max(1, len(vals) // 2):
            return [(path, scalars(parent), d)]
        out = []
        for k, v in d.items():
            out += _per_class_tables(v, f"{path}.{k}" if path else str(k), d)
        return out
    if isinstance(d, list) and d and all(isinstance(x, dict) for x in d) and any(
            any(_is_score(k) for k in x) for x in d):
        rows = {}
        for i, x in enumerate(d):
            name = x.get("name") or x.get("class") or x.get("label") or x.get("id") or str(i)
            rows[str(name)] = {k: v for k, v in x.items() if k not in ("name", "class", "label")}
        return [(path, scalars(parent), rows)]
    return []


def sec_seg_metrics(ctx) -> str:
    """Every table of classes with IoU / F1 in the JSON files of the step folders (e.g. seg_metrics.json)."""
    parts = []
    for s, f in ctx.find("*.json"):
        if f.name == "step.json" or f.stat().st_size > 2_000_000:
            continue
        d = ctx.read_json(f)
        tables = _per_class_tables(d) if isinstance(d, (dict, list)) else []
        for where, summary, per in tables:
            cols: list[str] = []
            for v in per.values():
                for k in v:
                    if isinstance(v[k], (int, float)) and not isinstance(v[k], bool) and k not in cols:
                        cols.append(k)
            cols.sort(key=lambda k: (0 if _is_score(k) else 1))
            rows = []
            for name, v in per.items():
                label = str(name)
                if label.isdigit() and int(label) < len(ctx.CITYSCAPES):
                    label = f"{label} {ctx.CITYSCAPES[int(label)][0]}"
                col = next((c for i, (n, c) in enumerate(ctx.CITYSCAPES) if n == str(name).lower() or str(i) == str(name)),
                           None)
                sw = f"<i class=\"sw\" style=\"background:rgb{col}\"></i>" if col else ""
                rows.append([("html", sw + ctx.esc(label))] + [v.get(c, "") for c in cols])
            parent = where.rsplit(".", 1)[0] if "." in where else ""
            title = f"{s.get('folder')}/{f.name}" + (f" · {parent}" if parent else "")
            parts.append(f"<h3>{ctx.esc(title)}</h3>")
            if summary:
                parts.append(ctx.table(["", ""], [[k, v] for k, v in summary.items()], "kv"))
            parts.append(ctx.table(["class"] + cols, rows))
        md = f.with_suffix(".md")
        if tables and md.is_file():
            name = f"{s.get('folder')}/{md.name}"
            parts.append(f"<p class=\"dim\">also as text: {ctx.link(ctx.href(md), name)}</p>")
    return "".join(parts)


def sec_confidence(ctx) -> str:
    """backproject's confidence.png (a top view: grey confident, orange low-confidence, red where the views
    and the geometry also disagree) with the step's counts."""
    hit = ctx.first("confidence.png")
    if hit is None:
        return ""
    step, f = hit
    metrics = (step.get("record") or {}).get("metrics") or {}
    c = metrics.get("confidence") or {}
    fus = metrics.get("fusion") or {}
    rows = [["low-confidence vertices", f"{c.get('low_confidence', '?')} ({100 * c.get('low_confidence_share', 0):.1f} %, "
             f"probability under {c.get('low_confidence_below', '?')})"],
            ["views and geometry disagree", f"{c.get('sources_disagree', 0)} ({100 * c.get('sources_disagree_share', 0):.1f} %)"]]
    if fus.get("geometry"):
        w = fus.get("weights") or {}
        rows.append(["fusion", f"{fus.get('kind')} capture: views x {w.get('views')}, geometry x {w.get('geometry')}"])
    src = ctx.add_image(f, "label_confidence.png")
    cap = (f"{ctx.esc(step.get('folder'))}/confidence.png: top view of the labels; grey confident, orange low-"
           f"confidence, red low-confidence where the views and the geometry disagree, dark unlabelled")
    return ctx.table(["", ""], rows, "kv") + "<div class=\"figs\">" + ctx.figure(src, cap) + "</div>"

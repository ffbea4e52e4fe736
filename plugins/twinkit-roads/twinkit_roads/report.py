"""twinkit-roads' sections of the run report: the road network over the orthophoto (with its OpenDRIVE
sampler) and the alignment numbers.

Registered through ``twinkit_register_report_sections`` (plugin.py exposes the hook implementation).
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

from twinkit import hookimpl


@hookimpl
def twinkit_register_report_sections(register):
    register("roads", sec_roads, title="Road network", order=500)
    register("alignment", sec_alignment, title="Alignment", order=900)
    register("signals", sec_signals, title="Signals", order=910)
    register("road_evidence", sec_road_evidence, title="Road network as evidence for the labels", order=920)


# --------------------------------------------------------------------------- OpenDRIVE, sampled for drawing

def _sample_geometry(g: ET.Element, step: float = 0.5) -> list[tuple[float, float]]:
    import numpy as np
    x0, y0 = float(g.get("x", 0)), float(g.get("y", 0))
    hdg, length = float(g.get("hdg", 0)), float(g.get("length", 0))
    n = max(2, int(math.ceil(length / step)) + 1)
    kind = next(iter(g), None)
    tag = kind.tag if kind is not None else "line"
    ch, sh = math.cos(hdg), math.sin(hdg)
    if tag == "paramPoly3":
        c = {k: float(kind.get(k, 0)) for k in ("aU", "bU", "cU", "dU", "aV", "bV", "cV", "dV")}
        pmax = 1.0 if kind.get("pRange", "normalized") == "normalized" else length
        pts = []
        for p in np.linspace(0, pmax, n):
            u = c["aU"] + c["bU"] * p + c["cU"] * p * p + c["dU"] * p ** 3
            v = c["aV"] + c["bV"] * p + c["cV"] * p * p + c["dV"] * p ** 3
            pts.append((x0 + u * ch - v * sh, y0 + u * sh + v * ch))
        return pts
    if tag == "poly3":
        c = [float(kind.get(k, 0)) for k in ("a", "b", "c", "d")]
        return [(x0 + u * ch - (c[0] + c[1] * u + c[2] * u * u + c[3] * u ** 3) * sh,
                 y0 + u * sh + (c[0] + c[1] * u + c[2] * u * u + c[3] * u ** 3) * ch)
                for u in np.linspace(0, length, n)]
    k0 = k1 = 0.0
    if tag == "arc":
        k0 = k1 = float(kind.get("curvature", 0))
    elif tag == "spiral":
        k0, k1 = float(kind.get("curvStart", 0)), float(kind.get("curvEnd", 0))
    pts = [(x0, y0)]
    x, y, h = x0, y0, hdg
    ds = length / (n - 1)
    for i in range(n - 1):
        s_mid = (i + 0.5) * ds
        k = k0 + (k1 - k0) * s_mid / max(length, 1e-9)
        hm = h + k * ds / 2
        x, y = x + ds * math.cos(hm), y + ds * math.sin(hm)
        h += k * ds
        pts.append((x, y))
    return pts


def read_opendrive(path: Path) -> list[dict]:
    """Each road's reference line (sampled) and its paved width at s = 0 (sum of lane widths)."""
    root = ET.parse(path).getroot()
    off = root.find("header/offset")
    ox = float(off.get("x", 0)) if off is not None else 0.0
    oy = float(off.get("y", 0)) if off is not None else 0.0
    roads = []
    for road in root.iter("road"):
        pts: list[tuple[float, float]] = []
        for g in road.findall("planView/geometry"):
            seg = _sample_geometry(g)
            pts.extend(seg if not pts else seg[1:])
        widths = {"left": 0.0, "right": 0.0}
        ls = road.find("lanes/laneSection")
        if ls is not None:
            for side in widths:
                for lane in ls.findall(f"{side}/lane"):
                    w = lane.find("width")
                    if w is not None and lane.get("type", "driving") in _PAVED:
                        widths[side] += float(w.get("a", 0))
        lo = road.find("lanes/laneOffset")
        offset = float(lo.get("a", 0)) if lo is not None else 0.0
        roads.append({"id": road.get("id"), "junction": road.get("junction", "-1"),
                      "points": [(x + ox, y + oy) for x, y in pts], "width": widths["left"] + widths["right"],
                      "left": widths["left"], "right": widths["right"], "offset": offset})
    return roads


_PAVED = ("driving", "bidirectional", "parking", "shoulder", "biking", "entry", "exit", "onRamp", "offRamp")


def offset_polyline(pts: list[tuple[float, float]], d: float) -> list[tuple[float, float]]:
    """The polyline moved sideways by ``d`` metres (positive: to the left of its direction)."""
    import numpy as np
    a = np.asarray(pts, float)
    if len(a) < 2 or d == 0:
        return [tuple(p) for p in a]
    t = np.gradient(a, axis=0)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    n = np.column_stack([-t[:, 1], t[:, 0]])
    return [tuple(p) for p in a + n * d]



# --------------------------------------------------------------------------- sections

def sec_roads(ctx) -> str:
    """The road network (the latest OpenDRIVE, and the site's reference lanes) over the orthophoto; road QA pictures."""
    layers = []  # (class, list of (points, width))
    sources = []
    for s, f in ctx.find("*.xodr"):
        try:
            roads = read_opendrive(f)
        except Exception as exc:
            ctx.log.warning("twinkit: report: cannot read %s (%s)", f, exc)
            continue
        shift = _projected_shift(ctx, roads)
        items = []
        for r in roads:
            ref = [(x - shift[0], y - shift[1]) for x, y in r["points"]]
            if r["junction"] in ("-1", "", None):  # paved bands of the normal roads, each side of the lane offset
                for side, sign in (("left", 1), ("right", -1)):
                    if r[side] > 0:
                        items.append((offset_polyline(ref, r["offset"] + sign * r[side] / 2), r[side], "band"))
                items.append((ref, 0.0, "xodr"))
            else:
                items.append((ref, 0.0, "xodr junction"))
        layers.append(("xodr", items))
        sources.append(f"{s.get('folder')}/{f.name} ({len(roads)} roads)")
        break
    for s, f in ctx.find("roads_truth.json")[:1]:
        d = ctx.read_json(f) or {}
        lanes = [([tuple(p[:2]) for p in ln.get("points", [])], 0.0, "truth") for ln in d.get("lanes", [])
                 if ln.get("points")]
        if lanes:
            layers.append(("truth", lanes))
            sources.append(f"{s.get('folder')}/{f.name} ({len(lanes)} lane centre lines, reference)")
    qa = []
    for s, f in ctx.find("*road*.png") + ctx.find("*xodr*.png"):
        name = f"{s.get('folder')}_{f.name}"
        if (ctx.out / "img" / name).exists():
            continue
        ctx.add_image(f, name)
        qa.append(ctx.figure(f"img/{name}", f"Road QA: {ctx.esc(f.name)}"))
    parts = []
    frame = ctx.ortho()
    if layers and frame:
        b, (w, h) = frame["bounds"], frame["size"]
        sx, sy = w / (b[2] - b[0]), h / (b[3] - b[1])
        svg = [f"<svg class=\"roads\" viewBox=\"0 0 {w} {h}\" xmlns=\"http://www.w3.org/2000/svg\">",
               f"<image href=\"{ctx.url(frame['texture'])}\" x=\"0\" y=\"0\" width=\"{w}\" height=\"{h}\" opacity=\"0.85\"/>"]
        drawn = sorted((it for _, items in layers for it in items), key=lambda it: 0 if it[2] == "band" else 1)
        for pts, width, cls in drawn:  # bands first, lines over them
            if len(pts) < 2:
                continue
            d = " ".join(f"{(x - b[0]) * sx:.1f},{(b[3] - y) * sy:.1f}" for x, y in pts)
            sw = f" stroke-width=\"{width * sx:.1f}\"" if cls == "band" else ""
            svg.append(f"<polyline{ctx.attr('class', cls)} points=\"{d}\"{sw}/>")
        svg.append("</svg>")
        keys = "<span class=\"key xodr\">OpenDRIVE reference lines (band: paved lanes; thin: junctions)</span>" if any(
            c == "xodr" for c, _ in layers) else ""
        keys += "<span class=\"key truth\">site's reference lanes</span>" if any(c == "truth" for c, _ in layers) else ""
        parts.append(f"<figure class=\"wide\">{''.join(svg)}<figcaption>Road network over the orthophoto. "
                     f"{keys}<br><span class=\"dim\">{ctx.esc('; '.join(sources))}</span></figcaption></figure>")
    for s, f in ctx.find("scan_roads.json")[:1]:  # roads from the scan: how much of them the checks kept
        d = ctx.read_json(f) or {}
        if d.get("kept_share") is None:
            continue
        low = d["kept_share"] < (d.get("params") or {}).get("min_kept_share", 0.5)
        parts.append(f"<p class=\"{'warn' if low else 'dim'}\">Roads from the scan: {len(d.get('roads', []))} roads; "
                     f"the checks against the scan kept {100 * d['kept_share']:.0f} % of the {d.get('derived_m', 0):.0f} m "
                     "of road first derived (lanes over walls, hedges, banks or roofs are cut, moved or narrowed; "
                     f"{ctx.esc(f.name)} lane_check)"
                     + (": the map covers less of the streets than the scan shows" if low else "") + ".</p>")
    if qa:
        parts.append("<div class=\"figs\">" + "".join(qa) + "</div>")
    return "".join(parts)


def _projected_shift(ctx, roads: list[dict]) -> tuple[float, float]:
    """OpenDRIVE in projected coordinates -> site frame, using the site's base point."""
    xs = [abs(x) for r in roads for x, _ in r["points"][:1]]
    if not xs or max(xs) < 1e4:
        return (0.0, 0.0)
    hit = ctx.first("site.json")
    bp = ((ctx.read_json(hit[1]) or {}).get("base_point_projected") or {}) if hit else {}
    return (float(bp.get("x", 0)), float(bp.get("y", 0)))


def sec_alignment(ctx) -> str:
    """Every number of the alignment and road-check files, residuals first."""
    parts = []
    for s, f in (ctx.find("*align*.json") + ctx.find("*residual*.json") + ctx.find("*reprojection*.json")
                 + ctx.find("*roads_check*.json")):
        d = ctx.read_json(f)
        if not isinstance(d, dict):
            continue
        flat = [[k, v] for k, v in ctx.flatten(d).items() if isinstance(v, (int, float, str, bool)) or
                (isinstance(v, list) and len(v) <= 6 and all(isinstance(x, (int, float)) for x in v))]
        flat.sort(key=lambda r: (0 if "resid" in r[0].lower() or "rms" in r[0].lower() else 1))
        flat = [[k, f"{v:.10g}" if isinstance(v, float) else v] for k, v in flat]  # coordinates keep their digits
        parts.append(f"<h3>{ctx.esc(s.get('folder'))}/{ctx.esc(f.name)}</h3>" + ctx.table(["", ""], flat, "kv"))
    return "".join(parts)


def _step_picture(ctx, step: dict, png, caption: str) -> str:
    """A step's picture copied into the report as a figure ("" when the step wrote none)."""
    if not png.is_file():
        return ""
    name = f"{step.get('folder')}_{png.name}"
    ctx.add_image(png, name)
    return "<div class=\"figs\">" + ctx.figure(f"img/{name}", caption) + "</div>"


def sec_signals(ctx) -> str:
    """place_signals: each OpenDRIVE signal, where it came from and how far it moved; the top view."""
    parts = []
    for s, f in ctx.find("signals.json")[:1]:
        d = ctx.read_json(f)
        if not isinstance(d, dict):
            continue
        rows = [[x.get("id"), x.get("kind"), x.get("road"), x.get("defined_on_road"), x.get("source"),
                 f"{x.get('moved_m', 0):.2f}", x.get("instance") if x.get("instance") is not None else "",
                 x.get("note", "")] for x in d.get("signals", [])]
        parts.append(f"<h3>{ctx.esc(s.get('folder'))}/{ctx.esc(f.name)}</h3>" + ctx.table(
            ["signal", "kind", "controls road", "defined on road", "source", "moved m", "scanned instance", "note"],
            rows))
        parts.append(_step_picture(ctx, s, f.parent / "signals.png", "Scanned lights (orange) and signs (blue); "
                                   "netconvert's signals (red) and where they are now (green)"))
    return "".join(parts)


def sec_road_evidence(ctx) -> str:
    """road_evidence: what the lanes relabelled, where they disagree with the scan; the three-panel picture."""
    parts = []
    for s, f in ctx.find("road_evidence.json")[:1]:
        d = ctx.read_json(f)
        if not isinstance(d, dict):
            continue
        if not d.get("enabled", True):
            parts.append(f"<p>{ctx.esc(d.get('note', 'switched off'))}</p>")
            continue
        rows = [["relabelled vertices", d.get("changed_vertices")], ["relabelled m²", d.get("changed_area_m2")],
                ["transitions", ", ".join(f"{k}: {v}" for k, v in (d.get("transitions") or {}).items())],
                ["lanes' area m²", d.get("lane_area_m2")],
                ["disagreement (geometry) m²", d.get("disagreement_geometry_m2")],
                ["disagreement (all) m²", d.get("disagreement_area_m2")],
                ["driving lanes on the wrong level / not ground", d.get("network_disagreement")],
                ["network vetoed", d.get("network_vetoed")], ["lanes vetoed", len(d.get("vetoed_lanes") or [])]]
        ev = d.get("evaluation")
        if isinstance(ev, dict):
            b, a = ev.get("iou_before", {}), ev.get("iou_after", {})
            for k in ("road", "sidewalk", "terrain", "miou"):
                if k in b:
                    rows.append([f"IoU {k} before / after", f"{b[k]:.1f} / {a.get(k, 0):.1f}"])
        parts.append(f"<h3>{ctx.esc(s.get('folder'))}/{ctx.esc(f.name)}</h3>" + ctx.table(["", ""], rows, "kv"))
        parts.append(_step_picture(ctx, s, f.parent / "road_evidence.png", "Labels before and after the road "
                                   "network's vote; where lanes and scan agree, were relabelled, or disagree"))
    return "".join(parts)

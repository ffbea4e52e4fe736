"""twinkit-roads' sections of the run report: the road network over the orthophoto (its lanes as CARLA reads
them, twinkit.street.lanes) and the alignment numbers.

Registered through ``twinkit_register_report_sections`` (plugin.py exposes the hook implementation).
"""
from __future__ import annotations

from pathlib import Path

from twinkit import hookimpl


@hookimpl
def twinkit_register_report_sections(register):
    register("roads", sec_roads, title="Road network", order=500)
    register("alignment", sec_alignment, title="Alignment", order=900)
    register("signals", sec_signals, title="Signals", order=910)
    register("crosswalks", sec_crosswalks, title="Crosswalks", order=915)
    register("road_evidence", sec_road_evidence, title="Road network as evidence for the labels", order=920)


# --------------------------------------------------------------------------- OpenDRIVE, sampled for drawing

#: lane types (CARLA's names, lower case) drawn as paved bands
_PAVED = ("driving", "bidirectional", "parking", "shoulder", "biking", "entry", "exit", "onramp", "offramp")


def network_items(path: Path, step_m: float = 1.0) -> list[tuple[list[tuple[float, float]], str]]:
    """The OpenDRIVE network as drawing items (site frame, or the file's own frame): one closed ring per paved
    lane segment (class ``band``: its two borders, with the widths and lane sections CARLA reads), then one
    polyline per driving-lane centre line (``xodr``; ``xodr junction`` inside junctions)."""
    import numpy as np

    from twinkit.street.lanes import LaneMap

    lm = LaneMap.from_file(path)
    items = []
    for ln in lm.lanes(step_m).per_lane():
        if str(ln.type[0]).lower() in _PAVED and len(ln) >= 2:
            left, right = ln.borders()
            items.append(([tuple(p) for p in np.concatenate([left, right[::-1]]).tolist()], "band"))
    wp = lm.waypoints(step_m)
    for ln in wp.take(wp.is_type("driving")).per_lane():
        cls = "xodr junction" if ln.in_junction[0] else "xodr"
        items.append(([tuple(p) for p in ln.xyz[:, :2].tolist()], cls))
    return items


# --------------------------------------------------------------------------- sections

def sec_roads(ctx) -> str:
    """The road network (the latest OpenDRIVE, and the site's reference lanes) over the orthophoto; road QA pictures."""
    layers = []  # (layer, list of (points, class))
    sources = []
    for s, f in ctx.find("*.xodr"):
        try:
            items = network_items(f)
        except Exception as exc:
            ctx.log.warning("twinkit: report: cannot read %s (%s)", f, exc)
            continue
        shift = _projected_shift(ctx, items)
        layers.append(("xodr", [([(x - shift[0], y - shift[1]) for x, y in pts], cls) for pts, cls in items]))
        n = sum(cls == "band" for _, cls in items)
        sources.append(f"{s.get('folder')}/{f.name} ({n} paved lane segments)")
        break
    for s, f in ctx.find("roads_truth.json")[:1]:
        d = ctx.read_json(f) or {}
        lanes = [([tuple(p[:2]) for p in ln.get("points", [])], "truth") for ln in d.get("lanes", [])
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
        drawn = sorted((it for _, items in layers for it in items), key=lambda it: 0 if it[1] == "band" else 1)
        for pts, cls in drawn:  # bands first, lines over them
            if len(pts) < 2:
                continue
            d = " ".join(f"{(x - b[0]) * sx:.1f},{(b[3] - y) * sy:.1f}" for x, y in pts)
            shape = "polygon" if cls == "band" else "polyline"
            svg.append(f"<{shape}{ctx.attr('class', cls)} points=\"{d}\"/>")
        svg.append("</svg>")
        keys = "<span class=\"key xodr\">OpenDRIVE driving-lane centre lines (band: paved lanes; thin: junctions)</span>" if any(
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


def _projected_shift(ctx, items: list) -> tuple[float, float]:
    """OpenDRIVE in projected coordinates -> site frame, using the site's base point."""
    xs = [abs(x) for pts, _ in items for x, _ in pts[:1]]
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
        rows = [[x.get("id"), x.get("kind"), x.get("type", ""), x.get("road"), x.get("defined_on_road"),
                 x.get("source"), f"{x.get('moved_m', 0):.2f}",
                 x.get("instance") if x.get("instance") is not None else "", x.get("note", "")]
                for x in d.get("signals", [])]
        parts.append(f"<h3>{ctx.esc(s.get('folder'))}/{ctx.esc(f.name)}</h3>" + ctx.table(
            ["signal", "kind", "type", "controls road", "defined on road", "source", "moved m", "scanned instance",
             "note"], rows))
        plan = (d.get("light_plan") or {}).get("junctions") or {}
        if plan:
            parts.append("<p>Junction signal plans as CARLA 0.9.16 runs them (twinkit.street.lights):</p>" + ctx.table(
                ["junction", "lights", "approaches", "light groups", "phases (controllers)",
                 "crossing approaches green together"],
                [[j, v.get("lights"), v.get("approaches"), v.get("groups"), v.get("controllers"),
                  len(v.get("conflicts", []))] for j, v in plan.items()]))
        parts.append(_step_picture(ctx, s, f.parent / "signals.png", "Scanned lights (orange) and signs (blue); "
                                   "netconvert's signals (red) and where they are now (green)"))
    return "".join(parts)


def sec_crosswalks(ctx) -> str:
    """place_crosswalks: each crosswalk, where it came from, where CARLA reads it."""
    parts = []
    for s, f in ctx.find("crosswalks.json")[:1]:
        d = ctx.read_json(f)
        if not isinstance(d, dict) or not d.get("enabled", True):
            continue
        m = d.get("metrics", {})
        rows = [[x.get("id", ""), x.get("source"), x.get("osm") or "", ", ".join(f"{v:.2f}" for v in x.get("centre", [])),
                 (x.get("zebra") or {}).get("bars", ""), x.get("road", ""), x.get("s", ""), x.get("note", "")]
                for x in d.get("crosswalks", [])]
        parts.append(f"<h3>{ctx.esc(s.get('folder'))}/{ctx.esc(f.name)}</h3><p>{m.get('osm_crossings', 0)} OSM "
                     f"crossings, {m.get('zebras', 0)} painted zebras in the scan; carla.Map reports "
                     f"{m.get('carla_crosswalks', 0)} crosswalks</p>")
        parts.append(ctx.table(["object", "source", "OSM", "centre (x, y) m", "bars", "road", "s m", "note"], rows))
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

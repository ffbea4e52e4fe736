"""twinkit-photo's section of the run report: the photos (registered and dropped), the georeference (how the
frame was levelled and scaled, outlier cameras), a top-down map of the cameras against their GPS fixes, and a
table per photo (GPS residual, outlier reason, depth-map coverage and dense points kept where the dense step
records them; a photo keeping under a tenth of the median is flagged).

Registered through ``twinkit_register_report_sections`` (plugin.py exposes the hook implementation). It reads
only the files of this distribution's own steps: ``sfm_report.json`` (sfm), ``georef.json`` (georeference) and
``points_meta.json`` (dense: ``dense.valid_ratio``, the share of each photo's pixels with a depth, and
``dense.per_photo``, the points of each photo's map that the fusion kept).
"""
from __future__ import annotations

import math
import statistics

from twinkit import hookimpl
from twinkit.report.html import esc


@hookimpl
def twinkit_register_report_sections(register):
    register("photos", sec_photos, title="Photos: registration and georeference", order=650)


def _own(ctx, name: str):
    """The newest file ``name`` among this plugin's steps' outputs, read as JSON (or None)."""
    for s in reversed(ctx.own_steps()):
        f = ctx.outputs(s).get(name)
        if f is not None:
            d = ctx.read_json(f)
            if d is not None:
                return s, f, d
    return None


def camera_map_svg(photos: dict, width: int = 560, height: int = 420, units: str = "m") -> str:
    """A top-down map (x east, y north) of the camera centres (blue; outliers red) and their GPS fixes
    (orange), each pair joined by a thin line, with a scale bar. ``photos``: {name: {camera_m, gps_m,
    outlier}} as georef.json writes it."""
    pts = []
    for p in photos.values():
        pts.append(p["camera_m"][:2])
        if p.get("gps_m"):
            pts.append(p["gps_m"][:2])
    if not pts:
        return ""
    xs, ys = [p[0] for p in pts], [p[1] for p in pts]
    x0, x1, y0, y1 = min(xs), max(xs), min(ys), max(ys)
    span = max(x1 - x0, y1 - y0, 1e-6)
    pad = 0.08 * span
    x0, y0 = x0 - pad, y0 - pad
    span += 2 * pad
    k = min(width, height) / span

    def xy(p):
        return (p[0] - x0) * k, height - (p[1] - y0) * k

    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
           f'viewBox="0 0 {width} {height}" style="background:#fafafa;border:1px solid #ddd">']
    for name, p in sorted(photos.items()):
        cx, cy = xy(p["camera_m"])
        if p.get("gps_m"):
            gx, gy = xy(p["gps_m"])
            out.append(f'<line x1="{cx:.1f}" y1="{cy:.1f}" x2="{gx:.1f}" y2="{gy:.1f}" stroke="#999" '
                       f'stroke-width="0.8"/>')
            out.append(f'<path d="M{gx - 3:.1f},{gy - 3:.1f}L{gx + 3:.1f},{gy + 3:.1f}M{gx - 3:.1f},{gy + 3:.1f}'
                       f'L{gx + 3:.1f},{gy - 3:.1f}" stroke="#e67e22" stroke-width="1.5"><title>{esc(name)} GPS'
                       f'</title></path>')
        col = "#c0392b" if p.get("outlier") else "#2c6fbb"
        why = f' (outlier: {esc(p["outlier"])})' if p.get("outlier") else ""
        out.append(f'<circle cx="{cx:.1f}" cy="{cy:.1f}" r="{4 if p.get("outlier") else 3}" fill="{col}">'
                   f'<title>{esc(name)}{why}</title></circle>')
        if p.get("outlier"):
            out.append(f'<text x="{cx + 6:.1f}" y="{cy - 4:.1f}" font-size="11" fill="#c0392b">'
                       f'{esc(name)}</text>')
    # scale bar: a round length near a fifth of the map
    target = span / 5
    bar = 10 ** math.floor(math.log10(target))
    for m in (5, 2, 1):
        if m * bar <= target:
            bar *= m
            break
    bl = bar * k
    out.append(f'<line x1="10" y1="{height - 12}" x2="{10 + bl:.1f}" y2="{height - 12}" stroke="#333" '
               f'stroke-width="2"/><text x="10" y="{height - 16}" font-size="11">{bar:g} {units}</text>')
    out.append("</svg>")
    return "".join(out)


def sec_photos(ctx) -> str:
    sfm = _own(ctx, "sfm_report.json")
    geo = _own(ctx, "georef.json")
    if sfm is None and geo is None:
        return ""
    parts = []
    if sfm is not None:
        parts += _sfm_part(ctx, sfm[2])
    if geo is not None:
        g = geo[2]
        units = "m" if g.get("scaled", True) else "model units"
        warn = "" if g.get("scaled", True) else (
            "<p class=\"degraded\"><b>Unscaled:</b> no GPS with a site CRS, no GCPs and no known distance: the site frame "
            "is in model units, and every length in this report is in those units, not metres.</p>")
        if g.get("scale_from") == "eye height":
            warn = (f"<p class=\"degraded\"><b>Scale estimated:</b> {ctx.esc(g.get('units'))}. A guess from the "
                    f"cameras' height over the sparse ground, not a georeference: every length in this report "
                    f"carries that error.</p>")
        parts.append("<h3>Georeference</h3>" + warn + ctx.table(["", "value"], _georef_rows(g)))
        photos = g.get("photos") or {}
        if photos:
            parts.append("<h3>Cameras (blue; outliers red) against their GPS fixes (orange), top-down</h3>"
                         + camera_map_svg(photos, units=units))
            parts.append(_per_photo_part(ctx, photos, sfm, units))
    return "".join(parts)


def _sfm_part(ctx, r: dict) -> list[str]:
    """The structure-from-motion table (and the camera groups' where there are several)."""
    rows = [["photos", r.get("photos")], ["registered", r.get("registered")],
            ["mean reprojection error (px)", r.get("mean_reprojection_error_px")],
            ["sparse points", r.get("sparse_points")], ["intrinsics from", r.get("intrinsics_from")],
            ["photos with GPS", r.get("photos_with_gps")]]
    unreg = r.get("unregistered") or []
    rows.append(["dropped (not registered)", ", ".join(unreg) if unreg else "none"])
    parts = ["<h3>Structure from motion</h3>" + ctx.table(["", "value"], rows)]
    groups = r.get("camera_groups") or []
    if len(groups) > 1:
        parts.append(ctx.table(["camera group (size, make, model)", "photos", "registered"],
                               [[f"{g['size'][0]}x{g['size'][1]} {g.get('make') or ''} {g.get('model') or ''}",
                                 g.get("photos"), g.get("registered")] for g in groups]))
    return parts


def _georef_rows(g: dict) -> list[list]:
    """The georeference table's rows: method, units, scale, levelling, fits, unused inputs, outlier cameras."""
    lvl = g.get("level") or {}
    rows = [["method", g.get("method")], ["units", g.get("units", "metres")],
            ["scale (site units per model unit)", (g.get("transform") or {}).get("scale")],
            ["scale from", g.get("scale_from") or "the fit"],
            ["up from", lvl.get("up_from")],
            ["final vertical vs. the photos' horizon (deg)", g.get("level_vs_camera_horizon_deg")]]
    hz = lvl.get("camera_horizon") or {}
    if hz:
        rows.append(["photos' horizon: photos used, spread (deg)", f"{hz.get('used')} of {hz.get('photos')}, "
                                                                   f"{hz.get('spread_deg')}"])
    vl = lvl.get("vertical_lines")
    if vl:
        rows.append(["vertical lines: lines, photos, vs. horizon (deg)",
                     f"{vl.get('lines')}, {vl.get('photos_with_lines')}, {vl.get('vs_camera_horizon_deg')}"])
    gp = lvl.get("ground_plane")
    if gp:
        rows.append(["ground plane", ("used" if gp.get("used") else f"not used: {gp.get('why_not')}")
                     + f" ({100 * gp.get('inlier_ratio', 0):.1f} % of the points, {gp.get('vs_photo_up_deg')} deg "
                       f"from the photos' vertical)"])
    if "gps" in g:
        rows.append(["GPS fit: inliers / photos with GPS, rmse (m)",
                     f"{g['gps'].get('inliers')} / {g['gps'].get('photos_with_gps')}, {g['gps'].get('rmse_m')}"])
    if "gcp" in g:
        rows.append(["GCPs used, rmse (m)", f"{g['gcp'].get('used')}, {g['gcp'].get('rmse_m')}"])
    for key, label in (("gcp_unused", "GCP file not used"), ("gps_unused", "EXIF GPS not used")):
        if key in g:
            u = g[key]
            rows.append([label, f"{u.get('why')}; " + (f"used instead: {u['used_instead']}" if "used_instead" in u
                                                       else u.get("suggestion", ""))])
    outl = g.get("outlier_cameras") or {}
    rows.append(["outlier cameras (left out of the later steps)",
                 "; ".join(f"{n}: {w}" for n, w in outl.items()) if outl else "none"])
    return rows


def _per_photo_part(ctx, photos: dict, sfm, units: str) -> str:
    """The per-photo table: registered, GPS residual, outlier reason, depth-map coverage, dense points kept."""
    cover, kept = {}, {}
    dense = _own(ctx, "points_meta.json")
    if dense is not None:
        cover = ((dense[2].get("dense") or {}).get("valid_ratio") or {})
        kept = ((dense[2].get("dense") or {}).get("per_photo") or {})
    # a photo whose depth map keeps under a tenth of the median: a stretch of the walk the fusion could
    # not confirm (photos too far apart, a white wall), where the mesh will be thin
    counts = [int(v) for v in kept.values() if isinstance(v, (int, float))]
    thin = 0.1 * statistics.median(counts) if counts else 0.0
    rows = []
    for n in sorted(set(photos) | set((sfm[2].get("unregistered") or []) if sfm else [])):
        p = photos.get(n)
        if p is None:
            rows.append([n, "no", "", "", "", ""])
            continue
        c = cover.get(n)
        k = kept.get(n)
        kcell = ""
        if isinstance(k, (int, float)):
            kcell = f"{int(k):,}" + (" (under a tenth of the median: little here is confirmed by a second "
                                     "photo)" if k < thin else "")
        rows.append([n, "yes", p.get("gps_residual_m") if p.get("gps_residual_m") is not None else "",
                     p.get("outlier") or "", f"{100 * c:.1f} %" if isinstance(c, (int, float)) else "", kcell])
    return "<h3>Per photo</h3>" + ctx.table(
        ["photo", "registered", f"GPS residual ({units})", "outlier camera", "depth-map coverage",
         "dense points kept"], rows)

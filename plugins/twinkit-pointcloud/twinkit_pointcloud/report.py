"""twinkit-pointcloud's sections of the run report: the reconstruction metrics (``recon_metrics.json``
of evaluate_reconstruction) and its pictures (the distance heat map, what clean_mesh removed) in the
"Pictures" gallery.

Registered through ``twinkit_register_report_sections`` (plugin.py exposes the hook implementation).
"""
from __future__ import annotations

from twinkit import hookimpl


@hookimpl
def twinkit_register_report_sections(register):
    register("pictures", sec_pictures, order=410)
    register("recon", sec_recon_metrics, title="Reconstruction metrics", order=700)


def sec_pictures(ctx) -> str:
    """Pictures for the "Pictures" gallery: the distance heat map and what the clean-up removed."""
    figs = []
    for pattern, caption in (("recon_metrics.png", "Distance from the cloud to the mesh (heat map)"),
                             ("*distance*.png", "Distance heat map"), ("*heat*.png", "Heat map"),
                             ("clean_report.png", "Mesh cleaning: what was removed"),
                             ("open_border.png", "Open border of the ground (red: a crack or hole inside the site; "
                                                 "blue: the site's edge)"),
                             ("drop_test.png", "Drop test over the lanes (orange: a ray that found no ground)")):
        for s, f in ctx.find(pattern)[:1]:
            name = f"{s.get('folder')}_{f.name}"
            if any(name in x for x in figs):
                continue
            ctx.add_image(f, name)
            figs.append(ctx.figure(f"img/{name}", ctx.esc(caption), f" <span class=\"dim\">{ctx.esc(s.get('folder'))}/{ctx.esc(f.name)}</span>"))
    return "".join(figs)


def _stats_table(ctx, title: str, d: dict) -> str:
    rows, cols = [], []
    for k, v in d.items():
        if isinstance(v, dict) and v and all(isinstance(x, (int, float)) for x in v.values()):
            for c in v:
                if c not in cols:
                    cols.append(c)
    for k, v in d.items():
        if isinstance(v, dict) and v and all(isinstance(x, (int, float)) for x in v.values()):
            rows.append([k] + [v.get(c, "") for c in cols])
    if not rows:
        return ""
    return f"<h3>{ctx.esc(title)}</h3>" + ctx.table([f"distance ({ctx.length_unit()})"] + cols, rows)


_STAT_KEYS = {"min", "max", "mean", "median", "p5", "p50", "p90", "p95", "p99", "rms", "std", "count"}


def sec_recon_metrics(ctx) -> str:
    """The distance statistics, coverage and counts of ``recon_metrics.json``."""
    hit = ctx.first("recon_metrics.json")
    if not hit:
        return ""
    s, f = hit
    d = ctx.read_json(f) or {}
    parts = []
    def is_stats(v):
        return isinstance(v, dict) and bool(v) and set(v) <= _STAT_KEYS

    dist = {k: v for k, v in d.items() if is_stats(v)}
    gt = d.get("gt") if isinstance(d.get("gt"), dict) else {}
    dist.update({f"gt: {k}": v for k, v in gt.items() if is_stats(v)})
    parts.append(_stats_table(ctx, "Distances", dist))
    scal = [[f"gt: {k}", v] for k, v in gt.items() if isinstance(v, (int, float)) and not isinstance(v, bool)]
    within = d.get("cloud_within_m")
    if isinstance(within, dict):
        parts.append("<h3>Cloud points within a distance of the mesh</h3>" + ctx.table(
            [f"within ({ctx.length_unit()})", "fraction"], [[k, v] for k, v in within.items()]))
    far = d.get("cloud_far")
    if isinstance(far, dict) and "share" in far:
        rows = [["whole cloud", far.get("points", ""), f"{100 * far['share']:.2f} %"]]
        for k, v in (far.get("per_class") or {}).items():
            rows.append([k, v.get("points", ""), f"{100 * v.get('share', 0.0):.2f} %"])
        parts.append(f"<h3>Points farther than {ctx.esc(far.get('far_m', ''))} {ctx.esc(ctx.length_unit())} from the mesh (labels lost)</h3>"
                     + ctx.table(["points", "count", "share farther"], rows))
    if isinstance(d.get("counts"), dict):
        parts.append("<h3>Counts</h3>" + ctx.table(["", "count"], [[k, v] for k, v in d["counts"].items()]))
    if scal:
        parts.append("<h3>Against ground truth</h3>" + ctx.table(["metric", "value"], scal))
    parts.append(f"<p class=\"dim\">from {ctx.esc(s.get('folder'))}/{ctx.esc(f.name)}</p>")
    return "".join(p for p in parts if p)

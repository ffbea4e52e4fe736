"""The core sections of the run report, and the list every page is assembled from.

The core owns the layout and these sections only: the run summary, the step timeline, the 3D view, the
orthophotos (the first part of "Pictures"), the provenance and the file list. Every other section comes
from the plugin that makes the files it shows, through the hook ``twinkit_register_report_sections``
(``twinkit.plugins.ReportSection``). Which plugin owns which section: docs/report.md.

Orders of the sections in the page (a plugin section takes a number between them)::

    summary 100  gates 150  warnings 160  timeline 200  view3d 300  pictures 400  roads 500  samples 600  recon 700
    segmetrics 800  alignment 900  provenance 1000  files 1100

Several parts may share one section id (each plugin adds its own pictures to "pictures"): the page
shows them as one section, in the order of their ``order``, under the title of the first. The parts of
a gallery section (``GALLERIES``: "pictures") return ``<figure>`` elements, which the page puts in one
row of figures.
"""
from __future__ import annotations

import json
from pathlib import Path

from twinkit.plugins import ReportSection
from twinkit.quality import degraded_of, run_status_text
from twinkit.report.context import SectionContext
from twinkit.report.gates import gates_section, warnings_section
from twinkit.report.html import attr, esc, link
from twinkit.report.page import figure, fmt, legend, size, status_badge, table
from twinkit.report.run import RunView, flatten, rel
from twinkit.report.viewer import sec_viewer

MAX_FILES_LISTED = 200      # per step folder; the folder itself is linked too
#: sections whose parts are figures, shown together in one row
GALLERIES = ("pictures",)


def _summary(run: RunView, out: Path) -> str:
    m = run.manifest
    cfg = m.get("config") or {}
    recipe = (cfg.get("recipe") or {}).get("name", "?")
    site = m.get("site") or {}
    git = m.get("git") or {}
    counts: dict[str, int] = {}
    for s in run.steps:
        counts[s.get("status", "?")] = counts.get(s.get("status", "?"), 0) + 1
    rows = [
        ["status", run_status_text(m)], ["recipe", recipe], ["site", site.get("name", "?")],
        ["started", m.get("started", "?")], ["finished", m.get("finished", "?")],
        ["duration", f"{m.get('duration_s', 0):.1f} s"],
        ["steps", ", ".join(f"{v} {k}" for k, v in counts.items())],
        ["overrides", " ".join(m.get("overrides") or []) or "(none)"],
        ["git", f"{(git.get('commit') or '?')[:12]}{' (uncommitted changes)' if git.get('dirty') else ''}"],
        ["workspace", ("html", link(rel(run.workspace, out), run.workspace))],
        ["manifest", ("html", f"{link(rel(run.run_dir / 'manifest.json', out), 'manifest.json')} · "
                              f"{link(rel(run.run_dir / 'run.log', out), 'run.log')}")],
    ]
    return table(["", ""], rows, "kv")


def _timeline(run: RunView) -> str:
    if not run.steps:
        return ""
    total = sum(float(s.get("duration_s") or 0) for s in run.steps) or 1.0
    rows = []
    for i, s in enumerate(run.steps, 1):
        d = float(s.get("duration_s") or 0)
        parts = _parts(s, d)
        bar = (f"<div{attr('class', 'bar st-' + str(s.get('status')) + (' split' if parts else ''))} "
               f"style=\"width:{max(0.5, 100 * d / total):.1f}%\" title=\"{d:.1f} s\">{_segments(parts, d)}</div>")
        rows.append("<tr>" + "".join([
            f"<td class=\"num\">{i}</td>",
            f"<td>{link('#step-' + str(s.get('folder')), s.get('folder'))}</td>",
            f"<td>{esc(s.get('plugin', ''))}</td>",
            f"<td>{status_badge(str(s.get('status', '?')))}"
            f"{(' ' + status_badge('degraded')) if degraded_of(s.get('metrics')) else ''}</td>",
            f"<td>{esc(s.get('why', ''))}</td>",
            f"<td class=\"num\">{d:.1f} s</td>",
            f"<td class=\"num\">{esc(fmt(s.get('peak_rss_mb')) if s.get('peak_rss_mb') else '')}</td>",
            f"<td class=\"barcell\">{bar}</td>",
        ]) + "</tr>" + _substep_row(parts, d))
    head = "".join(f"<th>{h}</th>" for h in ("#", "folder", "plugin", "status", "why", "time", "peak MB", ""))
    key = ("<p class=\"legend\">ran: computed now · cached: linked from an earlier result · reused: "
              "unchanged in place · edited: a hand edit was kept · manual: a file you provided · degraded: the step "
              "said its result is far below what it should be (reasons at the top) · a bar in parts: the step's "
              "substeps (hover for each; the table under the step lists them; twinkit profile prints them)</p>")
    return f"<table class=\"timeline\"><thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>{key}"


def _parts(step: dict, seconds: float) -> list[tuple[str, dict]]:
    """The substeps of a step that ran now (twinkit.profile), for its bar; none for a cached or reused one."""
    from twinkit.profile import merged_substeps, substep_parts

    if step.get("status") != "ran" or seconds <= 0:
        return []
    return substep_parts(seconds, merged_substeps(step.get("metrics")))


def _segments(parts: list[tuple[str, dict]], seconds: float) -> str:
    """The parts of a step's bar, one per top-level substep, each titled with its name, seconds and peak."""
    out = []
    for name, rec in parts:
        if "/" in name:
            continue
        sec = float(rec.get("seconds") or 0)
        peak = f", peak {float(rec['peak_rss_mb']):.0f} MB" if rec.get("peak_rss_mb") else ""
        out.append(f"<span style=\"width:{100 * sec / seconds:.1f}%\"{attr('title', f'{name}: {sec:.1f} s{peak}')}>"
                   "</span>")
    return "".join(out)


def _substep_row(parts: list[tuple[str, dict]], seconds: float) -> str:
    """A folded row under a step with substeps: name, seconds, share of the step, peak MB, calls."""
    if not parts:
        return ""
    rows = [[name, round(float(rec.get("seconds") or 0), 2), f"{100 * float(rec.get('seconds') or 0) / seconds:.0f} %",
             round(float(rec["peak_rss_mb"])) if rec.get("peak_rss_mb") else "", rec.get("calls") or ""]
            for name, rec in parts]
    inner = table(["substep", "seconds", "share", "peak MB", "calls"], rows, "small")
    return (f"<tr class=\"substeps\"><td></td><td colspan=\"7\"><details><summary>{len(parts)} parts</summary>"
            f"{inner}</details></td></tr>")


def _provenance(run: RunView, out: Path) -> str:
    m = run.manifest
    site = m.get("site") or {}
    py = m.get("python") or {}
    parts = []
    rows = [["CRS", site.get("crs", "")], ["base point", json.dumps(site.get("base_point", ""))],
            ["command", " ".join(m.get("argv") or [])], ["python", f"{py.get('version', '?')} on {py.get('platform', '?')}"],
            ["schema", m.get("schema_version", "?")]]
    parts.append(table(["", ""], rows, "kv"))
    plugins = m.get("plugins") or []
    if plugins:
        parts.append("<h3>Plugins</h3>" + table(["kind", "name", "version", "distribution"],
                                                  [[p.get("kind"), p.get("name"), p.get("version"),
                                                    p.get("distribution")] for p in plugins]))
    libs = m.get("libraries") or {}
    if libs:
        parts.append("<h3>Libraries</h3><p class=\"libs\">" +
                     " · ".join(f"{esc(k)} {esc(v)}" for k, v in sorted(libs.items())) + "</p>")
    inputs = m.get("inputs") or []
    if inputs:
        parts.append("<h3>Inputs</h3>" + table(["file", "size", "sha256"], [
            [("html", file_link(Path(e["path"]), out)), size(int(e.get("size", 0))), (e.get("sha256") or "")[:16]]
            for e in inputs]))
    cfg = m.get("config")
    if cfg:
        parts.append("<details><summary>Composed configuration</summary><pre>" +
                     esc(json.dumps(cfg, indent=2, sort_keys=True, default=str)) + "</pre></details>")
    return "".join(parts)


def file_link(p: Path, out: Path) -> str:
    return link(rel(p, out), p.name)


def _files(run: RunView, out: Path) -> str:
    blocks = []
    for s in run.steps:
        if not s["files"]:
            continue
        rows = []
        for f in s["files"]:
            name = f.relative_to(s["dir"])
            try:
                nbytes = f.stat().st_size
            except OSError:
                nbytes = 0
            rows.append([("html", link(rel(f, out), name)), size(nbytes),
                         (s["hashes"].get(str(name)) or "")[:16]])
        shown = rows[:MAX_FILES_LISTED]
        more = f"<p>and {len(rows) - len(shown)} more in {link(rel(s['dir'], out), 'the folder')}</p>" \
            if len(rows) > len(shown) else ""
        metrics = s.get("metrics") or {}
        mt = ""
        if metrics:
            flat = flatten(metrics)
            mt = "<details><summary>step metrics</summary>" + table(
                ["metric", "value"], [[k, v] for k, v in flat.items()], "kv small") + "</details>"
        blocks.append(
            f"<details class=\"stepfiles\"{attr('id', 'step-' + str(s.get('folder')))}><summary><b>{esc(s.get('folder'))}</b> "
            f"{status_badge(str(s.get('status', '?')))} {len(rows)} file(s) · "
            f"{link(rel(s['dir'], out), 'folder')}</summary>"
            + table(["file", "size", "sha256"], shown, "files") + more + mt + "</details>")
    return "".join(blocks)




def _orthophotos(ctx: SectionContext) -> str:
    """The first pictures: the top-down orthophoto of the mesh, and the same in segmentation colours."""
    figs = []
    o = ctx.ortho()
    if o:
        b = o["bounds"]
        ext = (f" <span class=\"dim\">{b[2] - b[0]:.1f} × {b[3] - b[1]:.1f} {esc(ctx.length_unit())}, north up, "
               f"from {esc(o['mesh'].name)}</span>")
        figs.append(figure(o["texture"], "Top-down orthophoto of the textured mesh", ext))
        if o["segmentation"]:
            src = f" <span class=\"dim\">from {esc(o.get('labels'))}</span>" if o.get("labels") else ""
            figs.append(figure(o["segmentation"], "The same in segmentation colours", src + legend()))
    return "".join(figs)


def core_sections() -> list[ReportSection]:
    """The core's own sections (page links are computed from the finished report folder)."""
    def mk(name, title, order, render):
        return ReportSection(name=name, render=render, title=title, order=order, distribution="twinkit",
                             module=__name__)

    return [
        mk("summary", "Run", 100, lambda ctx: _summary(ctx.run, ctx.report_dir)),
        mk("gates", "Quality gates", 150, lambda ctx: gates_section(ctx.run)),
        mk("warnings", "Warnings", 160, lambda ctx: warnings_section(ctx.run)),
        mk("timeline", "Step timeline", 200, lambda ctx: _timeline(ctx.run)),
        mk("view3d", "3D view", 300, lambda ctx: sec_viewer(ctx.run, ctx.out, ctx.topdown)),
        mk("pictures", "Pictures", 400, _orthophotos),
        mk("provenance", "Provenance", 1000, lambda ctx: _provenance(ctx.run, ctx.report_dir)),
        mk("files", "Files", 1100, lambda ctx: _files(ctx.run, ctx.report_dir)),
    ]

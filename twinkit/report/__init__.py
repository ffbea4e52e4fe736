"""The run report: ``<run folder>/report/report.html``, readable offline from ``file://``.

``write_report(run_dir, manifest, engine)`` is called by the command after every successful run; it reads
the manifest and the numbered step folders of ``engine.workspace`` and shows whatever exists (each section
appears once the stage that feeds it has produced its files). It never fails the run: any problem is
logged as one warning and the report is written without the part concerned (or not at all).

The page is assembled from sections: the core's own (:mod:`twinkit.report.sections`: run, timeline,
3D view, orthophotos, provenance, files) and those the plugins register through the hook
``twinkit_register_report_sections`` (each plugin shows the files it makes; a section is
``render(ctx) -> str | None`` with ctx a :class:`~twinkit.report.context.SectionContext`).

``write_sweep_summary(sweep_dir)`` gathers the ``job*/manifest.json`` of a multirun sweep into one page
(swept overrides against metrics, and a plot of each metric against each numeric swept parameter);
``SweepSummaryCallback`` calls it at the end of a multirun (a Hydra callback).

Heavy pictures (top-down orthophotos, the light GLB of the 3D view) are cached by the content of their
inputs in ``<site>/.cache/report/`` and hard-linked into each report, so a run that changed nothing pays
nothing for them. See docs/report.md.

Modules: ``run`` (the run folder as read), ``page`` (layout and HTML helpers), ``context`` (what a
section sees), ``sections`` (the core sections), ``render`` (top-down renderer and orthophotos),
``viewer`` (three.js bundle and the 3D view), ``sweep`` (multirun summary). Meshes are read and the
3D view's GLB written with the shared library (``twinkit.mesh``), like everywhere else.
"""
from __future__ import annotations

import json
import logging
import os
import shutil
import time
from pathlib import Path

from twinkit.report.context import SectionContext
from twinkit.report.html import esc
from twinkit.report.page import (ASSETS, CITYSCAPES, CSS_FILE, IGNORE_COLOR, Page, degraded_banner, palette,
                                 render_page, status_badge)
from twinkit.report.render import ORTHO_PX, TopDown
from twinkit.report.run import REPORT_DIR, RunView, prune_cache
from twinkit.report.sections import GALLERIES, core_sections
from twinkit.report.sweep import SweepSummaryCallback, write_sweep_summary

log = logging.getLogger("twinkit.report")

__all__ = ["write_report", "build_report", "write_sweep_summary", "SweepSummaryCallback", "prune_cache",
           "SectionContext", "report_sections", "palette", "CITYSCAPES", "IGNORE_COLOR", "ORTHO_PX", "REPORT_DIR"]


def report_sections(registry=None) -> list:
    """Every section part of the page, core and plugins', in page order (``twinkit.plugins.ReportSection``).

    ``registry`` defaults to the loaded plugins (``twinkit.plugins.get_registry()``)."""
    parts = core_sections()
    if registry is None:
        from twinkit.plugins import get_registry

        registry = get_registry()
    parts += list(getattr(registry, "report_sections", []) or [])
    first: dict[str, float] = {}
    for p in parts:
        first[p.name] = min(first.get(p.name, p.order), p.order)
    # sections by their first part's order; the parts of one section by their own order (stable: core first)
    return sorted(parts, key=lambda p: (first[p.name], p.name, p.order))


def build_report(run_dir: Path, manifest: dict, engine=None) -> Path:
    """Write ``<run_dir>/report/report.html`` (raises on problems; ``write_report`` is the safe entry).

    The sections come from ``engine.registry`` when the engine has one, else from the loaded plugins."""
    t0 = time.perf_counter()
    run = RunView(run_dir, manifest, engine)
    out = Path(run_dir) / REPORT_DIR
    for stale in list(Path(run_dir).glob(f".{REPORT_DIR}.tmp-*")) + list(Path(run_dir).glob(f".{REPORT_DIR}.old-*")):
        shutil.rmtree(stale, ignore_errors=True)  # left by an interrupted report
    tmp = Path(run_dir) / f".{REPORT_DIR}.tmp-{os.getpid()}"
    tmp.mkdir(parents=True)
    # links in the page are computed from the final folder; files are written into the temporary one
    page = Page(tmp)
    pics = TopDown(run, tmp)
    ctx = SectionContext(run, tmp, pics)
    timings: dict[str, float] = {}
    bodies: dict[str, list[str]] = {}
    titles: dict[str, str] = {}
    for part in report_sections(getattr(engine, "registry", None)):
        sid = part.name
        if part.title and sid not in titles:
            titles[sid] = part.title  # the first part with a title names the section
        title = titles.get(sid, sid)
        bodies.setdefault(sid, [])
        t = time.perf_counter()
        try:
            body = part.render(ctx.for_distribution(part.distribution))
            if body:
                bodies[sid].append(body)
        except Exception as exc:
            log.warning("twinkit: report: section '%s' left out (%s: %s)", title, type(exc).__name__, exc)
            log.debug("report section %s (%s)", sid, part.module, exc_info=True)
            page.notes.append(f"The section '{title}' could not be written ({type(exc).__name__}: {exc}); "
                              "see run.log.")
        timings[sid] = round(timings.get(sid, 0.0) + time.perf_counter() - t, 3)
    for sid, parts in bodies.items():
        body = "".join(parts)
        if body and sid in GALLERIES:
            body = "<div class=\"figs\">" + body + "</div>"
        page.add(sid, titles.get(sid, sid), body)
    cfg = manifest.get("config") or {}
    title = f"twinkit report: {(manifest.get('site') or {}).get('name', '?')} · " \
            f"{(cfg.get('recipe') or {}).get('name', '?')}"
    notes = [str(n) for n in manifest.get("notes") or []]  # facts on the twin beside the status ("no road network")
    sub = (f"{status_badge(str(manifest.get('status', '?')))}{''.join(' · ' + esc(n) for n in notes)} "
           f"run {esc(Path(run_dir).name)} · "
           f"{esc(manifest.get('finished', ''))}")
    if manifest.get("degraded"):
        page.banner = degraded_banner(manifest["degraded"])
    if isinstance(manifest.get("failed_step"), dict):
        from twinkit.report.page import failed_banner

        page.banner = failed_banner(manifest["failed_step"]) + page.banner
    shutil.copyfile(ASSETS / CSS_FILE, tmp / CSS_FILE)
    (tmp / "report.html").write_text(render_page(title, page, sub), encoding="utf-8")
    timings.update(pics.timings)
    timings["total_s"] = round(time.perf_counter() - t0, 3)
    prune_cache(run.cache_dir)
    (tmp / "report.json").write_text(json.dumps({"sections": [s for s, _, _ in page.sections],
                                                 "timings_s": timings}, indent=1) + "\n")
    old = Path(run_dir) / f".{REPORT_DIR}.old-{os.getpid()}"
    if out.exists():
        out.rename(old)
    tmp.rename(out)
    if old.exists():
        shutil.rmtree(old, ignore_errors=True)
    log.debug("report written in %.2f s: %s", timings["total_s"], timings)
    return out / "report.html"


def write_report(run_dir: Path, manifest: dict, engine=None) -> Path | None:
    """The report of one run; None (and one warning) if it could not be written. Never raises."""
    try:
        return build_report(Path(run_dir), manifest, engine)
    except Exception as exc:
        log.warning("twinkit: no report for this run (%s: %s)", type(exc).__name__, exc)
        log.debug("report", exc_info=True)
        return None

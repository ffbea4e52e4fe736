"""Report sections registered by plugins (hook ``twinkit_register_report_sections``)."""
from __future__ import annotations

import json
import logging
import re
import types
from types import SimpleNamespace

import pytest

from twinkit import hookimpl
from twinkit import report as R
from twinkit.errors import PluginError
from twinkit.plugins import KINDS, load_registry


def _module(fn):
    """A plugin module with one hook implementation."""
    mod = types.ModuleType("report_sections_test_plugin")
    mod.twinkit_register_report_sections = hookimpl(fn)
    return mod


def _engine(demo_run, mod):
    return SimpleNamespace(workspace=demo_run.ws, site_root=demo_run.ws,
                           registry=load_registry(extra=[(mod.__name__, mod)]))


def _ids(page):
    return re.findall(r"<section id=\"([^\"]+)\"", page.read_text())


def test_a_plugin_section_appears_in_its_place(demo_run, tmp_path):
    seen = {}

    def count_steps(ctx):
        seen["ctx"] = ctx
        evaluate = ctx.steps_of(kind="step", name="evaluate_reconstruction")
        outs = ctx.outputs(evaluate[0])
        return ctx.table(["output", "file"], [[k, ctx.esc(v.name)] for k, v in sorted(outs.items())])

    def register(register):
        register("extra_numbers", count_steps, title="Extra numbers", order=750)

    run = tmp_path / "run"
    run.mkdir()
    page = R.write_report(run, demo_run.manifest, _engine(demo_run, _module(register)))
    ids = _ids(page)
    assert ids.index("recon") < ids.index("extra_numbers") < ids.index("provenance")
    text = page.read_text()
    assert "<h2>Extra numbers</h2>" in text and "recon_metrics.json" in text
    assert "extra_numbers" in json.loads((page.parent / "report.json").read_text())["sections"]
    ctx = seen["ctx"]
    assert ctx.distribution == "report_sections_test_plugin" and ctx.own_steps() == []
    assert {s["id"] for s in ctx.steps_of(distribution="twinkit-pointcloud")} >= {"read_cloud", "evaluate"}


def test_a_failing_section_is_left_out_with_a_note(demo_run, tmp_path, caplog):
    def boom(ctx):
        raise RuntimeError("kaputt")

    def register(register):
        register("boom", boom, title="Boom", order=700)

    run = tmp_path / "run"
    run.mkdir()
    with caplog.at_level(logging.WARNING, logger="twinkit"):
        page = R.write_report(run, demo_run.manifest, _engine(demo_run, _module(register)))
    text = page.read_text()
    assert "kaputt" in text and "id=\"boom\"" not in text
    assert "id=\"timeline\"" in text and "id=\"recon\"" in text  # the others are all there
    assert "section 'Boom' left out" in caplog.text


def test_a_section_returning_nothing_is_left_out(demo_run, tmp_path):
    def register(register):
        register("nothing", lambda ctx: None, title="Nothing", order=650)

    run = tmp_path / "run"
    run.mkdir()
    page = R.write_report(run, demo_run.manifest, _engine(demo_run, _module(register)))
    assert "nothing" not in _ids(page) and "Nothing" not in page.read_text()


def test_parts_of_the_pictures_gallery_share_one_row(demo_run, tmp_path):
    def extra(ctx):
        return ctx.figure(ctx.add_image(ctx.workspace / "07_evaluate" / "recon_metrics.png", "extra.png"), "extra")

    def register(register):
        register("pictures", extra, order=499)

    run = tmp_path / "run"
    run.mkdir()
    page = R.write_report(run, demo_run.manifest, _engine(demo_run, _module(register)))
    sec = page.read_text().split("<section id=\"pictures\">", 1)[1].split("</section>", 1)[0]
    assert sec.count("<div class=\"figs\">") == 1
    assert sec.index("img/ortho.png") < sec.index("recon_metrics.png") < sec.index("img/extra.png")
    assert (page.parent / "img" / "extra.png").is_file()


def test_report_sections_are_not_a_step_kind():
    assert "report_section" not in KINDS and "twinkit_register_report_sections" not in KINDS.values()
    mod = _module(lambda register: register("x", lambda ctx: "", title="X"))
    reg = load_registry(extra=[(mod.__name__, mod)], entry_points=False)
    assert [(s.name, s.title, s.order) for s in reg.report_sections] == [("x", "X", 500.0)]
    assert reg.all() == []


def test_a_section_registered_twice_or_badly_fails_at_load():
    def twice(register):
        register("x", lambda ctx: "")
        register("x", lambda ctx: "")

    with pytest.raises(PluginError, match="twice"):
        load_registry(extra=[("m", _module(twice))], entry_points=False)
    with pytest.raises(PluginError, match="non-callable"):
        load_registry(extra=[("m", _module(lambda register: register("x", "not callable")))], entry_points=False)


def test_every_stage_section_comes_from_a_plugin():
    """The core owns the layout, the run summary, quality gates, warnings, timeline, 3D view, orthophotos,
    provenance and files."""
    parts = R.report_sections()
    core = {p.name for p in parts if p.distribution == "twinkit"}
    assert core == {"summary", "gates", "warnings", "timeline", "view3d", "pictures", "provenance", "files"}
    owners = {(p.name, p.distribution) for p in parts if p.distribution != "twinkit"}
    assert owners >= {("roads", "twinkit-roads"), ("alignment", "twinkit-roads"),
                      ("samples", "twinkit-segmentation"), ("segmetrics", "twinkit-segmentation"),
                      ("recon", "twinkit-pointcloud"), ("pictures", "twinkit-pointcloud"),
                      ("pictures", "twinkit-tiles")}
    order = ["summary", "timeline", "view3d", "pictures", "roads", "samples", "recon", "segmetrics", "alignment",
             "provenance", "files"]  # as before the sections moved (other installed plugins may add theirs)
    seen = list(dict.fromkeys(p.name for p in parts))
    assert [n for n in seen if n in order] == order


def test_the_core_report_names_no_plugin_file():
    from pathlib import Path

    core = Path(R.__file__).parent
    text = "\n".join(p.read_text() for p in core.glob("*.py"))
    for name in ("tile_seams", "recon_metrics", "roads_truth", "clean_report", "seg_metrics", ".xodr",
                 "alignment.json", "roads_check", "site.json", "*align*", "*road*", "renders/", "predictions/"):
        assert name not in text, name

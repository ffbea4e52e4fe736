"""twinkit.report.html: names from a run with <, " and & come out escaped, in text and in links."""
from __future__ import annotations

import json
from types import SimpleNamespace

from twinkit import hookimpl
from twinkit.plugins import load_registry
from twinkit.report import write_report
from twinkit.report.html import attr, esc, link, url
from twinkit.report.page import figure, table

BAD = 'a<b"&c'


def test_helpers_escape_text_attributes_and_addresses():
    assert esc(BAD) == "a&lt;b&quot;&amp;c"
    assert attr("id", BAD) == ' id="a&lt;b&quot;&amp;c"'
    assert url(f"img/{BAD} 1.png") == "img/a%3Cb%22%26c%201.png"
    assert url("../02_x/a%20b.ply") == "../02_x/a%20b.ply"  # an address made by rel() keeps its encoding
    assert url(f"#step-{BAD}") == "#step-a%3Cb%22%26c"
    assert url('file:///tmp/x"y') == "file:///tmp/x&quot;y"
    assert link(f"d/{BAD}.txt", BAD) == '<a href="d/a%3Cb%22%26c.txt">a&lt;b&quot;&amp;c</a>'
    assert link("x.txt", text_html="<b>x</b>", cls=BAD) == '<a href="x.txt" class="a&lt;b&quot;&amp;c"><b>x</b></a>'
    fig = figure(f"img/{BAD}.png", "cap")
    assert BAD not in fig and 'href="img/a%3Cb%22%26c.png"' in fig and 'src="img/a%3Cb%22%26c.png"' in fig
    assert BAD not in table([BAD], [[BAD], [("html", link(BAD))]], cls=BAD)


class _Section:
    """A plugin whose report section prints its step's folder and links its output."""

    @staticmethod
    def render(ctx):
        parts = []
        for step in ctx.steps:
            for name, path in ctx.outputs(step).items():
                parts.append(f"<p>{ctx.esc(step['folder'])}: {ctx.link(ctx.href(path), name)}</p>")
        return "".join(parts) or None

    @hookimpl
    def twinkit_register_report_sections(self, register):
        register("bad_names", self.render, title=f"Names {BAD}", order=950)


def test_a_name_with_markup_characters_is_escaped_in_a_section_and_its_href(tmp_path):
    folder, fname = f"02_{BAD}", f"p{BAD}.xyz"
    step = tmp_path / folder
    step.mkdir()
    (step / fname).write_text("0 0 0\n")
    (step / "step.json").write_text(json.dumps({"distribution": "bad", "descriptor": {
        "plugin": {"kind": "exporter", "name": "xyz"}, "outputs": [fname]}}))
    run = tmp_path / "runs" / "1"
    run.mkdir(parents=True)
    manifest = {"status": "ok", "steps": [{"id": "export", "folder": folder, "plugin": "exporter/xyz",
                                           "status": "ran", "metrics": {}}]}
    registry = load_registry(extra=[("bad", _Section())], entry_points=False)
    page = write_report(run, manifest, SimpleNamespace(workspace=tmp_path, site_root=tmp_path, registry=registry))
    text = page.read_text()
    assert BAD not in text  # nowhere on the page: not in the section, the timeline, the file list or a link
    sec = text.split('<section id="bad_names">', 1)[1].split("</section>", 1)[0]
    assert "<h2>Names a&lt;b&quot;&amp;c</h2>" in sec
    assert f"{esc(folder)}: " in sec
    assert f'href="../../../02_a%3Cb%22%26c/pa%3Cb%22%26c.xyz">{esc(fname)}</a>' in sec
    assert f'<a href="#step-02_a%3Cb%22%26c">{esc(folder)}</a>' in text  # the timeline's link to the step

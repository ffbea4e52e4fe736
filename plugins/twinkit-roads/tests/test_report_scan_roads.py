"""The report's roads section says how much of the roads derived from the scan the checks kept."""
from __future__ import annotations

import html
import json
import logging
from pathlib import Path

from twinkit_roads.report import sec_roads


class _Ctx:
    """What sec_roads reads of the report context: step files found by pattern, JSON, escaping."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.out = folder / "report"
        self.log = logging.getLogger("test")

    def find(self, pattern):
        return [({"folder": self.folder.name}, f) for f in sorted(self.folder.glob(pattern))]

    def read_json(self, f):
        return json.loads(Path(f).read_text())

    def esc(self, s):
        return html.escape(str(s))

    def ortho(self):
        return None


def test_the_roads_section_warns_when_the_checks_kept_little_of_the_derived_roads(tmp_path):
    step = tmp_path / "12_fetch_roads"
    step.mkdir()
    doc = {"roads": [{}, {}], "derived_m": 219.7, "kept_m": 57.6, "kept_share": 0.262, "params": {"min_kept_share": 0.5}}
    (step / "scan_roads.json").write_text(json.dumps(doc))
    out = sec_roads(_Ctx(step))
    assert 'class="warn"' in out and "kept 26 % of the 220 m" in out and "less of the streets" in out
    doc.update(kept_m=197.7, kept_share=0.9)
    (step / "scan_roads.json").write_text(json.dumps(doc))
    out = sec_roads(_Ctx(step))
    assert 'class="warn"' not in out and "kept 90 %" in out
    (step / "scan_roads.json").write_text(json.dumps({"roads": []}))  # an OSM run's folder has none: nothing said
    assert "kept" not in sec_roads(_Ctx(step))

"""twinkit-tiles adds its own sections to the run report (hook twinkit_register_report_sections)."""
from twinkit.plugins import load_registry

import twinkit_tiles.plugin as plugin


def test_the_report_sections_are_registered():
    reg = load_registry(extra=[("tiles", plugin)], entry_points=False)
    assert [(s.name, s.title, s.order) for s in reg.report_sections] == [('pictures', '', 420.0)]

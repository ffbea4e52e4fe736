"""twinkit-segmentation adds its own sections to the run report (hook twinkit_register_report_sections)."""
from twinkit.plugins import load_registry

import twinkit_segmentation.plugin as plugin


def test_the_report_sections_are_registered():
    reg = load_registry(extra=[("segmentation", plugin)], entry_points=False)
    assert [(s.name, s.title, s.order) for s in reg.report_sections] == [('samples', 'Sample views and 2D predictions', 600.0), ('segmetrics', 'Segmentation metrics', 800.0), ('confidence', 'Label confidence', 810.0)]

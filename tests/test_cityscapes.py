"""The shared CityScapes label set (twinkit.cityscapes)."""
from __future__ import annotations

import numpy as np
import pytest

from twinkit import cityscapes as cs


def test_palette_has_one_distinct_colour_per_class():
    assert cs.PALETTE.shape == (cs.N_CLASSES, 3) == (19, 3)
    assert len({tuple(c) for c in cs.PALETTE}) == 19
    assert cs.NAMES[0] == "road" and cs.NAMES[13] == "car" and cs.NAMES[18] == "bicycle"
    with pytest.raises(ValueError):
        cs.PALETTE[0, 0] = 1  # shared: nobody may repaint it in place


def test_colorize_and_nearest_class_round_trip():
    ids = np.array([[0, 1, 255], [13, 18, 40]])
    rgb = cs.colorize(ids)
    assert rgb.shape == (2, 3, 3) and tuple(rgb[0, 0]) == (128, 64, 128)
    assert tuple(rgb[0, 2]) == cs.IGNORE_RGB and tuple(rgb[1, 2]) == cs.IGNORE_RGB  # 255 and unknown -> black
    back = cs.nearest_class(rgb)
    assert back.tolist() == [[0, 1, 255], [13, 18, 255]]
    # a repainted colour a few levels off (JPEG, a paint program's blending) still maps to its class
    assert cs.nearest_class(np.array([131, 60, 125])) == 0


def test_report_uses_the_shared_palette():
    from twinkit import report

    assert np.array_equal(report.palette(), cs.lut())
    assert [n for n, _ in report.CITYSCAPES] == list(cs.NAMES)


def test_named_ids_and_groups():
    """Every trainId constant names its own class, and the groups hold the ids the callers relied on."""
    for i, name in enumerate(cs.NAMES):
        assert getattr(cs, name.upper().replace(" ", "_")) == i == cs.ID[name]
    assert cs.GROUND == (0, 1, 9)
    assert cs.MOVABLE == (11, 12, 13, 14, 15, 16, 17, 18)
    assert cs.WIDE_VEHICLES == (13, 14, 15, 16)
    assert cs.STREET_FURNITURE == (5, 6, 7)
    assert cs.name_of(13) == "car" and cs.name_of(cs.IGNORE) == "255"

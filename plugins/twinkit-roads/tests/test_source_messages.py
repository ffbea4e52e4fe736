"""Messages that know the source (issue 46): the road evidence, the alignment and the package name what the
network came from (an OSM extract, an OpenDRIVE file, the scan) and give the fix that fits it.

The source travels in the map's header (``twinkit.geo.xodr.source_kind``): road_source=scan tags its map,
road_source=opendrive its moved file, a netconvert of OSM carries no tag."""
from __future__ import annotations

import logging

import numpy as np
import pytest

from twinkit.geo.xodr import OPENDRIVE_TAG, SCAN_TAG, source_kind, tag_source

from test_road_evidence import run, write_inputs

TAGS = {"osm": None, "opendrive": OPENDRIVE_TAG, "scan": SCAN_TAG}


def tagged(inputs: dict, kind: str) -> dict:
    path = inputs["in_aligned_xodr"]
    if TAGS[kind]:
        path.write_text(tag_source(path.read_text(), TAGS[kind]))
    assert source_kind(path.read_text()) == kind
    return inputs


def test_source_kind_reads_the_header_tag():
    text = '<OpenDRIVE><header revMajor="1"/><road/></OpenDRIVE>'
    assert source_kind(None) == "none" and source_kind(text) == "osm"
    assert source_kind(tag_source(text, SCAN_TAG)) == "scan"
    once = tag_source(tag_source(text, OPENDRIVE_TAG), OPENDRIVE_TAG)
    assert source_kind(once) == "opendrive" and once.count(OPENDRIVE_TAG) == 1


@pytest.mark.parametrize("kind,says,not_says", [
    ("scan", ["road_source=scan", "road labels"], ["OSM, or", "outdated"]),
    ("opendrive", ["road_source=opendrive", "geoReference"], ["outdated OSM"]),
    ("osm", ["OpenStreetMap", "outdated OSM"], ["road_source=scan"]),
])
def test_the_network_veto_names_the_source_and_its_fix(tmp_path, caplog, kind, says, not_says):
    """A network shifted 1.5 m off its carriageway is vetoed; the warning was 'a wrong or outdated OSM, or a
    failed alignment?' for every source, the scan's own network included."""
    with caplog.at_level(logging.WARNING):
        _, doc, _ = run(tmp_path, tagged(write_inputs(tmp_path, dy=-1.5), kind))
    assert doc["network_vetoed"]
    veto = [r.getMessage() for r in caplog.records if "disagree with the scan's ground" in r.getMessage()]
    assert len(veto) == 1, caplog.text
    assert all(s in veto[0] for s in says) and not any(s in veto[0] for s in not_says), veto[0]


@pytest.mark.parametrize("kind,says", [("osm", "the OSM extract"), ("opendrive", "geoReference and offset")])
def test_no_overlap_names_the_fix_of_the_source(kind, says):
    """A network that finds no road surface: the fix named fits its source (was 'check the georeference, or
    raise align search_m' for every source)."""
    from twinkit import InputError
    from twinkit_roads.align import fit_or_keep

    sec, mask, grid = _mask_and_sections()
    with pytest.raises(InputError) as exc:
        fit_or_keep(sec, mask, grid, source=kind, log=logging.getLogger("t"), search_m=2.0)
    assert says in str(exc.value) and "steps.align_roads.search_m" in str(exc.value), exc.value


def test_the_scans_own_network_is_not_told_to_check_the_georeference(caplog):
    from twinkit_roads.align import fit_or_keep

    sec, mask, grid = _mask_and_sections()
    with caplog.at_level(logging.WARNING):
        res = fit_or_keep(sec, mask, grid, source="scan", log=logging.getLogger("t"), search_m=8.0)
    assert res.kept_identity
    assert "needs no alignment" in caplog.text
    assert "georeference" not in caplog.text and "search_m" not in caplog.text, caplog.text


def _mask_and_sections():
    from test_road_evidence import xodr
    from twinkit_roads.align import sample_sections
    from twinkit_roads.mesh2d import Grid

    grid = Grid.around(np.array([[-10.0, -20.0], [60.0, 30.0]]), 0.25)
    mask = np.zeros((grid.h, grid.w), bool)
    return sample_sections(xodr(0.0), 1.0), mask, grid


def test_road_source_opendrive_tags_its_map(tmp_path):
    """The moved file says it came from an OpenDRIVE file, through osm_to_opendrive's check, to the steps after."""
    from twinkit.testing import plugin_from_module, run_step

    import twinkit_roads.plugin as roads
    from test_opendrive_source import SWEREF_SITE, need_xodr, source

    out = source(tmp_path, need_xodr("soderleden.xodr"), SWEREF_SITE)
    assert source_kind(out["opendrive.xodr"].read_text()) == "opendrive"
    chk = run_step(plugin_from_module(roads, "step", "osm_to_opendrive"), tmp_path / "check",
                   {"in_opendrive_xodr": out["opendrive.xodr"]}, roads.ConvertParams(check_radius_m=1000),
                   site=SWEREF_SITE)
    assert source_kind(chk["roads.xodr"].read_text()) == "opendrive"

"""The road sources' preflight (issue 28): an OSM file that does not hold the site, a download with no
network and no cached answer, refused in seconds (before the meshing), one line each."""
from __future__ import annotations

import json
import socket

from conftest import DEMO_SITE

from twinkit_roads.preflight import file_preflight, osm_api_preflight, osm_file_bbox, overpass_preflight
from twinkit_roads.sources import OVERPASS_URL, DownloadParams, FileSourceParams, _bbox, _client, overpass_query


def _osm(path, lat0: float, lon0: float, bounds: bool = False):
    """A tiny OSM XML extract: one residential way of three nodes around (lat0, lon0)."""
    b = (f'<bounds minlat="{lat0 - 0.001}" minlon="{lon0 - 0.001}" maxlat="{lat0 + 0.001}" '
         f'maxlon="{lon0 + 0.001}"/>' if bounds else "")
    nodes = "".join(f'<node id="{i + 1}" version="1" lat="{lat0 + 0.0005 * i}" lon="{lon0 + 0.0005 * i}"/>'
                    for i in range(3))
    path.write_text(f'<?xml version="1.0"?><osm version="0.6" generator="test">{b}{nodes}'
                    '<way id="1" version="1"><nd ref="1"/><nd ref="2"/><nd ref="3"/>'
                    '<tag k="highway" v="residential"/></way></osm>')
    return path


def test_osm_file_that_does_not_hold_the_site_is_refused(tmp_path):
    far = _osm(tmp_path / "elsewhere.osm", 48.136, 10.07)  # Bavaria, for a site in Helsinki
    probs = file_preflight(DEMO_SITE, FileSourceParams(), {"in_osm": far})
    assert len(probs) == 1 and "elsewhere.osm covers lat 48.13" in probs[0], probs
    assert "base point (lat 60.169450, lon 24.933650" in probs[0] and "road_source=none" in probs[0]
    here = _osm(tmp_path / "here.osm", 60.1692, 24.9334, bounds=True)  # the header's box holds the base point
    assert osm_file_bbox(here)[0] == 60.1682
    assert file_preflight(DEMO_SITE, FileSourceParams(), {"in_osm": here}) == []


def test_no_osm_file_names_the_choices(tmp_path):
    probs = file_preflight(DEMO_SITE, FileSourceParams(), {})
    assert len(probs) == 1 and "site.inputs.osm=" in probs[0] and "road_source=none" in probs[0]
    # the demo's roads.osm is written by the site generator: nothing to check before it runs
    assert file_preflight(DEMO_SITE, FileSourceParams(), {"in_roads_osm": None}) == []
    probs = file_preflight(DEMO_SITE, FileSourceParams(path=str(tmp_path / "nope.osm.pbf")), {})
    assert len(probs) == 1 and "nope.osm.pbf: no such file" in probs[0]


def _closed_port() -> int:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()  # nothing listens there now: a connection is refused at once
    return port


def test_download_without_network_is_refused_unless_cached(tmp_path):
    url = f"http://127.0.0.1:{_closed_port()}/api/interpreter"
    params = DownloadParams(url=url, cache_dir=str(tmp_path / "cache"))
    probs = overpass_preflight(DEMO_SITE, params, {})
    assert len(probs) == 1 and "road_source=overpass: cannot connect to 127.0.0.1" in probs[0], probs
    assert "no cached answer" in probs[0] and "road_source=file" in probs[0] and "road_source=none" in probs[0]
    assert len(osm_api_preflight(DEMO_SITE, params, {})) == 1
    # an answer in the cache serves the step offline: no refusal
    client = _client(params)
    data = {"data": overpass_query(_bbox(params, DEMO_SITE), params.timeout_s)}
    key = client._key("POST", url, None, data)
    client.cache_dir.mkdir(parents=True)
    (client.cache_dir / f"{key}.body").write_bytes(b"<osm/>")
    (client.cache_dir / f"{key}.json").write_text(json.dumps({"url": url}))
    assert overpass_preflight(DEMO_SITE, params, {}) == []
    assert OVERPASS_URL.startswith("https://")

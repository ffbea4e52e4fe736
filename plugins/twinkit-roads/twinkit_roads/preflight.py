"""The road sources' preflight (twinkit/engine/preflight.py runs it before the first step): an OSM file
that does not cover the site, a download with no network and no cached answer, found in seconds
instead of after the meshing and the segmentation."""
from __future__ import annotations

import logging
import socket
from pathlib import Path
from urllib.parse import urlsplit

log = logging.getLogger("twinkit.preflight.roads")

#: a file larger than this without a bounding box in its header is not scanned here (the step checks it)
SCAN_MAX_BYTES = 300 * 1024 * 1024
CONNECT_TIMEOUT_S = 3.0
NO_ROADS_HINT = "or road_source=none for a twin without roads"


def georeference_preflight(site, params, inputs) -> list[str]:
    """Every road source places its network by the site's georeference: a site without ``site.crs`` /
    ``site.base_point`` is refused before the first step (was: after the meshing and the segmentation, when
    the source met it). The same line for every source, so that the default ``file`` and its fallback
    ``scan`` give it once."""
    from twinkit.geo.frame import georeference_problem

    problem = georeference_problem(site, "the road network (every road_source places it by the georeference)",
                                   NO_ROADS_HINT)
    return [problem] if problem else []


scan_preflight = opendrive_preflight = georeference_preflight


def osm_file_bbox(path: Path) -> tuple[float, float, float, float] | None:
    """(south, west, north, east) of an OSM file: the header's box, else its nodes' box (files up to
    SCAN_MAX_BYTES); None when unknown."""
    import osmium

    try:
        box = osmium.io.Reader(str(path), osmium.osm.osm_entity_bits.NOTHING).header().box()
        if box.valid():
            return box.bottom_left.lat, box.bottom_left.lon, box.top_right.lat, box.top_right.lon
    except Exception:  # noqa: BLE001 -- an unreadable header: the nodes decide, or the step reports it
        pass
    if path.stat().st_size > SCAN_MAX_BYTES:
        return None
    s = w = float("inf")
    n = e = float("-inf")
    for o in osmium.FileProcessor(str(path), osmium.osm.osm_entity_bits.NODE):
        if o.location.valid():
            lat, lon = o.location.lat, o.location.lon
            s, w, n, e = min(s, lat), min(w, lon), max(n, lat), max(e, lon)
    return (s, w, n, e) if s <= n else None


def _site_box(site, radius_m: float):
    from twinkit.geo import SiteFrame

    frame = SiteFrame.from_site(site)
    lon, lat = frame.local_to_lonlat([[0.0, 0.0]])[0]
    return frame.bbox_lonlat(radius_m), (lat, lon)


def file_preflight(site, params, inputs) -> list[str]:
    """``road_source=file``: the site has a georeference, an OSM file is given, exists and covers the site's box."""
    from .sources import site_radius

    no_georef = georeference_preflight(site, params, inputs)
    if no_georef:
        return no_georef

    if params.path:
        src = Path(params.path).expanduser()
        if not src.is_file():
            return [f"road_source.path={params.path}: no such file; give a .osm / .osm.bz2 / .osm.pbf extract, "
                    f"{NO_ROADS_HINT}"]
    else:
        src = inputs.get("in_osm") if "in_osm" in inputs else inputs.get("in_roads_osm")
        if "in_osm" not in inputs and "in_roads_osm" not in inputs:
            return ["road_source=file needs an OSM file: set site.inputs.osm=/path/to/area.osm.pbf or "
                    f"road_source.path=..., choose road_source=overpass / osm_api to download by box, {NO_ROADS_HINT}"]
        if src is None or not Path(src).is_file():
            return []  # written by an earlier step (the demo's generator), or missing (reported by the engine)
    src = Path(src)
    try:
        box = osm_file_bbox(src)
    except Exception as exc:  # noqa: BLE001 -- a corrupt file: fetch_roads's reader names the fault
        log.debug("%s: no bounds (%s: %s); fetch_roads reads and checks it", src.name, type(exc).__name__, exc)
        return []
    if box is None:
        log.info("%s: no bounding box in the header and too large to scan here; its cover is checked when "
                 "fetch_roads runs", src.name)
        return []
    try:
        (ss, sw, sn, se), (blat, blon) = _site_box(site, site_radius(site, -1.0))
    except Exception as exc:  # noqa: BLE001 -- no georeference: the step says so
        log.info("%s: coverage not checked (%s)", src.name, exc)
        return []
    s, w, n, e = box
    inter_h = max(0.0, min(n, sn) - max(s, ss))
    inter_w = max(0.0, min(e, se) - max(w, sw))
    share = inter_h * inter_w / max((sn - ss) * (se - sw), 1e-18)
    box_text = f"lat {s:.5f}..{n:.5f}, lon {w:.5f}..{e:.5f}"
    log.info("%s covers %s; the site's box around the base point (lat %.6f, lon %.6f): %.0f %% of it inside",
             src.name, box_text, blat, blon, 100 * share)
    if not (s <= blat <= n and w <= blon <= e):
        return [f"{src.name} covers {box_text}, which does not hold the site's base point (lat {blat:.6f}, lon "
                f"{blon:.6f}; {100 * share:.0f} % of the site's box inside): give an extract around the site, "
                f"check site.base_point, {NO_ROADS_HINT}"]
    if share < 0.999:
        log.warning("%s covers only %.0f %% of the site's box; roads beyond its edge are missing", src.name,
                    100 * share)
    return []


def _reachable(url: str) -> str | None:
    """None when a TCP connection to the URL's host opens within CONNECT_TIMEOUT_S, else why not."""
    u = urlsplit(url)
    host, port = u.hostname or "", u.port or (443 if u.scheme == "https" else 80)
    try:
        with socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S):
            return None
    except OSError as exc:
        return f"cannot connect to {host}:{port} within {CONNECT_TIMEOUT_S:g} s ({exc.strerror or exc})"


def _download_preflight(name: str, url: str, method: str, request: dict, params) -> list[str]:
    from .sources import _client

    client = _client(params)
    hit = client.cached(method, url, **request)
    if hit is not None:
        log.info("road_source=%s: a cached answer for this box (%s); no network needed", name, hit.name)
        return []
    why = _reachable(url)
    if why is None:
        return []
    return [f"road_source={name}: {why}, and no cached answer for this box in {client.cache_dir}: connect to the "
            f"network, or give a local extract (road_source=file site.inputs.osm=/path/area.osm.pbf), {NO_ROADS_HINT}"]


def overpass_preflight(site, params, inputs) -> list[str]:
    """``road_source=overpass``: the site has a georeference; a cached answer or a server that answers."""
    from .sources import OVERPASS_URL, _bbox, overpass_query

    no_georef = georeference_preflight(site, params, inputs)
    if no_georef:
        return no_georef

    url = params.url or OVERPASS_URL
    return _download_preflight("overpass", url, "POST",
                               {"data": {"data": overpass_query(_bbox(params, site), params.timeout_s)}}, params)


def osm_api_preflight(site, params, inputs) -> list[str]:
    """``road_source=osm_api``: the site has a georeference; a cached answer or a server that answers."""
    from .sources import OSM_API_URL, _bbox

    no_georef = georeference_preflight(site, params, inputs)
    if no_georef:
        return no_georef

    s, w, n, e = _bbox(params, site)
    url = params.url or OSM_API_URL
    return _download_preflight("osm_api", url, "GET", {"params": {"bbox": f"{w:.7f},{s:.7f},{e:.7f},{n:.7f}"}},
                               params)

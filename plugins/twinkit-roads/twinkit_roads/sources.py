"""Road sources: where the OpenStreetMap data for a site comes from.

Every source writes one OSM XML file (``osm.osm``) holding the site's roads, and
fails with an InputError naming the cause when the data hold no roads.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from twinkit import InputError
from twinkit import artefacts as A
from twinkit.geo import SiteFrame, check_bbox
from twinkit.ranges import param

from .osmio import OsmData, crop, looks_like_osm_xml, read_osm, write_osm_xml


@dataclass
class FileSourceParams:
    path: str = param("", path=True,
                      help="A local .osm, .osm.bz2 or .osm.pbf file; empty = the step's input (site.inputs.osm, or "
                           "a generated roads.osm).")
    crop_radius_m: float = param(-1.0,
                                 help="Crop the file around the base point: < 0 = the site box (site.osm_radius_m, "
                                      "default 150 m) plus crop_margin_m; 0 = keep the whole file; > 0 = a box of "
                                      "this half side (m).")
    crop_margin_m: float = param(150.0, ge=0,
                                 help="Margin (m) added to the site box when crop_radius_m < 0, so that the ways "
                                      'reaching into the site are kept whole (docs/roads.md "Crop first").')


@dataclass
class OpenDriveSourceParams:
    path: str = param("", path=True, help="The .xodr file; empty = the site's input (site.inputs.xodr=/path/map.xodr).")
    georeference: str = param("",
                              help="The map's frame when it has no (or a wrong) <geoReference>: a PROJ string or an "
                                   "EPSG code; \"site\" = already in the site frame; empty = the map's own "
                                   "<geoReference>.")
    heights: str = param("datum", choices=("datum", "keep"),
                         help="datum: the map's z are heights in the site's vertical datum (z - the base point's "
                              "altitude); keep: leave them unchanged.")
    max_residual_m: float = param(0.01, gt=0,
                                  help="Largest distance (m) allowed at a lane centre between the similarity that "
                                       "moves the map into the site frame and the exact pyproj transform.")
    sample_step_m: float = param(2.0, gt=0, help="Spacing (m) of the lane-centre samples of that residual check.")


@dataclass
class DownloadParams:
    url: str = param("", help="Server URL; empty = the source's public default.")
    radius_m: float = param(-1.0, gt=0, also=(-1,),
                            help="Half side (m) of the box around the base point to download; -1 = "
                                 "site.osm_radius_m (default 150).")
    bbox: str = param("",
                      help='An explicit box "south,west,north,east" (degrees) instead of a box around the base '
                           "point.")
    timeout_s: float = param(60.0, gt=0, help="Timeout (s) of each read (connecting: at most 15 s).")
    deadline_s: float = param(120.0, gt=0,
                              help="Limit (s) of the whole download, retries included (a trickling server cannot "
                                   "stall the run).")
    retries: int = param(3, ge=0, le=100, help="Retries after a failed request.")
    backoff_s: float = param(2.0, ge=0, help="Wait (s) before the first retry; it doubles with each further retry.")
    user_agent: str = param("",
                            help="HTTP User-Agent; empty = twinkit-roads/<version> (+ the project URL). Public "
                                 "servers require a real one.")
    cache_dir: str = param("", help="Where downloads are cached; empty = $XDG_CACHE_HOME/twinkit/osm.")
    cache_max_age_days: float = param(30.0, ge=0, help="A cached download older than this (days) is fetched again.")


def site_radius(site, radius_m: float) -> float:
    if radius_m is not None and radius_m > 0:
        return float(radius_m)
    return float((site or {}).get("osm_radius_m", 150.0) or 150.0)


def _bbox(params: DownloadParams, site) -> tuple[float, float, float, float]:
    if params.bbox.strip():
        try:
            s, w, n, e = (float(v) for v in params.bbox.split(","))
        except ValueError:
            raise InputError(f"road_source.bbox='{params.bbox}' must be 'south,west,north,east' in degrees") from None
        return check_bbox(s, w, n, e)
    frame = SiteFrame.from_site(site)  # InputError when the site has no georeference
    return frame.bbox_lonlat(site_radius(site, params.radius_m))


def finish(data: OsmData, out: Path, where: str, bbox=None, write_bbox: bool = True) -> dict:
    """Write ``data`` to ``out`` after checking it has roads (``<bounds>``: ``bbox``, or the data's own)."""
    counts = data.count()
    if counts["highway_ways"] == 0:
        box = f" in the box {tuple(round(v, 6) for v in bbox)}" if bbox else ""
        raise InputError(f"{where}: no roads (no highway=* ways){box}; {counts['ways']} ways, {counts['nodes']} nodes. "
                         "Check the base point and osm_radius_m, or give a file that covers the site")
    write_osm_xml(data, out, bbox if write_bbox else None)
    return counts


def file_source(params: FileSourceParams, ctx, *, out_osm_osm: Path, in_osm: Path | None = None,
                in_roads_osm: Path | None = None) -> dict:
    """Roads from a local OSM file (.osm, .osm.bz2, .osm.pbf), optionally cropped around the base point.

    Which file: ``road_source.path``, else the site input ``osm`` (site.inputs.osm), else a
    ``roads.osm`` written by an earlier step (the demo site generator).
    """
    roads_osm = A.read_osm(in_roads_osm) if in_roads_osm is not None else None  # the demo site's, checked
    src = Path(params.path).expanduser() if params.path else (in_osm or roads_osm)
    if src is None:
        raise InputError("road_source=file needs an OSM file: set site.inputs.osm=/path/to/area.osm.pbf or "
                         "road_source.path=..., or choose road_source=overpass / osm_api to download by box")
    t0 = time.perf_counter()
    data = read_osm(Path(src))
    t_read = time.perf_counter() - t0
    bbox, radius = None, 0.0
    ways_in = len(data.ways)
    if params.crop_radius_m != 0:
        radius = (params.crop_radius_m if params.crop_radius_m > 0
                  else site_radius(ctx.site, -1.0) + max(params.crop_margin_m, 0.0))
        bbox = SiteFrame.from_site(ctx.site).bbox_lonlat(radius)
        data = crop(data, bbox)
    t_crop = time.perf_counter() - t0 - t_read
    # an explicit crop_radius_m writes its box as the file's <bounds> (as before); the automatic one the data's
    counts = finish(data, out_osm_osm, str(src), bbox, write_bbox=params.crop_radius_m > 0)
    t_write = time.perf_counter() - t0 - t_read - t_crop
    crop_note = f", cropped to {radius:g} m around the base point ({ways_in} -> {counts['ways']} ways)" if bbox else ""
    ctx.log.info("read %s: %d highway ways, %d traffic signals%s; read %.2f s, crop %.2f s, write %.2f s",
                 Path(src).name, counts["highway_ways"], counts["traffic_signals"], crop_note, t_read, t_crop,
                 t_write)
    return {"source": str(src), **counts, "crop_half_side_m": radius, "ways_before_crop": ways_in,
            "read_s": round(t_read, 3), "crop_s": round(t_crop, 3), "write_s": round(t_write, 3)}


def _validate(body: bytes) -> str | None:
    if not looks_like_osm_xml(body):
        return "the answer is not OSM XML: " + body[:200].decode("utf-8", "replace").strip()
    if b"<remark>" in body[:100000] and b"runtime error" in body[:100000]:
        return "the server reported an error: " + body.split(b"<remark>")[1].split(b"</remark>")[0].decode()[:300]
    return None


def _client(params: DownloadParams):
    from .http import CachedHttp

    return CachedHttp(cache_dir=params.cache_dir or None, timeout_s=params.timeout_s, retries=params.retries,
                      backoff_s=params.backoff_s, user_agent=params.user_agent, max_age_days=params.cache_max_age_days,
                      deadline_s=params.deadline_s)


def _store(body: bytes, ctx, out: Path, where: str, bbox, res) -> dict:
    raw = out.with_suffix(".download.osm")
    raw.write_bytes(body)
    try:
        data = read_osm(raw)
    finally:
        raw.unlink(missing_ok=True)
    counts = finish(data, out, where, bbox)
    ctx.log.info("%s: %d highway ways (%s)", where, counts["highway_ways"], "cache" if res.from_cache else "downloaded")
    return {"url": res.url, "bbox": list(bbox), "from_cache": res.from_cache, "attempts": res.attempts, **counts}


OSM_API_URL = "https://api.openstreetmap.org/api/0.6/map"
OVERPASS_URL = "https://overpass-api.de/api/interpreter"


def osm_api_source(params: DownloadParams, ctx, *, out_osm_osm: Path) -> dict:
    """Everything in a box from the OpenStreetMap editing API (``/api/0.6/map?bbox=``; at most 0.25 square degrees)."""
    s, w, n, e = bbox = _bbox(params, ctx.site)
    if (n - s) * (e - w) > 0.25:
        raise InputError(f"box {bbox} is larger than the OSM API's 0.25 square degrees; use road_source=overpass")
    url = params.url or OSM_API_URL
    res = _client(params).request("GET", url, params={"bbox": f"{w:.7f},{s:.7f},{e:.7f},{n:.7f}"}, validate=_validate)
    return _store(res.body, ctx, out_osm_osm, url, bbox, res)


def overpass_query(bbox, timeout_s: float) -> str:
    s, w, n, e = bbox
    b = f"{s:.7f},{w:.7f},{n:.7f},{e:.7f}"
    return (f"[out:xml][timeout:{int(max(timeout_s, 25))}];"
            f"(way[\"highway\"]({b});node[\"highway\"]({b});relation[\"type\"=\"restriction\"]({b}););"
            "(._;>;);out body;")


def overpass_source(params: DownloadParams, ctx, *, out_osm_osm: Path) -> dict:
    """Roads in a box from an Overpass API server (highway ways, their nodes, turn restrictions)."""
    bbox = _bbox(params, ctx.site)
    url = params.url or OVERPASS_URL
    res = _client(params).request("POST", url, data={"data": overpass_query(bbox, params.timeout_s)},
                                  validate=_validate)
    return _store(res.body, ctx, out_osm_osm, url, bbox, res)


def opendrive_source(params, ctx, *, out_opendrive_xodr: Path, out_reprojection_json: Path,
                     in_xodr: Path | None = None) -> dict:
    """An existing OpenDRIVE map (``road_source.path``, else the site input ``xodr``) moved from its
    ``<geoReference>`` into the site frame (reproject.py); ``osm_to_opendrive`` then checks it."""
    from twinkit.geo.xodr import OPENDRIVE_TAG, tag_source

    from .reproject import to_site_frame, write_report

    src = Path(params.path).expanduser() if params.path else in_xodr
    if src is None:
        raise InputError("road_source=opendrive needs an OpenDRIVE file: set site.inputs.xodr=/path/to/map.xodr or "
                         "road_source.path=/path/to/map.xodr")
    frame = SiteFrame.from_site(ctx.site)
    text, rep = to_site_frame(Path(src), frame, params, ctx.log)
    # tagged, so that later steps name the file, not OSM, when the network does not fit (source_kind)
    out_opendrive_xodr.write_text(tag_source(text, OPENDRIVE_TAG), encoding="utf-8")
    write_report(rep, out_reprojection_json)
    return {"source": str(src), "residual_max_m": round(rep["residual_max_m"], 6),
            "scale": rep["similarity"]["scale"], "rotation_deg": rep["similarity"]["rotation_deg"],
            "lane_centres": rep["lane_centres"], "identity": rep["similarity"]["identity"]}



def scan_source(params, ctx, *, in_textured_mesh_ply: Path, out_opendrive_xodr: Path,
                out_scan_roads_json: Path, out_scan_roads_png: Path, in_labels_npy: Path | None = None,
                in_gt_labels_npy: Path | None = None, in_roads_truth_json: Path | None = None,
                in_points_meta_json: Path | None = None, in_points_ply: Path | None = None) -> dict:
    """Roads from the scan itself (no OSM): the labelled mesh's carriageway, curbs and sidewalks ->
    lanes -> OpenDRIVE in the site frame (``opendrive.xodr``, checked by osm_to_opendrive like a map)."""
    import json

    from twinkit import artefacts as A

    from .scan import (NoRoads, ScanSourceParams, build_network, choose_curbs, cloud_sampling, cloud_xy,
                       draw_scan_roads, level_params, mark_source, read_labels, read_truth, scan_metrics, scan_report)

    params = params or ScanSourceParams()
    t0 = time.perf_counter()
    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    which, src, labels = read_labels(params.labels, len(mesh.vertices), in_textured_mesh_ply.name, in_labels_npy,
                                     in_gt_labels_npy, ctx.log)
    spacing, two_way = cloud_sampling(in_points_meta_json, in_points_ply)
    labels_for_mask, curbs = choose_curbs(labels, spacing, params, src, ctx.log)
    params = level_params(params, labels_for_mask, curbs, two_way, ctx.log)
    use_cloud = not curbs and in_points_ply is not None and params.min_point_density > 0
    points_xy = cloud_xy(in_points_ply) if use_cloud else None
    frame = SiteFrame.from_site(ctx.site)
    try:
        net, info = build_network(mesh, labels_for_mask, labels, params, frame.proj_string(), out_opendrive_xodr,
                                  ctx.log, curbs=curbs, spacing=spacing, points_xy=points_xy)
    except NoRoads as exc:
        return _scan_no_roads(exc, ctx, mesh, labels, which, frame, out_opendrive_xodr, out_scan_roads_json,
                              out_scan_roads_png, t0)
    text = mark_source(out_opendrive_xodr.read_text(encoding="utf-8"))
    out_opendrive_xodr.write_text(text, encoding="utf-8")
    truth = read_truth(in_roads_truth_json)
    doc = scan_report(net, text, mesh, labels, which, src, info, params, truth)
    doc["ground_two_way_share"] = two_way
    draw_scan_roads(mesh.vertices, mesh.faces, labels, net, text, out_scan_roads_png, truth=truth)
    doc["total_s"] = round(time.perf_counter() - t0, 3)
    out_scan_roads_json.write_text(json.dumps(doc, indent=1))
    return scan_metrics(net, doc, which, params, ctx.log)


def _scan_no_roads(exc, ctx, mesh, labels, which, frame, out_xodr: Path, out_json: Path, out_png: Path,
                   t0: float) -> dict:
    """No road in the scan: a map without roads, so the twin goes on without a road network (the exports and
    the CARLA package without a map, as with road_source=none). Roads derived and then all dropped by the
    checks (the scan shows carriageway, none of it held up) make the run degraded; a scan with no carriageway
    at all (a park, a yard) is a twin without roads, said in a warning."""
    import json

    from .scan import draw_scan_roads, empty_map, empty_network, no_roads_report

    out_xodr.write_text(empty_map(frame.proj_string()), encoding="utf-8")
    why = str(exc)
    draw_scan_roads(mesh.vertices, mesh.faces, labels, empty_network(), out_xodr.read_text(encoding="utf-8"), out_png,
                    note=f"no roads: {why}")
    doc, metrics = no_roads_report(exc, which)
    doc["total_s"] = metrics["total_s"] = round(time.perf_counter() - t0, 3)
    out_json.write_text(json.dumps(doc, indent=1))
    ctx.log.warning("road_source=scan: no roads: %s. The twin has no road network (the CARLA package has no map); "
                    "give an OSM extract (site.inputs.osm) for one", why)
    if exc.derived:
        ctx.degraded(f"roads from the scan: none kept ({why})",
                     "see scan_roads.png; give an OSM extract (site.inputs.osm) for the map")
    return metrics

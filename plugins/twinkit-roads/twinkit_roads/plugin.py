"""twinkit-roads: road sources, OSM -> OpenDRIVE, alignment to the mesh, QA picture.

Steps (recipes/roads_demo.yaml):
  fetch_roads     road_source (file | osm_api | overpass)   -> osm.osm
                  road_source=opendrive                     -> opendrive.xodr (site frame), reprojection.json
                  road_source=scan (the labelled mesh)      -> opendrive.xodr, scan_roads.json, scan_roads.png
  osm_to_opendrive                                          -> roads.xodr, roads_check.json
  roads_overview  top view of the network (recipe roads)   -> roads_overview.png
  carla_roads     the map in CARLA's frame (recipe roads)   -> roads_carla.xodr, carla_geolocation.json
  align_roads     fit the network to the mesh's road surface -> alignment.json  (edit it to override)
  apply_alignment move the OpenDRIVE, draw the QA picture    -> aligned.xodr, roads_qa.png
  parking_lanes   parking lanes where OSM or the scan has them -> aligned.xodr (again), parking.json
  place_signals   signals at the scanned lights and signs   -> aligned.xodr (again), signals.json, signals.png
  place_crosswalks OSM crossings + the scan's zebras        -> aligned.xodr (again), crosswalks.json
  road_evidence   the lanes vote for road / sidewalk        -> labels.npy (again), road_evidence.json, .png
"""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

from twinkit import InputError, hookimpl
from twinkit import artefacts as A
from twinkit.geo.xodr import SOURCE_NAMES, source_hint, source_kind
from twinkit.geo.xodr import from_scan as from_scan_tag

from . import __version__
from .convert import ConvertParams
from .params import (AlignParams, ApplyParams, CarlaMapParams, CrosswalkParams, OverviewParams,  # noqa: F401 (re-exported)
                     ParkingParams, RoadEvidenceParams, SignalParams)
from .report import twinkit_register_report_sections  # noqa: F401 (this plugin's sections of the run report)
from .sources import (DownloadParams, FileSourceParams, OpenDriveSourceParams, file_source, opendrive_source, osm_api_source, overpass_source,
                      scan_source, site_radius)


def _source_version() -> str:
    """Distribution version + a digest of every module of the package, so that a change in a helper
    module (not only in this file, which the engine hashes) makes the steps run again."""
    import hashlib

    h = hashlib.sha256()
    root = Path(__file__).parent
    for f in sorted(root.rglob("*.py"), key=lambda f: f.relative_to(root).as_posix()):  # the scan/ package too
        h.update(f.relative_to(root).as_posix().encode() + f.read_bytes())
    return f"{__version__}+src.{h.hexdigest()[:12]}"


VERSION = _source_version()


def _bounds(site, radius_m: float) -> tuple[float, float, float, float]:
    r = site_radius(site, radius_m)
    return (-r, -r, r, r)


def _xodr_box(text: str, margin_m: float = 10.0) -> tuple[float, float, float, float]:
    """The box of an OpenDRIVE map's plan-view geometry starts (site frame), ``margin_m`` wider."""
    import re

    import numpy as np

    xy = np.array([(float(a), float(b)) for a, b in
                   re.findall(r'<geometry [^>]*?x="([-0-9.eE+]+)" y="([-0-9.eE+]+)"', text)])
    if not len(xy):
        return (-margin_m, -margin_m, margin_m, margin_m)
    lo, hi = xy.min(0) - margin_m, xy.max(0) + margin_m
    return (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))


def osm_to_opendrive(params: ConvertParams, ctx, *, out_roads_xodr: Path, out_roads_check_json: Path,
                     in_osm_osm: Path | None = None, in_opendrive_xodr: Path | None = None) -> dict:
    """Convert with netconvert into the site frame, then check with carla.Map offline.

    With ``opendrive.xodr`` from road_source=opendrive (already moved into the site frame) there is
    nothing to convert: the map is only checked, and written as roads.xodr like a converted one."""
    from .convert import check_xodr, netconvert_version, run_netconvert, way_type_message, xodr_counts
    from twinkit.geo import SiteFrame

    frame = SiteFrame.from_site(ctx.site)
    proj = frame.proj_string()
    t0 = time.perf_counter()
    if in_opendrive_xodr is not None:
        if in_osm_osm is not None:
            ctx.log.info("road_source gave an OpenDRIVE map: %s is not converted", in_osm_osm.name)
        text = Path(in_opendrive_xodr).read_text(encoding="utf-8")
        out_roads_xodr.write_text(text, encoding="utf-8")
        if from_scan_tag(text):
            info = {"source": "scan", "netconvert_s": 0.0}
            conv = "none: road_source=scan (derived from the scan and converted there, see scan_roads.json)"
        else:
            info = {"source": "opendrive", "netconvert_s": 0.0}
            conv = "none: road_source=opendrive (the map moved into the site frame, see reprojection.json)"
    elif in_osm_osm is not None:
        info = run_netconvert(in_osm_osm, out_roads_xodr, proj, params, ctx.log)
        text = out_roads_xodr.read_text(encoding="utf-8")
        conv = netconvert_version()
    else:
        raise InputError("osm_to_opendrive needs osm.osm (road_source=file, osm_api or overpass) or opendrive.xodr "
                         "(road_source=opendrive) from the fetch_roads step before it")
    counts = xodr_counts(text)
    from .scan import is_empty_map

    if counts["roads"] == 0 and in_opendrive_xodr is not None and is_empty_map(text):
        # road_source=scan found no road: a twin without a road network (scan_roads.json says why)
        report = {"ok": True, "no_roads": True, "source": "scan", "proj": proj, "site_frame": frame.to_json(),
                  **counts, "note": "the scan holds no road (scan_roads.json): no map to check"}
        out_roads_check_json.write_text(json.dumps(report, indent=1))
        ctx.log.warning("no roads: the scan holds none (see scan_roads.json); the twin has no road network")
        return {"roads": 0, "junctions": 0, "traffic_lights": 0, "waypoints": 0, "waypoints_inside": 0,
                "conversion_s": round(time.perf_counter() - t0, 3), "netconvert_s": 0.0, "check_s": 0.0,
                "no_roads": True}
    if counts["roads"] == 0:
        if in_opendrive_xodr is not None:
            raise InputError(f"{in_opendrive_xodr}: no roads in the OpenDRIVE map; check the road source's file")
        raise InputError(f"netconvert produced no roads from {in_osm_osm.name}: "
                         + way_type_message(in_osm_osm, params.way_types))
    from_scan = info.get("source") == "scan"
    # a network derived from the scan lies on the scan by construction, wherever the cloud sits in the site
    # frame (a local-frame cloud may lie a kilometre from the base point): its own extent is the box
    bounds = _xodr_box(text) if from_scan else _bounds(ctx.site, params.check_radius_m)
    t1 = time.perf_counter()
    chk = check_xodr(out_roads_xodr, bounds, params.step_m)
    check_s = time.perf_counter() - t1
    total = time.perf_counter() - t0
    # one street scanned end to end is one road with no junction: carla.Map gives it no topology segment
    # (nothing links to it), and its lanes are still there to drive
    ok = ((chk["topology_segments"] > 0 or from_scan) and chk["waypoints_inside"] >= params.min_waypoints_inside)
    report = {"ok": ok, "netconvert": conv, "netconvert_args": "see roads.xodr header comment",
              "proj": proj, "site_frame": frame.to_json(), "bounds_local": bounds, **info, **counts,
              "carla": chk, "check_s": round(check_s, 3), "conversion_s": round(total, 3)}
    out_roads_check_json.write_text(json.dumps(report, indent=1))
    if not ok:
        raise InputError(_not_covered(out_roads_xodr.name, in_opendrive_xodr, text, frame, chk, bounds,
                                      params.min_waypoints_inside))
    ctx.log.info("%d roads, %d junctions, %d traffic lights; carla.Map: %d waypoints (%d inside the site); "
                 "netconvert %.2f s, check %.2f s, total %.2f s", counts["roads"], counts["junctions"],
                 counts["traffic_lights"], chk["waypoints"], chk["waypoints_inside"], info["netconvert_s"], check_s,
                 total)
    return {"roads": counts["roads"], "junctions": counts["junctions"], "traffic_lights": counts["traffic_lights"],
            "waypoints": chk["waypoints"], "waypoints_inside": chk["waypoints_inside"],
            "conversion_s": round(total, 3), "netconvert_s": info["netconvert_s"], "check_s": round(check_s, 3)}


def _not_covered(name: str, in_opendrive_xodr: Path | None, text: str, frame, chk: dict, bounds, need: int) -> str:
    """The message of a map that does not cover the site: what carla.Map found, and where the map's roads landed."""
    import re

    from twinkit.geo.carla import landed_text

    xy = [(float(a), float(b)) for a, b in re.findall(r'<geometry [^>]*?x="([-0-9.eE+]+)" y="([-0-9.eE+]+)"', text)]
    where = f" (its roads landed at {landed_text(frame, xy)})" if xy else ""
    what = (f"the OpenDRIVE map ({in_opendrive_xodr.name}) does not cover the site{where}: check site.base_point and "
            "the map's geoReference (its +x_0/+y_0 and +lat_0/+lon_0)" if in_opendrive_xodr is not None
            else f"the OSM data do not cover the site{where}")
    return (f"{name}: carla.Map found {chk['topology_segments']} topology segments and {chk['waypoints_inside']} "
            f"waypoints inside the site box {bounds} (need {need}); {what}")


def roads_overview(params: OverviewParams, ctx, *, in_roads_xodr: Path, out_roads_overview_png: Path,
                   in_roads_check_json: Path | None = None) -> dict:
    """The road network seen from above, without any mesh: lanes by type, centre lines, the site box."""
    from .qa import draw_network

    params = params or OverviewParams()
    text = in_roads_xodr.read_text(encoding="utf-8")
    bounds = None
    title = in_roads_xodr.name
    if in_roads_check_json is not None:
        chk = json.loads(in_roads_check_json.read_text())
        bounds = tuple(chk.get("bounds_local") or ()) or None
        title = (f"{chk.get('roads', '?')} roads, {chk.get('junctions', '?')} junctions, "
                 f"{chk.get('traffic_lights', '?')} traffic lights")
    try:
        info = draw_network(text, out_roads_overview_png, bounds, params.px_per_m, params.max_px, title)
    except ValueError as exc:
        raise InputError(f"{in_roads_xodr}: {exc}; carla.Map finds no lanes (check osm_to_opendrive)") from None
    ctx.log.info("roads_overview.png: %d lane segments (%s), %d x %d px", info["lane_segments"],
                 ", ".join(f"{k} {v}" for k, v in info["lane_types"].items()), *info["px"])
    return {"lane_segments": info["lane_segments"], "m_per_px": info["m_per_px"]}


def carla_roads(params: CarlaMapParams, ctx, *, in_roads_xodr: Path, out_roads_carla_xodr: Path,
                out_carla_geolocation_json: Path) -> dict:
    """roads.xodr (site frame) -> roads_carla.xodr in the CARLA package's frame, the one CARLA geolocates; CARLA's
    geolocation error measured with the carla wheel at the map's lane centres (carla_geolocation.json)."""
    from .carla_map import carla_map, write_doc

    params = params or CarlaMapParams()
    text, doc = carla_map(in_roads_xodr.read_text(encoding="utf-8"), ctx.site, params, in_roads_xodr.name, ctx.log)
    out_roads_carla_xodr.write_text(text, encoding="utf-8")
    write_doc(doc, out_carla_geolocation_json)
    w = doc["wheel"]
    return {"carla_error_max_m": round(w["carla_error_max_m"], 4), "carla_error_mean_m": round(w["carla_error_mean_m"], 4),
            "points": w["points"], "scale": doc["frame"]["scale"], "rotation_deg": doc["frame"]["rotation_deg"]}


def align_roads(params: AlignParams, ctx, *, in_roads_xodr: Path, in_textured_mesh_ply: Path,
                out_alignment_json: Path, in_labels_npy: Path | None = None) -> dict:
    """Rigid 2D fit (yaw, translation) of the network to the road surface (labels) or the ground (align.py),
    then onto the kerbs (kerbs.py)."""
    from .align import alignment_doc, alignment_metrics, fit_or_keep, no_roads_alignment, sample_sections, surface_dz
    from .kerbs import kerb_correction
    from .mesh2d import Grid, road_faces, road_mask
    from .scan import is_empty_map

    xodr_text = in_roads_xodr.read_text(encoding="utf-8")
    if is_empty_map(xodr_text):  # road_source=scan found no road
        out_alignment_json.write_text(json.dumps(no_roads_alignment(), indent=1))
        ctx.log.info("alignment: no roads in the map (the scan holds none): nothing to align")
        return {"yaw_deg": 0.0, "tx_m": 0.0, "ty_m": 0.0, "dz_m": 0.0, "kept_identity": True, "no_roads": True}
    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    labels = A.read_labels(in_labels_npy) if in_labels_npy is not None and params.use_labels else None
    fidx, how = road_faces(mesh.vertices, mesh.faces, labels, curb_tol_m=params.curb_tol_m)
    if len(fidx) < 10:
        raise InputError(f"{in_textured_mesh_ply.name}: no road surface found ({how}); nothing to align to")
    grid = Grid.around(mesh.vertices[:, :2], params.raster_m)
    sec = sample_sections(xodr_text, 1.0)
    # a network drawn from this very mesh (road_source=scan) is kept where it was drawn: the fit is measured,
    # not applied, and the kerb refinement is not run (the scan's lanes keep curb_clearance_m from the edges)
    source = source_kind(xodr_text)
    from_scan = source == "scan"
    res = fit_or_keep(sec, road_mask(mesh.vertices, mesh.faces, fidx, grid), grid, source=source, log=ctx.log,
                      search_m=params.search_m, fit_scale=params.fit_scale, yaw_range_deg=params.yaw_range_deg,
                      huber_m=params.huber_m, margin_m=params.margin_m, model=params.model)
    kerb, offsets = None, {}
    if params.kerbs and not from_scan:
        kerb, offsets = kerb_correction(xodr_text, res, mesh.vertices, mesh.faces, max_shift_m=params.kerb_max_shift_m,
                                        road_offset_m=params.kerb_road_offset_m, log=ctx.log)
    dz = surface_dz(mesh.vertices, mesh.faces, fidx, res.tf, sec, from_scan) if params.fit_height else 0.0
    # the scan's own network carries the scan's heights, each direction's from its own lanes' surface: its
    # height offset is measured, not applied (the road vertices' median beside its axis moved a real sweep's
    # lanes 3-4 cm under the surface, and the drop test from 77 to 51 %)
    dz_measured, dz = (dz, 0.0) if from_scan else (None, dz)
    doc = alignment_doc(res, dz, how, params.model, kerb, offsets)
    if from_scan:
        doc["dz_measured_m"] = round(dz_measured, 4)
        ctx.log.info("alignment: the network was derived from this scan (road_source=scan): kept in place, its "
                     "heights too (the road surface's median is %.3f m off them, not applied)", dz_measured)
    elif res.kept_identity:
        ctx.log.info("alignment: no rigid move fits the road surface better than the network as it is: kept in place")
    if res.degenerate and not from_scan:  # the scan's own network is not moved: nothing to constrain
        ctx.log.warning("alignment of the network from %s poorly constrained (parallel roads only?): check "
                        "alignment.json", SOURCE_NAMES[source])
    out_alignment_json.write_text(json.dumps(doc, indent=1))
    ctx.log.info("alignment: yaw %.3f deg, t (%.3f, %.3f) m, dz %.3f m; residual %.3f m (was %.3f) from %s",
                 doc["yaw_deg"], doc["tx_m"], doc["ty_m"], dz, res.rmse_after, res.rmse_before, how)
    return alignment_metrics(doc, kerb)


def apply_alignment(params: ApplyParams, ctx, *, in_roads_xodr: Path, in_alignment_json: Path,
                    in_textured_mesh_ply: Path, out_aligned_xodr: Path, out_roads_qa_png: Path,
                    in_roads_truth_json: Path | None = None) -> dict:
    """Move the OpenDRIVE by alignment.json (never the mesh) and draw the top-down QA picture."""
    import numpy as np

    from .align import centreline_rmse, lane_lines, transform_xodr
    from .kerbs import set_lane_offsets
    from .qa import draw_qa

    try:
        a = json.loads(in_alignment_json.read_text())
        yaw, tx, ty = math.radians(float(a["yaw_deg"])), float(a["tx_m"]), float(a["ty_m"])
        dz = float(a.get("dz_m", 0.0))
        offsets = {int(k): float(v) for k, v in (a.get("lane_offsets_m") or {}).items()}
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise InputError(f"{in_alignment_json}: unreadable alignment ({exc}); it needs numbers yaw_deg, tx_m, ty_m "
                         "(and dz_m; lane_offsets_m: road id -> metres)") from None
    text = in_roads_xodr.read_text(encoding="utf-8")
    moved = set_lane_offsets(transform_xodr(text, yaw, tx, ty, dz), offsets)
    moved, trim = trim_ends(moved, params, in_textured_mesh_ply, out_aligned_xodr.name, ctx.log)
    A.write_opendrive(out_aligned_xodr, moved)
    metrics = {"yaw_deg": a["yaw_deg"], "tx_m": tx, "ty_m": ty, "dz_m": dz, "roads_offset": len(offsets), **trim}
    truth = None
    if in_roads_truth_json is not None:
        tj = A.read_roads_truth(in_roads_truth_json)
        truth = [np.asarray(ln["points"], float) for ln in tj.get("lanes", [])]
    if truth:
        allp = np.concatenate(truth)[:, :2]
        lo, hi = allp.min(0) + 2.0, allp.max(0) - 2.0  # ignore the truncated ends at the site border
        b = (lo[0], lo[1], hi[0], hi[1])
        before, n0 = centreline_rmse(text, truth, b)
        after, n1 = centreline_rmse(moved, truth, b)
        metrics.update({"centreline_rmse_before_m": round(before, 4), "centreline_rmse_after_m": round(after, 4),
                        "centreline_points": n1})
        ctx.log.info("lane centre lines vs truth: RMSE %.3f m before, %.3f m after", before, after)
    draw_qa(in_textured_mesh_ply, lane_lines(moved, 1.0, junctions=True), lane_lines(text, 1.0, junctions=True),
            out_roads_qa_png, params.qa_px_per_m, params.qa_max_px, truth=truth)
    return metrics


def parking_lanes(params: ParkingParams, ctx, *, in_aligned_xodr: Path, in_textured_mesh_ply: Path,
                  in_labels_npy: Path, out_aligned_xodr: Path, out_parking_json: Path,
                  in_osm_osm: Path | None = None) -> dict:
    """Parking lanes between the outermost driving lane and the sidewalk lane where OSM or the scan shows
    parked cars (parking.py), so the sidewalk lanes lie on the sidewalk; then the outer lanes of the map's ends
    narrowed to the scanned ground (``ground_ends.trim_outer_lanes``)."""
    import numpy as np

    from twinkit.cityscapes import WIDE_VEHICLES

    from .parking import add_parking, osm_parking
    from .scan import is_empty_map

    params = params or ParkingParams()
    text = A.read_opendrive(in_aligned_xodr)
    if is_empty_map(text):
        A.write_opendrive(out_aligned_xodr, text)
        out_parking_json.write_text(json.dumps({"enabled": bool(params.enabled), "note": "no roads in the map",
                                                "sides": []}, indent=1))
        ctx.log.info("parking lanes: no roads in the map; aligned.xodr unchanged")
        return {"parking_lanes": 0}
    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    doc: dict = {"enabled": bool(params.enabled), "parking_lanes": 0, "sides": [],
                 "params": {k: getattr(params, k) for k in params.__dataclass_fields__}}
    seen = 0
    if params.enabled:
        labels = A.read_labels(in_labels_npy, len(mesh.vertices), in_textured_mesh_ply.name)
        osm = osm_parking(in_osm_osm) if params.osm_tags else {}
        res = add_parking(text, mesh.vertices, mesh.faces,
                          labels if params.scanned_vehicles else np.full_like(labels, 255), osm_sides=osm,
                          vehicle_ids=WIDE_VEHICLES, default_width_m=params.default_width_m,
                          min_width_m=params.min_width_m, max_width_m=params.max_width_m,
                          min_kerb_samples=params.min_kerb_samples, kerb_top_m=params.kerb_top_m, step_m=params.step_m)
        text, seen = res.text, sum(s.vehicles for s in res.sides)
        doc.update(parking_lanes=res.inserted, sides=[s.doc() for s in res.sides])
        for s in res.sides:
            ctx.log.info("parking lanes: road %d %s: %s", s.road, s.side,
                         f"{s.width_m:.2f} m ({s.why})" if s.width_m > 0 else s.why)
        if (osm or params.scanned_vehicles) and res.inserted == 0:
            ctx.log.warning("parking lanes: none added (no OSM parking tag on the roads and no scanned vehicle beside "
                            "them): the sidewalk lanes stay where netconvert put them")
    else:
        doc["note"] = "switched off"
        ctx.log.info("parking lanes: switched off")
    text, outer = outer_lanes_to_ground(text, params, mesh, out_aligned_xodr.name, ctx.log)
    doc["outer_lanes"] = outer
    A.write_opendrive(out_aligned_xodr, text)
    out_parking_json.write_text(json.dumps(doc, indent=1))
    return {"parking_lanes": doc["parking_lanes"], "parked_vehicles_seen": seen,
            "outer_lanes_narrowed": len(outer.get("narrowed", [])),
            "outer_off_ground_before": outer.get("outer_off_ground_before"),
            "outer_off_ground_after": outer.get("outer_off_ground_after")}


def outer_lanes_to_ground(text: str, params: ParkingParams, mesh, name: str, log) -> tuple[str, dict]:
    """The map with the outer lanes (sidewalk, parking, ...) of its ends narrowed to the mesh
    (``ground_ends.trim_outer_lanes``) and the report of it; unchanged when ``outer_lanes_to_ground`` is off."""
    from .ground_ends import TrimParams, trim_outer_lanes

    if not params.outer_lanes_to_ground:
        return text, {"enabled": False}
    out, rep = trim_outer_lanes(text, mesh.vertices, mesh.faces, TrimParams(margin_m=params.outer_margin_m),
                                source=name)
    for n in rep["notes"]:
        log.warning("outer lanes to the ground: %s", n)
    for c in rep["narrowed"]:
        log.info("outer lanes to the ground: road %s %s: %s lane %d without width over %.2f m", c["road"], c["end"],
                 c["type"], c["lane"], c["metres"])
    log.info("outer lanes to the ground: %d lanes narrowed at the map's ends; outer-lane cross-sections (every "
             "0.25 m) off the ground %d -> %d", len(rep["narrowed"]), rep["outer_off_ground_before"],
             rep["outer_off_ground_after"])
    return out, {"enabled": True, **rep}


def trim_ends(text: str, params: ApplyParams, mesh_ply: Path, name: str, log) -> tuple[str, dict]:
    """The aligned map with its ends cut back onto the mesh (``ground_ends.trim_to_ground``) and the step's
    metrics of it; the map unchanged when ``trim_to_ground`` is off or it has no road."""
    from .ground_ends import TrimParams, trim_to_ground

    if not params.trim_to_ground or "<road " not in text:
        return text, {"trim_to_ground": False}
    mesh = A.read_textured_mesh(mesh_ply)
    tp = TrimParams(step_m=params.trim_step_m, band_m=params.trim_band_m, margin_m=params.trim_margin_m,
                    max_trim_m=params.trim_max_m, min_left_m=params.trim_min_left_m)
    out, rep = trim_to_ground(text, mesh.vertices, mesh.faces, tp, source=name)
    for e in rep["ends"]:
        if e.get("note"):
            log.warning("map end %s (junction %s): %s", ", ".join(e["ends"]), e["junction"], e["note"])
    for n in rep["notes"]:
        log.warning("trim to the ground: %s", n)
    log.info("trim to the ground: %d of %d map ends cut back (at most %.2f m); driving-lane samples off the ground "
             "%d -> %d of %d, every lane %d -> %d", rep["cut_ends"], len(rep["ends"]), rep["max_trim_m"],
             rep["driving_off_ground_before"], rep["driving_off_ground_after"], rep["driving_samples_after"],
             rep["samples_off_ground_before"], rep["samples_off_ground_after"])
    if rep["driving_off_ground_after"]:
        log.warning("trim to the ground: %d driving-lane samples (every %.2f m) still have no ground beneath "
                    "(see the notes above and docs/roads.md 'Roads on the ground')", rep["driving_off_ground_after"],
                    tp.step_m)
    return out, {"trim_to_ground": True, "trimmed_ends": rep["cut_ends"], "trim_max_m": rep["max_trim_m"],
                 "driving_off_ground_before": rep["driving_off_ground_before"],
                 "driving_off_ground_after": rep["driving_off_ground_after"],
                 "lane_samples_off_ground_before": rep["samples_off_ground_before"],
                 "lane_samples_off_ground_after": rep["samples_off_ground_after"]}


def place_signals(params: SignalParams, ctx, *, in_aligned_xodr: Path, in_textured_mesh_ply: Path,
                  in_labels_npy: Path, out_aligned_xodr: Path, out_signals_json: Path,
                  out_signals_png: Path, in_osm_osm: Path | None = None,
                  in_alignment_json: Path | None = None) -> dict:
    """Move netconvert's traffic lights onto the scanned ones (instances.py), one controller per junction phase
    (controllers.py), add the scanned signs typed from OSM's sign nodes or their look (signals.py, signtypes.py)."""
    from .align import lane_lines
    from .instances import scanned_instances
    from twinkit.street.lights import light_plan

    from .signals import carla_position_errors, draw_signals, place_signals as place, signals_report
    from .signtypes import osm_sign_nodes, typed_plates

    params = params or SignalParams()
    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    labels = A.read_labels(in_labels_npy)
    if labels.ndim != 1 or len(labels) != len(mesh.vertices):
        raise InputError(f"{in_labels_npy}: {labels.shape} labels for the {len(mesh.vertices)} vertices of "
                         f"{in_textured_mesh_ply.name}; give the per-vertex labels of this mesh (the segmentation's "
                         "labels.npy)")
    text = A.read_opendrive(in_aligned_xodr)
    kept, rejected = scanned_instances(mesh.vertices, labels, params)
    osm_signs = None
    if in_osm_osm is not None:
        from twinkit.geo import SiteFrame

        align = json.loads(in_alignment_json.read_text()) if in_alignment_json is not None else None
        osm_signs = osm_sign_nodes(in_osm_osm, SiteFrame.from_site(ctx.site).lonlat_to_local, align)
        ctx.log.info("%d OSM sign node(s) (stop, give way, speed limit) to type the scanned plates", len(osm_signs))
    plates = typed_plates(rejected, mesh.colors)  # stop / yield / speed plates whose thin pole the mesh lost
    for i, inst in enumerate(plates):
        inst.id = len(kept) + i
    kept, rejected = kept + plates, [r for r in rejected if not any(r is p for p in plates)]
    try:
        moved, placed, notes = place(text, kept, gate_m=params.gate_m, group_m=params.group_m,
                                     carla_light_shift_m=params.carla_light_shift_m, add_signs=params.add_signs,
                                     sign_max_road_m=params.sign_max_road_m, wrong_side_m=params.wrong_side_m,
                                     one_head=params.one_head, lights_on_ground=params.lights_on_ground,
                                     phase_plan=params.phase_plan, phases=dict(params.phases), colors=mesh.colors,
                                     osm_signs=osm_signs)
    except (ValueError, KeyError, AttributeError) as exc:
        raise InputError(f"{in_aligned_xodr}: cannot read its roads and signals ({exc})") from None
    # what CARLA makes of each signal, against where we meant it to be
    try:
        carla_err = carla_position_errors(moved, placed, f"{in_aligned_xodr.name} with the scanned signals")
    except InputError as exc:
        edited = (f"if you edited {in_alignment_json} by hand, undo that edit or re-run align_roads "
                  "(rerun=[align_roads])") if in_alignment_json is not None else "re-run the road steps before it"
        raise InputError(f"{in_aligned_xodr}: the map with the scanned signals placed on it does not parse in "
                         f"carla.Map ({getattr(exc, 'why', exc)}); {edited}, or report it with this file") from None
    A.write_opendrive(out_aligned_xodr, moved)
    for p in placed:
        if p.source == "netconvert":
            ctx.log.warning("signal %s (road %s): %s", p.id, p.road, p.note)
    for n in notes:
        ctx.log.warning("%s", n)
    doc, metrics = signals_report(placed, kept, rejected, notes, carla_err,
                                  {k: getattr(params, k) for k in params.__dataclass_fields__}, light_plan(moved))
    out_signals_json.write_text(json.dumps(doc, indent=1))
    draw_signals(in_textured_mesh_ply, lane_lines(moved, 1.0, junctions=True), kept, rejected, placed,
                 out_signals_png, params.qa_px_per_m)
    ctx.log.info("CARLA's light plan (emulated): %d junction(s) with lights, %d light group(s) at the busiest, "
                 "%d pair(s) of crossing approaches green together; signs typed for CARLA %d, generic %d",
                 metrics["signalised_junctions"], metrics["max_light_groups_per_junction"],
                 metrics["conflicting_greens"], metrics["signs_typed"], metrics["signs_generic"])
    ctx.log.info("%d scanned lights (%d of them poles carrying an unlabelled head), %d signs (%d clusters "
                 "rejected); %d of %d light signals from the scan, %d kept from netconvert; %d signs written",
                 metrics["scanned_lights"], metrics["pole_head_lights"], metrics["scanned_signs"],
                 len(rejected), metrics["light_signals_from_scan"], metrics["light_signals"],
                 metrics["light_signals_netconvert"], metrics["signs_written"])
    return metrics


def place_crosswalks(params: CrosswalkParams, ctx, *, in_aligned_xodr: Path, in_textured_mesh_ply: Path,
                     out_aligned_xodr: Path, out_crosswalks_json: Path, in_labels_npy: Path | None = None,
                     in_osm_osm: Path | None = None, in_alignment_json: Path | None = None) -> dict:
    """OpenDRIVE crosswalk objects from OSM's crossings and the scan's painted zebras (crosswalks.py)."""
    from .crosswalks import run_crosswalks

    params = params or CrosswalkParams()
    text = A.read_opendrive(in_aligned_xodr)
    doc, moved = run_crosswalks(params, text, ctx.site, in_textured_mesh_ply, in_labels_npy, in_osm_osm,
                                in_alignment_json, ctx.log)
    A.write_opendrive(out_aligned_xodr, moved)
    A.write_crosswalks(out_crosswalks_json, doc)
    return doc["metrics"]


def road_evidence(params: RoadEvidenceParams, ctx, *, in_aligned_xodr: Path, in_textured_mesh_ply: Path,
                  in_labels_npy: Path, out_labels_npy: Path, out_road_evidence_json: Path,
                  out_road_evidence_png: Path, in_gt_labels_npy: Path | None = None,
                  in_points_meta_json: Path | None = None) -> dict:
    """The aligned lanes vote for road / sidewalk on ground-level surface where the scan agrees (evidence.py)."""
    from .evidence import (add_evaluation, draw_evidence, draw_passthrough, evidence_report, lanes_of,
                           passthrough_reason, road_evidence as vote, unchanged)
    from .mesh2d import Grid
    from .scan import cloud_sampling, is_empty_map

    params = params or RoadEvidenceParams()
    labels = A.read_labels(in_labels_npy)
    text = A.read_opendrive(in_aligned_xodr)
    no_roads = is_empty_map(text)
    _, two_way = cloud_sampling(in_points_meta_json)
    rings = two_way is not None and two_way < params.min_two_way_share
    why = passthrough_reason(params.enabled, no_roads, two_way if rings else None, params.min_two_way_share)
    if why:
        A.write_labels(out_labels_npy, labels)
        doc = {"enabled": bool(params.enabled), "no_roads": no_roads,
               **({"rings": True, "ground_two_way_share": round(two_way, 3)} if rings else {}),
               "note": f"{why}: labels.npy passed through unchanged"}
        out_road_evidence_json.write_text(json.dumps(doc, indent=1))
        draw_passthrough(out_road_evidence_png, why)
        ctx.log.info("road evidence: %s; labels unchanged", why)
        return {"enabled": bool(params.enabled), "changed_vertices": 0, **({"no_roads": True} if no_roads else {}),
                **({"rings": True} if rings else {})}
    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    if labels.ndim != 1 or len(labels) != len(mesh.vertices):
        raise InputError(f"{in_labels_npy}: {labels.shape} labels for the {len(mesh.vertices)} vertices of "
                         f"{in_textured_mesh_ply.name}; give the per-vertex labels of this mesh (the segmentation's "
                         "labels.npy)")
    lanes = lanes_of(text, in_aligned_xodr, params.step_m, params.road_types, params.sidewalk_types)
    grid = Grid.around(mesh.vertices[:, :2], params.raster_m)
    ev = vote(mesh.vertices, mesh.faces, labels, lanes, grid, normal_min_z=params.normal_min_z,
              max_height_m=params.max_height_m, curb_min_m=params.curb_min_m, curb_max_m=params.curb_max_m,
              window_m=params.window_m, max_disagreement=params.max_disagreement,
              max_network_disagreement=params.max_network_disagreement, plateau=params.plateau,
              relabel_from=tuple(int(c) for c in params.relabel_classes))
    new = ev.labels if params.relabel else labels.copy()
    A.write_labels(out_labels_npy, new.astype(labels.dtype))
    doc, metrics = evidence_report(ev, labels, new, params.relabel,
                                   {k: getattr(params, k) for k in params.__dataclass_fields__})
    if in_gt_labels_npy is not None:
        gt = A.read_labels(in_gt_labels_npy)
        if len(gt) == len(labels):
            before, after = add_evaluation(doc, metrics, labels, new, gt)
            ctx.log.info("vs ground truth: road %.1f -> %.1f, sidewalk %.1f -> %.1f, terrain %.1f -> %.1f, "
                         "mIoU %.1f -> %.1f", before.get("road", 0), after.get("road", 0), before.get("sidewalk", 0),
                         after.get("sidewalk", 0), before.get("terrain", 0), after.get("terrain", 0),
                         before["miou"], after["miou"])
    out_road_evidence_json.write_text(json.dumps(doc, indent=1))
    draw_evidence(mesh.vertices, mesh.faces, labels, ev if params.relabel else unchanged(ev, labels), lanes,
                  out_road_evidence_png, params.picture_px_per_m)
    ctx.log.info("road network evidence: %d vertices (%.1f m^2) relabelled %s; lanes disagree with the scan's "
                 "geometry over %.1f m^2 (%.1f %% of the lanes' area), %d lanes vetoed", doc["changed_vertices"],
                 doc["changed_area_m2"], doc["transitions"], doc["disagreement_geometry_m2"],
                 100 * doc["disagreement_fraction"], len(doc["vetoed_lanes"]))
    if ev.network_vetoed:
        kind = source_kind(text)
        ctx.log.warning("the driving lanes of the network from %s disagree with the scan's ground over %.0f %% of "
                        "their surface (more than max_network_disagreement %.0f %%): %s. No label changed; see "
                        "road_evidence.png", SOURCE_NAMES[kind], 100 * ev.network_disagreement,
                        100 * params.max_network_disagreement, source_hint(kind, "misfit"))
    return metrics


@hookimpl
def twinkit_register_road_sources(register):
    from .preflight import file_preflight, opendrive_preflight, osm_api_preflight, overpass_preflight, scan_preflight

    # the default road source; without an OSM file that covers the site it gives way to the scan (issue 28)
    register("file", file_source, params=FileSourceParams, version=VERSION, preflight=file_preflight,
             fallback="scan",
             description="local .osm / .osm.bz2 / .osm.pbf (site.inputs.osm or road_source.path); without one "
                         "that covers the site: roads from the scan (road_source=scan)")
    register("osm_api", osm_api_source, params=DownloadParams, version=VERSION, preflight=osm_api_preflight,
             description="OpenStreetMap API /map by box around the base point (cached)")
    register("overpass", overpass_source, params=DownloadParams, version=VERSION, preflight=overpass_preflight,
             description="Overpass API query for highways by box around the base point (cached)")
    from .scan import ScanSourceParams

    register("scan", scan_source, params=ScanSourceParams, version=VERSION, preflight=scan_preflight,
             description="roads derived from the scan itself (no OSM): the labelled road surface, curbs and "
                         "sidewalks of the textured mesh -> lanes -> OpenDRIVE (scan_roads.json, scan_roads.png)")
    register("opendrive", opendrive_source, params=OpenDriveSourceParams, version=VERSION, preflight=opendrive_preflight,
             description="an existing OpenDRIVE map (site.inputs.xodr or road_source.path) moved from its "
                         "geoReference into the site frame")


@hookimpl
def twinkit_register_steps(register):
    register("osm_to_opendrive", osm_to_opendrive, params=ConvertParams, version=VERSION,
             description="OSM -> OpenDRIVE with netconvert in the site frame; checked with carla.Map")
    register("roads_overview", roads_overview, params=OverviewParams, version=VERSION,
             description="top view of the road network without a mesh (lanes by type); roads_overview.png")
    register("carla_roads", carla_roads, params=CarlaMapParams, version=VERSION,
             description="the map in the CARLA package's frame, the one CARLA geolocates (roads_carla.xodr); CARLA's "
                         "geolocation measured with the carla wheel at its lane centres (carla_geolocation.json)")
    register("align_roads", align_roads, params=AlignParams, version=VERSION,
             description="fit the road network to the mesh's road surface (yaw, translation); alignment.json")
    register("apply_alignment", apply_alignment, params=ApplyParams, version=VERSION,
             description="move the OpenDRIVE by alignment.json; top-down QA picture")
    register("parking_lanes", parking_lanes, params=ParkingParams, version=VERSION,
             description="OpenDRIVE parking lanes where OSM or the scan shows parked cars; aligned.xodr, parking.json")
    register("place_signals", place_signals, params=SignalParams, version=VERSION,
             description="OpenDRIVE signals at the scanned traffic lights and signs; signals.json, signals.png")
    register("place_crosswalks", place_crosswalks, params=CrosswalkParams, version=VERSION,
             description="OpenDRIVE crosswalk objects from OSM crossings and the scan's painted zebras (as CARLA's "
                         "get_crosswalks reports them); crosswalks.json")
    register("road_evidence", road_evidence, params=RoadEvidenceParams, version=VERSION,
             description="the aligned lanes vote road / sidewalk on ground-level surface; labels.npy, "
                         "road_evidence.json, road_evidence.png (disagreements reported)")

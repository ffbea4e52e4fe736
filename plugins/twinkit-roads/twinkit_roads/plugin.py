"""twinkit-roads: road sources, OSM -> OpenDRIVE, alignment to the mesh, QA picture.

Steps (recipes/roads_demo.yaml):
  fetch_roads     road_source (file | osm_api | overpass)   -> osm.osm
                  road_source=opendrive                     -> opendrive.xodr (site frame), reprojection.json
                  road_source=scan (the labelled mesh)      -> opendrive.xodr, scan_roads.json, scan_roads.png
  osm_to_opendrive                                          -> roads.xodr, roads_check.json
  roads_overview  top view of the network (recipe roads)   -> roads_overview.png
  align_roads     fit the network to the mesh's road surface -> alignment.json  (edit it to override)
  apply_alignment move the OpenDRIVE, draw the QA picture    -> aligned.xodr, roads_qa.png
  place_signals   signals at the scanned lights and signs   -> aligned.xodr (again), signals.json, signals.png
  road_evidence   the lanes vote for road / sidewalk        -> labels.npy (again), road_evidence.json, .png
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

from twinkit import artefacts as A
from typing import List

from twinkit import InputError, hookimpl
from twinkit.geo.xodr import from_scan as from_scan_tag
from twinkit.ranges import param

from . import __version__
from .convert import ConvertParams
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
        what = (f"the OpenDRIVE map ({in_opendrive_xodr.name}) does not cover the site: check site.base_point and the "
                "map's geoReference" if in_opendrive_xodr is not None else "the OSM data do not cover the site")
        raise InputError(f"{out_roads_xodr.name}: carla.Map found {chk['topology_segments']} topology segments and "
                         f"{chk['waypoints_inside']} waypoints inside the site box {bounds} (need "
                         f"{params.min_waypoints_inside}); {what}")
    ctx.log.info("%d roads, %d junctions, %d traffic lights; carla.Map: %d waypoints (%d inside the site); "
                 "netconvert %.2f s, check %.2f s, total %.2f s", counts["roads"], counts["junctions"],
                 counts["traffic_lights"], chk["waypoints"], chk["waypoints_inside"], info["netconvert_s"], check_s,
                 total)
    return {"roads": counts["roads"], "junctions": counts["junctions"], "traffic_lights": counts["traffic_lights"],
            "waypoints": chk["waypoints"], "waypoints_inside": chk["waypoints_inside"],
            "conversion_s": round(total, 3), "netconvert_s": info["netconvert_s"], "check_s": round(check_s, 3)}


@dataclass
class OverviewParams:
    px_per_m: float = param(4.0, gt=0, help="pixels per metre of the overview picture")
    max_px: int = param(3000, ge=16, help="at most this many pixels across; large networks are drawn coarser")


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


@dataclass
class AlignParams:
    fit_scale: bool = param(False, help="also estimate a uniform scale; it is reported, never applied to the OpenDRIVE")
    search_m: float = param(8.0, ge=0, help="metres: radius of the coarse search for the translation (0: refine only)")
    yaw_range_deg: float = param(3.0, ge=0, le=180, help="degrees: the coarse search tries yaws within plus or minus this")
    raster_m: float = param(0.1, gt=0, help="metres: pixel size of the road masks the fit compares")
    margin_m: float = param(6.0, ge=0, help="metres: how far beyond the network's carriageway edge to look for the mesh's road edge")
    huber_m: float = param(0.3, gt=0, help="metres: threshold of the robust (Huber) loss of the fit's residuals")
    curb_tol_m: float = param(0.07, ge=0, help="metres: without road labels the fit uses the ground; a vertex this far above the lowest local level still counts as road")
    fit_height: bool = param(True, help="shift the OpenDRIVE elevation to the median height of the road surface")
    model: str = param("middles", choices=("middles", "edges"), help="the residuals: 'middles' of the carriageway, or each of its 'edges' with a free extra width per road")
    use_labels: bool = param(True, help="fit to the road-labelled surface when labels.npy exists; false: always to the ground (kerbs)")
    kerbs: bool = param(True, help="after the fit, move the lane edges onto the feet of the kerbs seen in the mesh (a centimetre-scale correction)")
    kerb_max_shift_m: float = param(0.3, ge=0, help="metres: the kerb correction is refused when it would move the network farther than this")
    kerb_road_offset_m: float = param(0.15, ge=0, help="metres: then move each road sideways onto its own kerbs, at most this far (0: off)")


def align_roads(params: AlignParams, ctx, *, in_roads_xodr: Path, in_textured_mesh_ply: Path,
                out_alignment_json: Path, in_labels_npy: Path | None = None) -> dict:
    """Rigid 2D fit (yaw, translation) of the network to the road surface (labels) or the ground."""
    import numpy as np

    from .align import fit, sample_sections
    from .mesh2d import Grid, road_faces, road_mask
    from .scan import is_empty_map

    if is_empty_map(in_roads_xodr.read_text(encoding="utf-8")):  # road_source=scan found no road
        doc = {"yaw_deg": 0.0, "tx_m": 0.0, "ty_m": 0.0, "dz_m": 0.0, "scale_estimate": 1.0, "kept_identity": True,
               "no_roads": True, "definition": "aligned_xy = Rz(yaw_deg) @ xy + [tx_m, ty_m] about the site origin; "
                                               "z += dz_m", "note": "no roads in the map: nothing to align"}
        out_alignment_json.write_text(json.dumps(doc, indent=1))
        ctx.log.info("alignment: no roads in the map (the scan holds none): nothing to align")
        return {"yaw_deg": 0.0, "tx_m": 0.0, "ty_m": 0.0, "dz_m": 0.0, "kept_identity": True, "no_roads": True}
    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    labels = None
    if in_labels_npy is not None and params.use_labels:
        labels = A.read_labels(in_labels_npy)
    fidx, how = road_faces(mesh.vertices, mesh.faces, labels, curb_tol_m=params.curb_tol_m)
    if len(fidx) < 10:
        raise InputError(f"{in_textured_mesh_ply.name}: no road surface found ({how}); nothing to align to")
    grid = Grid.around(mesh.vertices[:, :2], params.raster_m)
    mask = road_mask(mesh.vertices, mesh.faces, fidx, grid)
    xodr_text = in_roads_xodr.read_text(encoding="utf-8")
    sec = sample_sections(xodr_text, 1.0)
    # a network drawn from this very mesh (road_source=scan) is already where the mesh's roads are: the fit,
    # against a cruder road surface (the ground level, which takes ramped sidewalks too), can only move it
    # off (Lille: turned 2.6 deg, lanes onto the curb); it is measured, not applied. Nor is the kerb
    # refinement: it puts driving-lane borders on the kerbs' feet, and the scan's lanes keep
    # curb_clearance_m (a strip) from the edges they were drawn on
    from_scan = from_scan_tag(xodr_text)
    try:
        res = fit(sec, mask, grid, fit_scale=params.fit_scale, search_m=0.0 if from_scan else params.search_m,
                  yaw_range_deg=params.yaw_range_deg, huber_m=params.huber_m, margin_m=params.margin_m,
                  model=params.model, keep_identity=from_scan)
    except InputError as exc:
        if not from_scan:
            raise
        # the scan's own network stays where it was drawn whatever the fit says; that the cruder surface
        # here (road labels or the ground level) does not find it is no reason to stop the run (Autzen:
        # paths drawn on paved-looking grey ground the ground test does not take)
        from .align import FitResult, Transform2D

        ctx.log.warning("alignment: the scan's own network is kept in place; its residual is not measured (%s)", exc)
        nan = float("nan")
        res = FitResult(Transform2D(about=tuple(sec.c.mean(0)) if len(sec.c) else (0.0, 0.0)), nan, nan,
                        len(sec.c), 0, 0, False, kept_identity=True)
    kerb = None
    if params.kerbs and not from_scan:
        from .align import lane_lines, refine_to_kerbs

        lines = lane_lines(xodr_text, 1.0)
        kerb = refine_to_kerbs(lines, res.tf, mesh.vertices, mesh.faces, max_shift_m=params.kerb_max_shift_m)
        if kerb.applied:
            res.tf = kerb.tf
            ctx.log.info("alignment: lane edges onto %d kerb feet: median offset %.3f -> %.3f m (moved %.3f m, %.3f deg)",
                         kerb.edges, kerb.before_m, kerb.after_m, math.hypot(*kerb.shift_m), kerb.yaw_deg)
        else:
            ctx.log.info("alignment: kerb refinement not applied: %s", kerb.why)
    offsets: dict = {}
    if kerb is not None and params.kerb_road_offset_m > 0:
        from .align import road_lane_offsets

        offsets = road_lane_offsets(lines, res.tf, mesh.vertices, mesh.faces,
                                    max_offset_m=params.kerb_road_offset_m)
        if offsets:
            ctx.log.info("alignment: %d road(s) moved sideways onto their kerbs: %s", len(offsets),
                         ", ".join(f"road {k} {v:+.3f} m" for k, v in sorted(offsets.items())))
    yaw, tx, ty, scale = res.tf.about_origin()
    dz = 0.0
    if params.fit_height:
        # the road surface's height under each carriageway middle against the OpenDRIVE's own height there
        # (0 from OSM; the scanned heights from road_source=scan): one offset, the median of the differences
        from scipy.spatial import cKDTree

        rv = np.unique(mesh.faces[fidx].ravel())
        d, i = cKDTree(mesh.vertices[rv, :2]).query(res.tf.apply(sec.c), distance_upper_bound=1.0)
        hit = np.isfinite(d)
        if hit.sum() >= 6:
            dz = float(np.median(mesh.vertices[rv[i[hit]], 2] - sec.z[hit]))
        elif from_scan:  # the scan's network carries the scanned heights already
            dz = 0.0
        else:  # the middles find no road vertex near them: the medians of the whole surface and network
            dz = float(np.median(mesh.vertices[rv, 2]) - np.median(sec.z))
    doc = {
        "yaw_deg": round(math.degrees(yaw), 6), "tx_m": round(tx, 4), "ty_m": round(ty, 4), "dz_m": round(dz, 4),
        "scale_estimate": round(scale, 6),
        "definition": "aligned_xy = Rz(yaw_deg) @ xy + [tx_m, ty_m] about the site origin; z += dz_m. "
                      "Edit the numbers and re-run: later steps use your values.",
        "residual_rmse_m": round(res.rmse_after, 4) if math.isfinite(res.rmse_after) else None,
        "residual_rmse_before_m": round(res.rmse_before, 4) if math.isfinite(res.rmse_before) else None,
        "sections": res.n_sections, "sections_used": res.n_used, "iterations": res.iterations,
        "degenerate": res.degenerate, "kept_identity": res.kept_identity, "road_surface_from": how,
        "model": params.model,
        "note": "residual = RMS offset between carriageway middles of the network and of the mesh's road surface",
    }
    if kerb is not None:
        doc["kerbs"] = {"edges": kerb.edges, "applied": kerb.applied, "why_not": kerb.why or None,
                        "median_offset_before_m": round(kerb.before_m, 4) if math.isfinite(kerb.before_m) else None,
                        "median_offset_after_m": round(kerb.after_m, 4) if math.isfinite(kerb.after_m) else None,
                        "shift_m": [round(x, 4) for x in kerb.shift_m], "yaw_deg": round(kerb.yaw_deg, 4),
                        "note": "lane edges against the foot of the kerb beside them (profiles of vertical rays "
                                "across each driving lane border); included in yaw_deg / tx_m / ty_m when applied"}
        doc["lane_offsets_m"] = {str(k): v for k, v in sorted(offsets.items())}
        doc["lane_offsets_note"] = ("per OpenDRIVE road id: metres to the left of its reference line, added to its "
                                    "<laneOffset> by apply_alignment after the rigid move (each road onto its own "
                                    "kerbs); edit or empty it by hand like the numbers above")
    if from_scan:
        ctx.log.info("alignment: the network was derived from this scan (road_source=scan): kept in place")
    elif res.kept_identity:
        ctx.log.info("alignment: no rigid move fits the road surface better than the network as it is: kept in place")
    if res.degenerate:
        ctx.log.warning("alignment poorly constrained (parallel roads only?): check alignment.json")
    out_alignment_json.write_text(json.dumps(doc, indent=1))
    ctx.log.info("alignment: yaw %.3f deg, t (%.3f, %.3f) m, dz %.3f m; residual %.3f m (was %.3f) from %s",
                 doc["yaw_deg"], tx, ty, dz, res.rmse_after, res.rmse_before, how)
    return {**{k: doc[k] for k in ("yaw_deg", "tx_m", "ty_m", "dz_m", "residual_rmse_m", "residual_rmse_before_m",
                                   "sections_used", "road_surface_from", "kept_identity")},
            "kerb_edges": kerb.edges if kerb else 0, "kerb_applied": bool(kerb and kerb.applied),
            "kerb_offset_after_m": doc.get("kerbs", {}).get("median_offset_after_m")}


@dataclass
class ApplyParams:
    qa_px_per_m: float = param(20.0, gt=0, help="pixels per metre of the QA picture of the aligned network over the mesh")
    qa_max_px: int = param(4096, ge=16, help="at most this many pixels across the QA picture")


def apply_alignment(params: ApplyParams, ctx, *, in_roads_xodr: Path, in_alignment_json: Path,
                    in_textured_mesh_ply: Path, out_aligned_xodr: Path, out_roads_qa_png: Path,
                    in_roads_truth_json: Path | None = None) -> dict:
    """Move the OpenDRIVE by alignment.json (never the mesh) and draw the top-down QA picture."""
    import numpy as np

    from .align import centreline_rmse, lane_lines, set_lane_offsets, transform_xodr
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
    A.write_opendrive(out_aligned_xodr, moved)
    metrics = {"yaw_deg": a["yaw_deg"], "tx_m": tx, "ty_m": ty, "dz_m": dz, "roads_offset": len(offsets)}
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


@dataclass
class SignalParams:
    # finding scanned instances (signals.find_instances): CityScapes trainIds 5 pole, 6 light, 7 sign
    link_m: float = param(0.35, gt=0, help="metres: vertices of one label (pole, light, sign) closer than this belong to one cluster")
    min_vertices: int = param(12, ge=0, help="clusters with fewer vertices are label noise and are dropped")
    min_height_m: float = param(1.5, ge=0, help="metres: a light head or a sign plate hangs at least this high above the local ground")
    max_height_m: float = param(8.0, gt=0, help="metres: ... and at most this high")
    max_size_m: float = param(2.0, gt=0, help="metres: a cluster wider or taller than this is a mislabelled patch of something else")
    min_pole_vertices: int = param(3, ge=0, help="pole-labelled vertices below the cluster (within pole_radius_m) that show it hangs on a pole")
    pole_radius_m: float = param(0.6, gt=0, help="metres: radius around a cluster searched for the pole that carries it")
    ground_radius_m: float = param(3.0, gt=0, help="metres: the local ground under a signal is the 2nd percentile of the mesh's heights within this radius (street.ground.LocalGround, disc mode)")
    plate_depth_m: float = param(0.12, ge=0, help="metres: a 'light' cluster thinner than this across is a sign plate (light heads are boxes)")
    # poles carrying an unlabelled head (signals.find_pole_heads): candidates for lights the labels miss,
    # offered only to netconvert light heads left unpaired by the labelled lights
    pole_heads: bool = param(True, help="look for poles carrying an unlabelled head: light candidates the labels missed, offered only to netconvert light heads no labelled light paired with")
    head_min_m: float = param(1.8, ge=0, help="metres: bottom of the head band above the local ground, for heads on poles")
    head_max_m: float = param(4.5, gt=0, help="metres: top of that head band")
    head_min_width_m: float = param(0.3, ge=0, help="metres: narrowest extent of the head band; a bare pole or a sign plate is thinner")
    head_max_width_m: float = param(1.0, gt=0, help="metres: widest extent of the head band")
    head_clear_m: float = param(0.8, ge=0, help="metres: no vertex at head height from here to 1.5 m off the pole's axis (keeps trees and walls out)")
    # placing (signals.place_signals)
    gate_m: float = param(15.0, gt=0, help="metres: a netconvert light group and a scanned light farther apart than this never pair")
    group_m: float = param(2.0, ge=0, help="metres: netconvert light signals of one road within this distance along s are one head")
    wrong_side_m: float = param(6.0, ge=0, help="metres: extra pairing cost of a light across the reference line from the lanes of its head")
    carla_light_shift_m: float = param(0.25, help="metres: CARLA moves lights this far along their heading on import (MapBuilder.cpp); the placement compensates")
    add_signs: bool = param(True, help="write the scanned traffic signs as OpenDRIVE signals")
    sign_max_road_m: float = param(12.0, gt=0, help="metres: a sign farther than this from every road's reference line is not written")
    qa_px_per_m: float = param(20.0, gt=0, help="pixels per metre of the signals' QA picture")


def place_signals(params: SignalParams, ctx, *, in_aligned_xodr: Path, in_textured_mesh_ply: Path,
                  in_labels_npy: Path, out_aligned_xodr: Path, out_signals_json: Path,
                  out_signals_png: Path) -> dict:
    """Move netconvert's traffic lights onto the scanned ones, add the scanned signs (signals.py)."""
    import numpy as np

    from .align import lane_lines
    from .signals import draw_signals, find_instances, find_pole_heads, place_signals as place

    params = params or SignalParams()
    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    labels = A.read_labels(in_labels_npy)
    if labels.ndim != 1 or len(labels) != len(mesh.vertices):
        raise InputError(f"{in_labels_npy}: {labels.shape} labels for the {len(mesh.vertices)} vertices of "
                         f"{in_textured_mesh_ply.name}; give the per-vertex labels of this mesh (the segmentation's "
                         "labels.npy)")
    text = A.read_opendrive(in_aligned_xodr)
    kept, rejected = find_instances(
        mesh.vertices, labels, link_m=params.link_m, min_vertices=params.min_vertices, min_height_m=params.min_height_m,
        max_height_m=params.max_height_m, max_size_m=params.max_size_m, ground_radius_m=params.ground_radius_m,
        pole_radius_m=params.pole_radius_m, min_pole_vertices=params.min_pole_vertices,
        plate_depth_m=params.plate_depth_m)
    if params.pole_heads:
        heads = find_pole_heads(mesh.vertices, labels, kept, link_m=params.link_m,
                                head_z_m=(params.head_min_m, params.head_max_m),
                                head_width_m=(params.head_min_width_m, params.head_max_width_m),
                                clear_ring_m=(params.head_clear_m, max(params.head_clear_m + 0.2, 1.5)),
                                ground_radius_m=params.ground_radius_m)
        for i, h in enumerate(heads):
            h.id = len(kept) + i
        kept = kept + heads
    try:
        moved, placed, notes = place(text, kept, gate_m=params.gate_m, group_m=params.group_m,
                                     carla_light_shift_m=params.carla_light_shift_m, add_signs=params.add_signs,
                                     sign_max_road_m=params.sign_max_road_m, wrong_side_m=params.wrong_side_m)
    except (ValueError, KeyError, AttributeError) as exc:
        raise InputError(f"{in_aligned_xodr}: cannot read its roads and signals ({exc})") from None
    from twinkit.street.lanes import LaneMap, OpenDriveError

    try:
        m = LaneMap(moved, "signals", source=f"{in_aligned_xodr.name} with the scanned signals")
    except OpenDriveError as exc:
        raise InputError(str(exc)) from None
    # what CARLA makes of each signal, against where we meant it to be
    want = {p.id: p.new_xy for p in placed}
    carla_err = {}
    for lm in m.landmarks():
        w = want.get(lm.id)
        if w is not None:
            carla_err[lm.id] = round(float(math.hypot(lm.xyz[0] - w[0], lm.xyz[1] - w[1])), 4)
    A.write_opendrive(out_aligned_xodr, moved)
    for p in placed:
        if p.source == "netconvert":
            ctx.log.warning("signal %s (road %s): %s", p.id, p.road, p.note)
    for n in notes:
        ctx.log.warning("%s", n)
    lights = [p for p in placed if p.kind == "light"]
    n_scan = sum(p.source == "scan" for p in lights)
    doc = {
        "signals": [dict(p.to_json(), carla_position_error_m=carla_err.get(p.id)) for p in placed],
        "instances": [i.to_json() for i in kept], "rejected_clusters": [i.to_json() for i in rejected],
        "notes": notes,
        "definition": "position: where CARLA 0.9.16 puts the signal (x, y site frame, m); s, t, zOffset in the road's "
                      "reference-line frame of defined_on_road; road = the road whose lanes it controls (a "
                      "signalReference there when defined_on_road differs); source scan|netconvert; moved_m = "
                      "horizontal distance from netconvert's position",
        "params": {k: getattr(params, k) for k in params.__dataclass_fields__},
    }
    out_signals_json.write_text(json.dumps(doc, indent=1))
    draw_signals(in_textured_mesh_ply, lane_lines(moved, 1.0, junctions=True), kept, rejected, placed,
                 out_signals_png, params.qa_px_per_m)
    ctx.log.info("%d scanned lights (%d of them poles carrying an unlabelled head), %d signs (%d clusters "
                 "rejected); %d of %d light signals from the scan, %d kept from netconvert; %d signs written", sum(i.kind == "light" for i in kept),
                 sum(i.evidence == "pole_head" for i in kept),
                 sum(i.kind == "sign" for i in kept), len(rejected), n_scan, len(lights), len(lights) - n_scan,
                 sum(p.kind == "sign" for p in placed))
    moved_m = [p.moved_m for p in lights if p.source == "scan"]
    return {"scanned_lights": sum(i.kind == "light" for i in kept),
            "scanned_signs": sum(i.kind == "sign" for i in kept),
            "pole_head_lights": sum(i.evidence == "pole_head" for i in kept),
            "rejected_clusters": len(rejected), "light_signals": len(lights), "light_signals_from_scan": n_scan,
            "light_signals_netconvert": len(lights) - n_scan, "signs_written": sum(p.kind == "sign" for p in placed),
            "median_moved_m": round(float(np.median(moved_m)), 3) if moved_m else 0.0,
            "max_carla_position_error_m": max(carla_err.values(), default=0.0)}


def _road_types():
    from .evidence import ROAD_TYPES
    return list(ROAD_TYPES)


@dataclass
class RoadEvidenceParams:
    enabled: bool = param(True, help="false: labels.npy passes through unchanged (the site key road_evidence: false does the same)")
    relabel: bool = param(True, help="false: compare and report only, change no label")
    road_types: List[str] = param(default_factory=_road_types, free=True, help="OpenDRIVE lane types whose lanes vote road")
    sidewalk_types: List[str] = param(default_factory=lambda: ["sidewalk"], free=True, help="OpenDRIVE lane types whose lanes vote sidewalk")
    relabel_classes: List[int] = param(default_factory=lambda: [0, 1, 9], ge=0, le=255, help="the ground classes (CityScapes trainIds) a lane's vote may change")
    normal_min_z: float = param(0.9, ge=0, le=1, help="a ground vertex has a normal whose up component is at least this (about 25 degrees from up at 0.9)")
    max_height_m: float = param(0.45, ge=0, help="metres: ... and lies at most this high above the local lowest ground")
    curb_min_m: float = param(0.06, ge=0, help="metres: the raised (pavement) level starts this far above the local lowest ground; below is the carriageway")
    curb_max_m: float = param(0.35, ge=0, help="metres: ... and ends this far above it")
    window_m: float = param(8.0, gt=0, help="metres: the local lowest ground is the minimum over this window of the "
                                          "0.5 m cells' 5th percentiles of up-facing vertices (street.ground.LocalGround)")
    max_disagreement: float = param(0.5, ge=0, le=1, help="a lane, or a road, whose surface disagrees with the scan over more than this share casts no vote")
    max_network_disagreement: float = param(0.10, ge=0, le=1, help="share: when the driving-like lanes of the whole network disagree over more than this, no lane votes (a misaligned or outdated map; see docs/roads.md)")
    plateau: bool = param(True, help="a raised plateau that an agreeing sidewalk lane lies on becomes sidewalk (its road votes)")
    raster_m: float = param(0.1, gt=0, help="metres: pixel size of the lane raster")
    step_m: float = param(0.5, gt=0, help="metres: lanes are sampled this far apart along s")
    picture_px_per_m: float = param(10.0, gt=0, help="pixels per metre of the evidence picture")


def road_evidence(params: RoadEvidenceParams, ctx, *, in_aligned_xodr: Path, in_textured_mesh_ply: Path,
                  in_labels_npy: Path, out_labels_npy: Path, out_road_evidence_json: Path,
                  out_road_evidence_png: Path, in_gt_labels_npy: Path | None = None) -> dict:
    """The aligned lanes vote for road / sidewalk on ground-level surface where the scan agrees (evidence.py)."""
    from twinkit.street.lanes import OpenDriveError

    from .evidence import (L_ROAD, L_SIDEWALK, STATUS, S_AGREE, S_LEVEL, S_NONGROUND_GEOM, S_NONGROUND_LABEL,
                           S_RELABEL, draw_evidence, lane_polygons, road_evidence as vote)
    from .mesh2d import Grid

    params = params or RoadEvidenceParams()
    labels = A.read_labels(in_labels_npy)
    from .scan import is_empty_map

    no_roads = is_empty_map(A.read_opendrive(in_aligned_xodr))
    if not params.enabled or no_roads:
        A.write_labels(out_labels_npy, labels)
        why = ("no roads in the map (the scan holds none)" if no_roads else
               "switched off (steps.road_evidence.enabled=false or site road_evidence: false)")
        doc = {"enabled": bool(params.enabled), "no_roads": no_roads,
               "note": f"{why}: labels.npy passed through unchanged"}
        out_road_evidence_json.write_text(json.dumps(doc, indent=1))
        from PIL import Image, ImageDraw

        img = Image.new("RGB", (420, 40), (0, 0, 0))
        ImageDraw.Draw(img).text((10, 14), f"road network evidence: {why[:44]}; labels unchanged", fill=(255, 255, 255))
        img.save(out_road_evidence_png)
        ctx.log.info("road evidence: %s; labels unchanged", why)
        return {"enabled": bool(params.enabled), "changed_vertices": 0, **({"no_roads": True} if no_roads else {})}
    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    if labels.ndim != 1 or len(labels) != len(mesh.vertices):
        raise InputError(f"{in_labels_npy}: {labels.shape} labels for the {len(mesh.vertices)} vertices of "
                         f"{in_textured_mesh_ply.name}; give the per-vertex labels of this mesh (the segmentation's "
                         "labels.npy)")
    try:
        text = A.read_opendrive(in_aligned_xodr)
        lanes = lane_polygons(text, params.step_m, tuple(t.lower() for t in params.road_types),
                              tuple(t.lower() for t in params.sidewalk_types))
    except OpenDriveError as exc:
        raise InputError(f"{in_aligned_xodr}: {exc.why}; re-run apply_alignment") from None
    except (OSError, UnicodeDecodeError, RuntimeError, ValueError) as exc:
        raise InputError(f"{in_aligned_xodr}: not a readable OpenDRIVE ({exc}); re-run apply_alignment") from None
    if not lanes:
        raise InputError(f"{in_aligned_xodr}: carla.Map finds no lanes in it; check the OpenDRIVE (osm_to_opendrive)")
    grid = Grid.around(mesh.vertices[:, :2], params.raster_m)
    ev = vote(mesh.vertices, mesh.faces, labels, lanes, grid, normal_min_z=params.normal_min_z,
              max_height_m=params.max_height_m, curb_min_m=params.curb_min_m, curb_max_m=params.curb_max_m,
              window_m=params.window_m, max_disagreement=params.max_disagreement,
              max_network_disagreement=params.max_network_disagreement, plateau=params.plateau,
              relabel_from=tuple(int(c) for c in params.relabel_classes))
    new = ev.labels if params.relabel else labels.copy()
    A.write_labels(out_labels_npy, new.astype(labels.dtype))
    from twinkit.cityscapes import NAMES

    name = lambda c: NAMES[c] if c < len(NAMES) else "unlabelled"  # noqa: E731
    ch = new != labels
    trans: dict[str, int] = {}
    for a, b in zip(labels[ch].tolist(), new[ch].tolist()):
        k = f"{name(a)} -> {name(b)}"
        trans[k] = trans.get(k, 0) + 1
    area = ev.area
    a = lambda m: round(float(area[m].sum()), 2)  # noqa: E731
    inl = ev.lane_vote > 0
    geo = (ev.status == S_NONGROUND_GEOM) | (ev.status == S_LEVEL)
    areas = {STATUS[s].replace(" ", "_"): a(ev.status == s) for s in STATUS if s}
    per_vote = {nm: {"lane_area_m2": a(ev.lane_vote == lv), "agree_m2": a((ev.lane_vote == lv) & (ev.status == S_AGREE)),
                     "relabelled_m2": a((ev.lane_vote == lv) & (ev.status == S_RELABEL)),
                     "disagree_geometry_m2": a((ev.lane_vote == lv) & geo),
                     "disagree_label_m2": a((ev.lane_vote == lv) & (ev.status == S_NONGROUND_LABEL))}
                for nm, lv in (("road", L_ROAD), ("sidewalk", L_SIDEWALK))}
    doc = {
        "enabled": True, "relabel": params.relabel,
        "changed_vertices": int(ch.sum()), "changed_area_m2": a(ch), "transitions": trans,
        "changed_per_class": {name(c): int(((new == c) & ch).sum()) - int(((labels == c) & ch).sum())
                              for c in sorted(set(labels[ch].tolist()) | set(new[ch].tolist()))},
        "lane_area_m2": a(inl), "areas_m2": areas, "per_vote": per_vote,
        "disagreement_area_m2": a(inl & (geo | (ev.status == S_NONGROUND_LABEL))),
        "disagreement_geometry_m2": a(inl & geo),
        "disagreement_fraction": round(float(area[inl & geo].sum() / max(area[inl].sum(), 1e-9)), 4),
        "network_disagreement": round(ev.network_disagreement, 4), "network_vetoed": ev.network_vetoed,
        "vetoed_lanes": [ln for ln in ev.lanes if ln["vetoed"]],
        "lanes": ev.lanes,
        "definition": "areas in m^2 of mesh surface (a third of each adjacent triangle per vertex) under the lanes "
                      "that vote (driving-like: road, sidewalk: sidewalk). agrees: ground-level surface of the "
                      "lane's class; relabelled: ground class changed to the lane's; disagreements: the lane lies "
                      "over raised/non-ground geometry (a building, a wall, a car body), over ground the scan calls "
                      "a non-ground class, or on the wrong level (sidewalk lane on the carriageway level, driving "
                      "lane on a raised pavement); vetoed: a lane or road mostly disagreeing casts no vote",
        "params": {k: getattr(params, k) for k in params.__dataclass_fields__},
    }
    metrics = {"changed_vertices": int(ch.sum()), "changed_area_m2": a(ch),
               "disagreement_geometry_m2": doc["disagreement_geometry_m2"],
               "disagreement_fraction": doc["disagreement_fraction"], "vetoed_lanes": len(doc["vetoed_lanes"]),
               "network_disagreement": doc["network_disagreement"], "network_vetoed": ev.network_vetoed}
    if in_gt_labels_npy is not None:
        gt = A.read_labels(in_gt_labels_npy)
        if len(gt) == len(labels):
            before, after = _iou(labels, gt), _iou(new, gt)
            doc["evaluation"] = {"iou_before": before, "iou_after": after}
            metrics["iou_before"] = {k: before[k] for k in ("road", "sidewalk", "terrain", "miou") if k in before}
            metrics["iou_after"] = {k: after[k] for k in ("road", "sidewalk", "terrain", "miou") if k in after}
            ctx.log.info("vs ground truth: road %.1f -> %.1f, sidewalk %.1f -> %.1f, terrain %.1f -> %.1f, "
                         "mIoU %.1f -> %.1f", before.get("road", 0), after.get("road", 0), before.get("sidewalk", 0),
                         after.get("sidewalk", 0), before.get("terrain", 0), after.get("terrain", 0),
                         before["miou"], after["miou"])
    out_road_evidence_json.write_text(json.dumps(doc, indent=1))
    draw_evidence(mesh.vertices, mesh.faces, labels, ev if params.relabel else _unchanged(ev, labels), lanes,
                  out_road_evidence_png, params.picture_px_per_m)
    ctx.log.info("road network evidence: %d vertices (%.1f m^2) relabelled %s; lanes disagree with the scan's "
                 "geometry over %.1f m^2 (%.1f %% of the lanes' area), %d lanes vetoed", int(ch.sum()), a(ch), trans,
                 doc["disagreement_geometry_m2"], 100 * doc["disagreement_fraction"], len(doc["vetoed_lanes"]))
    if ev.network_vetoed:
        ctx.log.warning("the network's driving lanes disagree with the scan's ground over %.0f %% of their surface "
                        "(more than max_network_disagreement %.0f %%): a wrong or outdated OSM, or a failed alignment? "
                        "No label changed; see road_evidence.png", 100 * ev.network_disagreement,
                        100 * params.max_network_disagreement)
    return metrics


def _unchanged(ev, labels):
    import dataclasses

    return dataclasses.replace(ev, labels=labels.copy())


def _iou(pred, gt) -> dict:
    """Per-class IoU (percent) over the classes present in the ground truth, and their mean (the segmentation
    plugin's definition: unlabelled predictions are misses, unlabelled ground truth is left out)."""
    import numpy as np

    from twinkit.cityscapes import N_CLASSES, NAMES

    gt = np.asarray(gt).astype(np.int64)
    pred = np.asarray(pred).astype(np.int64)
    valid = gt < N_CLASSES
    g, p = gt[valid], pred[valid]
    out = {}
    for c in np.unique(g):
        tp = int(((p == c) & (g == c)).sum())
        fp = int(((p == c) & (g != c)).sum())
        fn = int(((p != c) & (g == c)).sum())
        out[NAMES[c]] = round(100.0 * tp / max(tp + fp + fn, 1), 2)
    out["miou"] = round(float(np.mean(list(out.values()))), 2) if out else 0.0
    return out


@hookimpl
def twinkit_register_road_sources(register):
    from .preflight import file_preflight, osm_api_preflight, overpass_preflight

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

    register("scan", scan_source, params=ScanSourceParams, version=VERSION,
             description="roads derived from the scan itself (no OSM): the labelled road surface, curbs and "
                         "sidewalks of the textured mesh -> lanes -> OpenDRIVE (scan_roads.json, scan_roads.png)")
    register("opendrive", opendrive_source, params=OpenDriveSourceParams, version=VERSION,
             description="an existing OpenDRIVE map (site.inputs.xodr or road_source.path) moved from its "
                         "geoReference into the site frame")


@hookimpl
def twinkit_register_steps(register):
    register("osm_to_opendrive", osm_to_opendrive, params=ConvertParams, version=VERSION,
             description="OSM -> OpenDRIVE with netconvert in the site frame; checked with carla.Map")
    register("roads_overview", roads_overview, params=OverviewParams, version=VERSION,
             description="top view of the road network without a mesh (lanes by type); roads_overview.png")
    register("align_roads", align_roads, params=AlignParams, version=VERSION,
             description="fit the road network to the mesh's road surface (yaw, translation); alignment.json")
    register("apply_alignment", apply_alignment, params=ApplyParams, version=VERSION,
             description="move the OpenDRIVE by alignment.json; top-down QA picture")
    register("place_signals", place_signals, params=SignalParams, version=VERSION,
             description="OpenDRIVE signals at the scanned traffic lights and signs; signals.json, signals.png")
    register("road_evidence", road_evidence, params=RoadEvidenceParams, version=VERSION,
             description="the aligned lanes vote road / sidewalk on ground-level surface; labels.npy, "
                         "road_evidence.json, road_evidence.png (disagreements reported)")

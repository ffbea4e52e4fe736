"""The scan road source's flow: derive the network, dress it (sidewalks, heights, signals), check it against
the scan before and after netconvert until its lanes lie on scanned ground; then its report and metrics."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .checks import (check_lanes, check_sidewalks, cut_arms, detach_junctions, narrow_arms, new_turns, nudge_arms,
                     parked_faces, trim_unsupported)
from .measures import describe, lanes_on_road, network_length, record_stage
from .model import Network, NoRoads, ScanSourceParams
from .netconvert import netconvert_plain, write_plain, write_turns
from .network import add_heights_and_signals, add_sidewalks, carriageway_level, derive_network


def build_network(mesh, labels_for_mask, labels, p: ScanSourceParams, proj: str, out_xodr: Path, log, *,
                  curbs: bool, spacing: float | None, points_xy: np.ndarray | None) -> tuple[Network, dict]:
    """The checked network of a mesh (site frame) and netconvert's info; the map is at ``out_xodr`` (its
    plain files beside it in scan_plain/). ``labels_for_mask`` draws the carriageway, ``labels`` the sidewalks
    and signals. Raises NoRoads when no road holds up."""
    from twinkit.surface.closest import Surface

    net = derive_network(mesh.vertices, mesh.faces, labels_for_mask, p, log, curbs=curbs, rgb=mesh.colors, points_xy=points_xy)
    net.stats["curbs"] = curbs
    net.stats["point_spacing_m"] = spacing
    derived_m = network_length(net)
    record_stage(net, "derived")
    if p.sidewalks and curbs:
        add_sidewalks(net, mesh.vertices, mesh.faces, labels, p)
    add_heights_and_signals(net, mesh.vertices, mesh.faces, labels, p)
    scene = Surface(np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces)).scene  # one BVH for both checks
    cut = trim_unsupported(net, mesh.vertices, mesh.faces, p, scene=scene)
    if cut["cut_m"] or cut["dropped_roads"]:
        log.info("road_source=scan: %.1f m of road ends cut back and %d roads dropped where their lanes left the "
                 "scanned ground", cut["cut_m"], cut["dropped_roads"])
    record_stage(net, "trim_unsupported")
    work = out_xodr.parent / "scan_plain"
    rounds = []
    parked = parked_faces(np.asarray(mesh.faces), labels, curbs)
    zr = carriageway_level(net, mesh.vertices, mesh.faces)  # the junctions' connecting roads follow it
    bare = None
    if p.open_gap_m > 0:  # the ground the scan never measured (parked cars cover nothing: lift_movables takes them)
        from twinkit.surface.watertight import OpenGround

        kept = np.asarray(mesh.faces) if parked is None else np.asarray(mesh.faces)[~parked]
        bare = OpenGround.of_mesh(mesh.vertices, kept, p.open_gap_m)
    settled: bool | None = None if p.lane_check_rounds == 0 else False
    for rnd in range(p.lane_check_rounds + 1):
        nod, edg = write_plain(net, p, proj, work)
        info = netconvert_plain(nod, edg, out_xodr, p, log, surface=lambda xy: net.grid.sample(zr, xy),
                                con=write_turns(net, edg, work))
        if rnd == p.lane_check_rounds:
            break
        row = check_round(net, out_xodr.read_text(encoding="utf-8"), mesh, p, scene, rnd, log, parked, bare)
        rounds.append(row)
        record_stage(net, f"lane_check {rnd + 1}")
        if row.get("settled"):
            row.pop("settled")
            settled = True
            break
    net.stats["lane_check"] = rounds
    net.stats["lane_check_settled"] = settled
    if settled is False:
        log.warning("road_source=scan: the lane check still changed the network in its last round "
                    "(lane_check_rounds=%d): the map netconvert built after it was not checked again; the drop "
                    "test judges it", p.lane_check_rounds)
    kept_m = network_length(net)
    net.stats.update({"derived_m": round(derived_m, 1), "kept_m": round(kept_m, 1),
                      "kept_share": round(kept_m / derived_m, 3) if derived_m else None})
    return net, info


def check_round(net: Network, xodr_text: str, mesh, p: ScanSourceParams, scene, rnd: int, log,
                parked: np.ndarray | None = None, bare=None) -> dict:
    """One lane check of netconvert's map (junctions included) against the scan, and the network's repair:
    narrowed, moved, cut, junctions taken apart (``parked``: faces of parked vehicles, ``bare``: the ground the
    scan never measured, ``check_lanes``). Returns the round's row (``settled``: nothing more to do)."""
    chk = check_lanes(net, xodr_text, mesh.vertices, mesh.faces, p, scene, parked=parked, unscanned=bare)
    row = {"round": rnd + 1, "samples": chk["samples"], "on_share": chk["on_share"],
           "unscanned_samples": chk["bare_samples"],
           "junctions_off": {f"n{k}": v for k, v in chk["bad_junctions"].items()},
           "roads_off": len(chk["bad_points"])}
    turns = new_turns(chk["bad_turns"], net.no_turns)
    net.no_turns.extend(turns)
    row["turns_dropped"] = len(turns)
    walks = check_sidewalks(net, xodr_text, p, scene)
    if walks:
        row["sidewalks_changed"] = walks
        log.info("road_source=scan: check %d: %s (the scanned pavement does not hold them: CARLA's walkers would "
                 "fall through)", rnd + 1, "; ".join(
                     f"road {w['road']}'s {w['side']} sidewalk "
                     + (f"narrowed {w['from_m']:.2f} -> {w['to_m']:.2f} m" if w["to_m"] > 0 else
                        f"dropped ({w['from_m']:.2f} m wide, its kerb band on the scan over "
                        f"{100 * w['kerb_band_on']:.0f} % of it)") for w in walks))
    if (not chk["bad_points"] and not chk["bad_junctions"] and not chk["narrow"] and not chk["nudge"] and not walks
            and not turns):
        return {**row, "settled": True}
    before = (len(net.arms), sum(len(a.xy) for a in net.arms), len(net.nodes))
    row["roads_narrowed"] = narrow_arms(net, chk["narrow"], p)  # in place: the indices stay
    row["roads_moved"] = nudge_arms(net, chk["nudge"], p)
    cut2 = cut_arms(net, chk["bad_points"], p, keep_junction_ends=False)
    gone = detach_junctions(net, [k for k in chk["bad_junctions"] if k in net.nodes], p)
    row.update({"cut_m": cut2["cut_m"], "dropped_roads": cut2["dropped_roads"] + gone})
    after = (len(net.arms), sum(len(a.xy) for a in net.arms), len(net.nodes))
    if not row["roads_narrowed"] and not row["roads_moved"] and after == before and not walks and not turns:
        return {**row, "settled": True}  # what is off cannot be cut (single shape points): the drop test reports it
    log.info("road_source=scan: check %d: %.1f %% of the driving-lane samples on the scanned surface%s; %d "
             "road(s) off it in places (%.1f m cut), %d narrowed, %d junction(s) taken apart (%s), %d road(s) "
             "dropped, %d turn(s) off the scanned surface or over ground it never measured dropped; netconvert "
             "again", rnd + 1,
             100 * chk["on_share"],
             f" ({chk['bare_samples']} over ground the scan never measured: its sparse far range or beyond its edge)"
             if chk["bare_samples"] else "", len(chk["bad_points"]), cut2["cut_m"],
             row["roads_narrowed"],
             len(chk["bad_junctions"]), ", ".join(f"n{k}: {100 * v:.0f} % on" for k, v in
                                                 chk["bad_junctions"].items()) or "-",
             row["dropped_roads"], len(turns))
    if not net.arms:
        raise NoRoads("none of the roads derived from the scan keeps its lanes on the scanned surface (they "
                      "float over banks or sink into slopes)", derived=True)
    return row


def scan_report(net: Network, text: str, mesh, labels, which: str, src: Path | None, info: dict,
                p: ScanSourceParams, truth: list[np.ndarray] | None) -> dict:
    """scan_roads.json's document (without total_s): the network, netconvert's info, the parameters, lanes on
    road (with labels) and the centre lines' RMSE to the truth (when known)."""
    doc = describe(net)
    doc.update({"labels": which, "labels_file": str(src) if src else None, **info,
                "definition": "roads derived from the scan: carriageway = road-labelled surface"
                              + (" on the level below the curbs" if p.use_curbs and net.stats.get("curbs", True)
                                 else "") + "; axes = its skeleton, centred between the edges; lanes of lane_width_m per "
                              "direction, a remainder >= min_strip_m a parking strip at the curb; sidewalk lanes "
                              "where sidewalk surface lies beyond the curb; junctions by netconvert",
                "params": {k: getattr(p, k) for k in p.__dataclass_fields__}})
    if labels is not None:
        doc["lanes_on_road"] = lanes_on_road(text, mesh.vertices, mesh.faces, labels)
    if truth:
        from ..align import centreline_rmse

        allp = np.concatenate(truth)
        lo, hi = allp.min(0) + 2.0, allp.max(0) - 2.0
        rmse, n = centreline_rmse(text, truth, (lo[0], lo[1], hi[0], hi[1]))
        doc["centreline_rmse_m"] = round(rmse, 4)
        doc["centreline_points"] = n
    return doc


def scan_metrics(net: Network, doc: dict, which: str, p: ScanSourceParams, log) -> dict:
    """The step's metrics, logged, with the warnings a person should see (lanes off road, little kept)."""
    n_roads, n_j = len(net.arms), sum(nd["kind"] == "junction" for nd in net.nodes.values())
    n_lanes = sum(a.lanes["lanes"] * (2 if a.lanes["two_way"] else 1) for a in net.arms)
    log.info("roads from the scan (%s; labels: %s): %d roads, %d junctions, %d driving lanes, %d sidewalk lanes; "
             "%.1f s", net.stats["carriageway_from"], which, n_roads, n_j, n_lanes,
             sum((a.sidewalk_left_m > 0) + (a.sidewalk_right_m > 0) for a in net.arms), doc["total_s"])
    metrics = {"roads": n_roads, "junctions": n_j, "driving_lanes": n_lanes, "labels": which,
               "carriageway_m2": net.stats["carriageway_m2"], "total_s": doc["total_s"]}
    if "lanes_on_road" in doc:
        metrics["lanes_on_road_share"] = doc["lanes_on_road"]["on_road_share"]
        if doc["lanes_on_road"]["on_road_share"] < 0.9:
            log.warning("only %.0f %% of the derived driving lanes lie on road-labelled surface: check "
                        "scan_roads.png", 100 * doc["lanes_on_road"]["on_road_share"])
    if net.stats.get("kept_share") is not None:
        metrics["kept_share"] = net.stats["kept_share"]
        if net.stats["kept_share"] < p.min_kept_share:
            log.warning("the checks against the scan kept only %.0f %% of the %.0f m of road derived from it (lanes "
                        "over walls, hedges, banks or roofs were cut; scan_roads.json lane_check): the map covers "
                        "less of the streets than the scan shows, see scan_roads.png; an OSM extract "
                        "(site.inputs.osm) gives the whole network", 100 * net.stats["kept_share"],
                        net.stats["derived_m"])
    if "centreline_rmse_m" in doc:
        metrics["centreline_rmse_m"] = doc["centreline_rmse_m"]
        log.info("derived lane centre lines vs truth: RMSE %.3f m (%d points), lanes on road %.1f %%",
                 doc["centreline_rmse_m"], doc["centreline_points"],
                 100 * doc.get("lanes_on_road", {}).get("on_road_share", float("nan")))
    return metrics


def no_roads_report(exc: NoRoads, which: str) -> tuple[dict, dict]:
    """scan_roads.json's document (without total_s) and the metrics when the scan holds no road."""
    why = str(exc)
    doc = {"roads": [], "nodes": [], "no_roads": why, "derived_then_dropped": bool(exc.derived), "labels": which,
           "definition": "no road in the scan: opendrive.xodr holds no road (userData twinkit_roads=none); the twin "
                         "has no road network"}
    metrics = {"roads": 0, "junctions": 0, "driving_lanes": 0, "labels": which, "no_roads": True}
    return doc, metrics

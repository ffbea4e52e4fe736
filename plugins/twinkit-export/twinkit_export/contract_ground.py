"""Package rule ``lanes_over_ground``: every lane waypoint of the package's OpenDRIVE has the map's mesh beneath it.

What CARLA does with the lanes: the traffic manager drives every autopilot vehicle along the waypoints of the
driving lanes (``InMemoryMap::SetUp`` in ``LibCarla/source/carla/trafficmanager/InMemoryMap.cpp`` builds its graph
from ``Map::GenerateWaypoints``, ``LibCarla/source/carla/road/Map.cpp``, which walks every ``Driving`` lane), and
keeps them on a lane to its end: a lane end with a successor leads on (netconvert's dead-end turnarounds), one
without removes the vehicle (``LocalizationStage::Update`` in ``LocalizationStage.cpp``: ``marked_for_removal``
when ``GetNextWaypoint()`` is empty). Nothing checks that there is ground under the lane: a waypoint past the
mesh is driven over the void (the vehicle falls or hangs on the mesh's edge).

The check: CARLA's waypoints every ``step_m`` (1 m; :class:`twinkit.street.lanes.LaneMap`, the ``carla`` wheel
offline) against the map FBX's meshes (the meshes ``make import`` places, read from the FBX:
:func:`twinkit_export.fbxbin.mesh_arrays`), with the one rule of :mod:`twinkit.street.lane_ground` (the mesh
crosses the waypoint's vertical within ``band_m``, 0.5 m, of its height). A violation: the waypoints off the
ground in a group (nearby waypoints off the ground) that stays within ``EDGE_M`` (5 m) of the mesh (:func:`past_the_edge`): a lane that
runs a little past the scan, where the map ends (netconvert's turnaround bulging past the mesh, a road end beyond
it). A lane that runs on far beyond the mesh belongs to a map larger than the scan (``road_source=opendrive`` of a
whole town, an OSM extract wider than the scan): counted (``beyond_scan``), not a violation; the trim
(``twinkit_roads.ground_ends``) cuts only the map's ends. The message names the count and the first ones.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

SRC_LANES = ("LibCarla/source/carla/trafficmanager/InMemoryMap.cpp (SetUp), LocalizationStage.cpp (Update); "
             "LibCarla/source/carla/road/Map.cpp (GenerateWaypoints)")
#: metres: a run of waypoints off the ground that stays this close to the mesh runs past its edge (a turnaround's
#: bulge, a road end); farther out, the map is larger than the scan
EDGE_M = 5.0
RULE = ("the traffic manager drives every waypoint of the driving lanes to the lane's end; no waypoint (every 1 m) "
        "may run past the edge of the map's mesh (off the ground, within 5 m of the mesh) with no ground beneath it "
        "(within 0.5 m of its height)", SRC_LANES)


def map_ground(fbx: Path) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (n, 3) metres, triangles (m, 3)) of every mesh of the map FBX, in the package's frame."""
    from .fbxbin import mesh_arrays

    parts = mesh_arrays(fbx)
    if not parts:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    offs = np.cumsum([0] + [len(v) for _, v, _ in parts])
    return np.vstack([v for _, v, _ in parts]), np.vstack([f + o for (_, _, f), o in zip(parts, offs)])


def lanes_over_map_ground(xodr: Path, ground, step_m: float = 1.0, band_m: float | None = None):
    """The package map's waypoints against its mesh (:class:`twinkit.street.lane_ground.LanesOverGround`);
    ``ground``: the map FBX's path, or its (vertices, faces) (:func:`map_ground`)."""
    from twinkit.street.lane_ground import GROUND_BAND_M, lanes_over_ground
    from twinkit.street.lanes import LaneMap

    vertices, faces = map_ground(ground) if isinstance(ground, (str, Path)) else ground
    lm = LaneMap(xodr.read_text(encoding="utf-8"), xodr.stem, source=xodr)
    return lanes_over_ground(lm, vertices, faces, step_m=step_m, band_m=GROUND_BAND_M if band_m is None else band_m)


def past_the_edge(res, vertices: np.ndarray, edge_m: float = EDGE_M) -> np.ndarray:
    """(n,) bool: the waypoints of ``res`` off the ground in a group that stays within ``edge_m`` of the mesh
    (horizontally, to its nearest vertex). A group: waypoints off the ground joined when closer than twice the
    waypoint step (one lane's run, and the lanes beside it). Such a group is a lane running a little past the scan
    (a turnaround's bulge, a road end); a group reaching farther belongs to a map larger than the scan."""
    from scipy.spatial import cKDTree

    from twinkit.surface.linked import linked_groups

    off = np.flatnonzero(res.off)
    out = np.zeros(len(res.off), bool)
    if not len(off) or not len(vertices):
        return out
    xy = res.xyz[off, :2]
    dist, _ = cKDTree(vertices[:, :2]).query(xy, workers=-1)
    n, lab = linked_groups(xy, 2.0 * res.step_m)
    far = np.zeros(n, bool)
    np.logical_or.at(far, lab, dist > edge_m)
    out[off[~far[lab]]] = True
    return out


def check_lanes_over_ground(rep, pkg: Path, maps: list, step_m: float = 1.0) -> list[dict]:
    """Add a ``lanes_over_ground`` violation to ``rep`` (a ``ContractReport``) for each map of the description
    (``maps``: its entries, ``source`` and ``xodr`` relative to ``pkg``) with waypoints past the edge of its mesh
    (:func:`past_the_edge`); returns each map's counts (``LanesOverGround.summary`` and ``past_edge``)."""
    out = []
    for m in maps:
        if not isinstance(m, dict) or not m.get("source") or not m.get("xodr"):
            continue  # the json rule reports incomplete entries
        src, xodr = pkg / str(m["source"]), pkg / str(m["xodr"])
        if not (src.is_file() and xodr.is_file()):
            continue
        try:
            vertices, faces = map_ground(src)
            res = lanes_over_map_ground(xodr, (vertices, faces), step_m)
        except Exception as exc:  # noqa: BLE001 - an FBX or OpenDRIVE the check cannot read is a violation
            rep.add("lanes_over_ground", f"{src.name} / {xodr.name}: the lanes could not be checked against the "
                                         f"mesh ({type(exc).__name__}: {exc})")
            continue
        edge = past_the_edge(res, vertices)
        s = res.summary(limit=0)
        s.update({"map": str(m.get("name", src.stem)), "past_edge": int(edge.sum()),
                  "beyond_scan": int(res.off.sum() - edge.sum())})
        out.append(s)
        if edge.any():
            where = "; ".join(f"road {res.road[i]} lane {res.lane[i]} s {res.s[i]:.1f} at ({res.xyz[i, 0]:.2f}, "
                              f"{res.xyz[i, 1]:.2f})" for i in np.flatnonzero(edge)[:5])
            rep.add("lanes_over_ground", f"{xodr.name}: {int(edge.sum())} of {s['points']} lane waypoints (every "
                                         f"{step_m:g} m) run past the edge of {src.name} with no ground beneath: the "
                                         f"traffic manager drives them over the void ({where}); cut the map's ends "
                                         f"back (steps.apply_alignment.trim_to_ground)")
    return out

"""Lanes over the scanned ground: which lane points have the ground mesh beneath them.

The one rule, used by the road steps (trimming road ends to the scan: ``twinkit_roads.ground_ends``), the CARLA
package's checker (``twinkit_export.contract_ground``) and the benchmarks: a lane point (x, y, z; site or package
frame, metres, z up) has ground beneath when a vertical ray through (x, y) meets the mesh within ``band_m`` of z
(:func:`twinkit.surface.watertight.drop_test` with ``tol_m=band_m``). The band is wide (0.5 m) on purpose: it
asks "is there a surface under the lane at all", not "is it at the lane's exact height" (the drop test's 5 cm
question); a roof or a tree crown metres above or below the lane does not count.

Lane points come from CARLA's own parser (:class:`twinkit.street.lanes.LaneMap`): the driving lanes' waypoints
(``generate_waypoints``, what CARLA's traffic manager drives on) and, with ``every_lane``, every lane reached
sideways from them (sidewalks, shoulders, ...).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: metres: a lane point has ground beneath when the mesh crosses its vertical within this of its height
GROUND_BAND_M = 0.5


def on_ground(xyz: np.ndarray, vertices: np.ndarray, faces: np.ndarray, band_m: float = GROUND_BAND_M,
              scene=None) -> np.ndarray:
    """(n,) bool: the mesh (``vertices`` (v, 3) float, ``faces`` (f, 3) int) crosses the vertical through each
    point of ``xyz`` (n, 3) within ``band_m`` of the point's z. ``scene``: the mesh's open3d raycasting scene
    when the caller casts several sets of rays on one mesh."""
    from twinkit.surface.watertight import drop_test

    p = np.asarray(xyz, float).reshape(-1, 3)
    return drop_test(np.asarray(vertices, float), np.asarray(faces), p, band_m, scene=scene)


@dataclass
class LanesOverGround:
    """Lane points of a map against a ground mesh: ``xyz`` (n, 3) float the points (the map's frame),
    ``road`` / ``lane`` (n,) int64 their ids, ``s`` (n,) float64 m along the road, ``type`` (n,) str CARLA's
    lane type, ``ground`` (n,) bool the ground beneath (:func:`on_ground`); ``step_m`` the spacing."""

    xyz: np.ndarray
    road: np.ndarray
    lane: np.ndarray
    s: np.ndarray
    type: np.ndarray
    ground: np.ndarray
    step_m: float

    @property
    def off(self) -> np.ndarray:
        """(n,) bool: the points without ground beneath."""
        return ~self.ground

    def summary(self, limit: int = 20) -> dict:
        """Counts (points, off the ground, per lane type) and the first ``limit`` points off the ground."""
        off = np.flatnonzero(self.off)
        types: dict[str, list[int]] = {}
        for t, g in zip(self.type.tolist(), self.ground.tolist()):
            n = types.setdefault(str(t), [0, 0])
            n[0] += 1
            n[1] += int(not g)
        return {"step_m": self.step_m, "points": int(len(self.ground)), "off_ground": int(len(off)),
                "by_type": {k: {"points": v[0], "off_ground": v[1]} for k, v in sorted(types.items())},
                "off_ground_at": [{"road": int(self.road[i]), "lane": int(self.lane[i]), "s": round(float(self.s[i]), 2),
                                   "x": round(float(self.xyz[i, 0]), 2), "y": round(float(self.xyz[i, 1]), 2),
                                   "type": str(self.type[i])} for i in off[:limit]]}


def lanes_over_ground(lane_map, vertices: np.ndarray, faces: np.ndarray, *, step_m: float = 1.0,
                      band_m: float = GROUND_BAND_M, every_lane: bool = False, scene=None) -> LanesOverGround:
    """The lane points of ``lane_map`` (a :class:`twinkit.street.lanes.LaneMap`) every ``step_m`` and the ground
    beneath each: the driving waypoints (CARLA's ``generate_waypoints``), or with ``every_lane`` every lane reached
    sideways from them. ``vertices`` / ``faces``: the ground mesh in the map's frame."""
    smp = lane_map.lanes(step_m) if every_lane else lane_map.waypoints(step_m).unique(3)
    ground = on_ground(smp.xyz, vertices, faces, band_m, scene=scene) if len(smp) else np.zeros(0, bool)
    return LanesOverGround(smp.xyz, smp.road, smp.lane, smp.s, smp.type, ground, float(step_m))

"""Child process: parse an OpenDRIVE file with carla.Map offline and report on it as one JSON line.

    python -m twinkit_roads.xodrcheck file.xodr '[xmin, ymin, xmax, ymax]' 2.0 [samples.npy]

With a fourth argument, the lane centres of the waypoints are saved there as an (n, 6) array:
x, y, z (site frame), road id, lane id, s. The map is read through :class:`twinkit.street.lanes.LaneMap`.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

#: OpenDRIVE signal types CARLA makes traffic lights of
TRAFFIC_LIGHT_TYPES = ("1000001", "1000002", "1000011")


def main(argv: list[str]) -> int:
    path, bounds, step = Path(argv[0]), json.loads(argv[1]), float(argv[2])
    t0 = time.perf_counter()
    from twinkit.street.lanes import LaneMap, OpenDriveError

    try:
        m = LaneMap.from_file(path, path.stem or "site")
    except OpenDriveError as exc:  # reported to the parent
        print(json.dumps({"error": str(exc)}))
        return 0
    t_parse = time.perf_counter() - t0
    topo = m.topology()
    wps = m.waypoints(step)
    t_wp = time.perf_counter() - t0 - t_parse
    import numpy as np

    xmin, ymin, xmax, ymax = bounds
    x, y = wps.xyz[:, 0], wps.xyz[:, 1]
    inside = int(((xmin <= x) & (x <= xmax) & (ymin <= y) & (y <= ymax)).sum())
    junctions = set(wps.junction[wps.in_junction].tolist())
    lane_types: dict[str, int] = {}
    for t in wps.type:
        lane_types[t] = lane_types.get(t, 0) + 1
    if len(argv) > 3:
        np.save(argv[3], np.c_[wps.xyz, wps.road, wps.lane, wps.s].astype(float).reshape(-1, 6))
    marks = m.landmarks()
    lights = [lm for lm in marks if lm.type in TRAFFIC_LIGHT_TYPES]
    print(json.dumps({"topology_segments": len(topo), "waypoints": len(wps), "waypoints_inside": inside,
                      "junctions_with_waypoints": len(junctions), "landmarks": len(marks),
                      "traffic_light_landmarks": len(lights), "lane_types": lane_types,
                      "parse_s": round(t_parse, 3), "waypoints_s": round(t_wp, 3)}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

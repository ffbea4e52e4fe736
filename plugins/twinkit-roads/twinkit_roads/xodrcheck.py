"""Child process: parse an OpenDRIVE file with carla.Map offline and report on it as one JSON line.

    python -m twinkit_roads.xodrcheck file.xodr '[xmin, ymin, xmax, ymax]' 2.0 [samples.npy]

With a fourth argument, the lane centres of the waypoints are saved there as an (n, 6) array:
x, y (site convention), z, road id, lane id, s.

CARLA's frame is left-handed: a waypoint at carla (x, y) is at site (x, -y).
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path


def main(argv: list[str]) -> int:
    path, bounds, step = Path(argv[0]), json.loads(argv[1]), float(argv[2])
    t0 = time.perf_counter()
    import carla

    text = path.read_text(encoding="utf-8")
    try:
        m = carla.Map(path.stem or "site", text)
    except Exception as exc:  # noqa: BLE001 - reported to the parent
        print(json.dumps({"error": f"{type(exc).__name__}: {exc}"}))
        return 0
    t_parse = time.perf_counter() - t0
    topo = m.get_topology()
    wps = m.generate_waypoints(step)
    t_wp = time.perf_counter() - t0 - t_parse
    xmin, ymin, xmax, ymax = bounds
    inside = 0
    junctions = set()
    lane_types: dict[str, int] = {}
    for w in wps:
        loc = w.transform.location
        x, y = loc.x, -loc.y
        if xmin <= x <= xmax and ymin <= y <= ymax:
            inside += 1
        if w.is_junction:
            junctions.add(w.junction_id)
        lane_types[str(w.lane_type)] = lane_types.get(str(w.lane_type), 0) + 1
    if len(argv) > 3:
        import numpy as np

        np.save(argv[3], np.array([(w.transform.location.x, -w.transform.location.y, w.transform.location.z,
                                    w.road_id, w.lane_id, w.s) for w in wps], float).reshape(-1, 6))
    lights = [lm for lm in m.get_all_landmarks() if lm.type in ("1000001", "1000002", "1000011")]
    print(json.dumps({"topology_segments": len(topo), "waypoints": len(wps), "waypoints_inside": inside,
                      "junctions_with_waypoints": len(junctions), "landmarks": len(m.get_all_landmarks()),
                      "traffic_light_landmarks": len(lights), "lane_types": lane_types,
                      "parse_s": round(t_parse, 3), "waypoints_s": round(t_wp, 3)}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

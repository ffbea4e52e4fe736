"""The demo street's road truth and its OSM extract, from the layout's dimensions and road marks."""
from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from twinkit_demo_site.layout import Dims, Marks

def roads_truth(d: Dims, m: Marks) -> dict:
    """roads_truth.json: the roads, junction, lanes (driving direction) and crossings in the site frame."""
    H, rm, rs = d.half_m, d.rm, d.rs
    zx0, zx1, zy0, zy1 = m.zx0, m.zx1, m.zy0, m.zy1
    lane_lines = []
    for yl, dirn in ((-d.lane_m * 1.5, 1), (-d.lane_m * 0.5, 1), (d.lane_m * 0.5, -1), (d.lane_m * 1.5, -1)):
        xs_line = [-H, H] if dirn > 0 else [H, -H]
        lane_lines.append({"road": "main", "direction": "east" if dirn > 0 else "west",
                           "points": [[xs_line[0], yl, 0.0], [xs_line[1], yl, 0.0]]})
    for xl_ in (-d.lane_m / 2, d.lane_m / 2):
        lane_lines.append({"road": "side_north", "direction": "south", "points": [[xl_, H, 0.0], [xl_, rm, 0.0]]})
    lane_lines.append({"road": "side_south", "direction": "south", "points": [[-d.lane_m / 2, -rm, 0.0], [-d.lane_m / 2, -H, 0.0]]})
    lane_lines.append({"road": "side_south", "direction": "north", "points": [[d.lane_m / 2, -H, 0.0], [d.lane_m / 2, -rm, 0.0]]})
    return {
        "frame": "site local (metres, x east, y north, z up; origin = base point)",
        "roads": [
            {"name": "main", "centerline": [[-H, 0.0, 0.0], [H, 0.0, 0.0]], "width_m": 2 * rm,
             "lanes": 4, "oneway": False, "parking_strip_m": d.park_m,
             "polygon": [[-H, -rm], [H, -rm], [H, rm], [-H, rm]]},
            {"name": "side_north", "centerline": [[0.0, H, 0.0], [0.0, rm, 0.0]], "width_m": 2 * rs, "lanes": 2, "oneway": True,
             "polygon": [[-rs, rm], [rs, rm], [rs, H], [-rs, H]]},
            {"name": "side_south", "centerline": [[0.0, -rm, 0.0], [0.0, -H, 0.0]], "width_m": 2 * rs, "lanes": 2, "oneway": False,
             "polygon": [[-rs, -H], [rs, -H], [rs, -rm], [-rs, -rm]]},
        ],
        "junction": {"polygon": [[-rs, -rm], [rs, -rm], [rs, rm], [-rs, rm]], "traffic_signals": True},
        "lanes": lane_lines,
        "crossings": [
            {"road": "main", "polygon": [[zx0, -rm], [zx1, -rm], [zx1, rm], [zx0, rm]]},
            {"road": "main", "polygon": [[-zx1, -rm], [-zx0, -rm], [-zx0, rm], [-zx1, rm]]},
            {"road": "side_north", "polygon": [[-rs, zy0], [rs, zy0], [rs, zy1], [-rs, zy1]]},
            {"road": "side_south", "polygon": [[-rs, -zy1], [rs, -zy1], [rs, -zy0], [-rs, -zy0]]},
        ],
        "sidewalk_width_m": d.sidewalk_m,
        "curb_height_m": d.curb_m,
    }


def osm_extract(d: Dims, m: Marks) -> dict:
    """The OpenStreetMap view of the junction in the true site frame: nodes id -> (x, y, tags), ways."""
    H = d.half_m
    zxm, zym = (m.zx0 + m.zx1) / 2, (m.zy0 + m.zy1) / 2
    return {
        "nodes": {  # id -> (x, y, tags)
            1: (-H, 0.0, {}), 2: (-zxm, 0.0, {"highway": "crossing", "crossing": "zebra", "crossing:markings": "zebra"}),
            3: (0.0, 0.0, {"highway": "traffic_signals"}),
            4: (zxm, 0.0, {"highway": "crossing", "crossing": "zebra", "crossing:markings": "zebra"}), 5: (H, 0.0, {}),
            6: (0.0, H, {}), 7: (0.0, zym, {"highway": "crossing", "crossing": "zebra", "crossing:markings": "zebra"}),
            8: (0.0, -zym, {"highway": "crossing", "crossing": "zebra", "crossing:markings": "zebra"}), 9: (0.0, -H, {}),
        },
        "ways": [
            (101, [1, 2, 3, 4, 5], {"highway": "secondary", "name": "Demokatu", "lanes": "4", "oneway": "no",
                                    "sidewalk": "both", "parking:both": "lane", "maxspeed": "40", "surface": "asphalt"}),
            (102, [6, 7, 3], {"highway": "residential", "name": "Testikuja", "lanes": "2", "oneway": "yes",
                              "sidewalk": "both", "maxspeed": "30", "surface": "asphalt"}),
            (103, [3, 8, 9], {"highway": "residential", "name": "Testikuja", "lanes": "2", "oneway": "no",
                              "lanes:forward": "1", "lanes:backward": "1", "sidewalk": "both", "maxspeed": "30", "surface": "asphalt"}),
        ],
    }

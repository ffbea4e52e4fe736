"""Roads from the scan itself: lane centre lines, carriageway and sidewalk edges from the labelled mesh.

What a person does by hand in RoadRunner from lidar, as a road source (``road_source=scan``):

1. **Carriageway mask** (top view, ``raster_m``): faces labelled road (CityScapes 0) that lie on the
   carriageway level, i.e. below the curbs: up-facing faces within ``curb_tol_m`` of the local lowest
   ground (mesh2d.road_faces' ground fit, the same curb test align_roads uses). The labels say where
   the road roughly is; the curb step draws its edge. Curb-level faces a little beyond the labels
   (``label_margin_m``) are kept, so a label edge that wanders onto the carriageway does not move the
   road. Holes (cars, mislabelled markings) are filled.
2. **Axes and topology**: the mask is thinned to a one-pixel skeleton (Zhang-Suen); its pixels form a
   graph whose nodes are junctions (3+ arms) and ends. Short spurs (from mask corners) are pruned,
   nodes closer than a junction's size are merged.
3. **Each arm**: the skeleton path is smoothed; along it the distance to the carriageway edge is
   measured on both sides (rays along the normal). Parked cars and occlusions only ever *remove*
   road from the mask, so each side's edge is a high percentile over a window along the road. The
   axis is moved to the middle of the two edges; near a junction the axis is the straight
   continuation of the arm up to the junction point (the least-squares meeting point of the arms).
4. **Lanes**: per side ``floor(half width / lane_width_m)`` lanes of ``lane_width_m``; a remainder of
   at least ``min_strip_m`` is a parking strip at the curb (OpenDRIVE type none from netconvert,
   ``strip_type``), a smaller one widens the lanes. Roads narrower than two lanes are one lane, one way.
5. **Sidewalks**: beyond each curb, the run of sidewalk-labelled surface (else the raised level);
   its robust width becomes a sidewalk lane (``min_sidewalk_m``..``max_sidewalk_m``).
6. **OpenDRIVE**: a SUMO plain network (nodes at the junctions and ends, one edge per direction with
   its lanes: sidewalk, strip, driving lanes) goes through netconvert, which builds the junctions'
   connecting roads, as for OSM. A junction with traffic-light-labelled surface near it gets a
   signal plan (netconvert's signals, moved to the scanned heads later by place_signals).
"""
from __future__ import annotations

from .build import build_network, check_round, no_roads_report, scan_metrics, scan_report
from .checks import (bare_turns, check_lanes, check_sidewalks, cut_arms, detach_junctions, lane_heights, narrow_arms, nudge_arms, parked_faces,
                     steps_across, trim_unsupported)
from .geometry import lane_layout
from .inputs import choose_curbs, cloud_sampling, cloud_xy, level_params, read_labels, read_truth
from .masks import carriageway_mask, measured
from .measures import covered, describe, in_junctions, lanes_on_road, network_length, record_stage, street_axis
from .model import Arm, Network, NoRoads, ScanSourceParams, empty_network
from .netconvert import empty_map, is_empty_map, mark_source, netconvert_plain, write_plain, write_turns
from .network import WALK_MAX_M, add_heights_and_signals, add_sidewalks, derive_network
from .picture import draw_scan_roads
from .skeleton import skeleton_graph, thin

__all__ = ["Arm", "Network", "NoRoads", "ScanSourceParams", "WALK_MAX_M", "add_heights_and_signals", "add_sidewalks",
           "bare_turns", "build_network", "carriageway_mask", "check_lanes", "check_round", "check_sidewalks", "choose_curbs", "cloud_sampling", "cloud_xy",
           "covered", "in_junctions", "level_params",
           "cut_arms", "derive_network", "describe", "detach_junctions", "draw_scan_roads", "empty_map",
           "empty_network", "is_empty_map", "lane_heights", "lane_layout", "lanes_on_road", "mark_source",
           "measured", "narrow_arms", "netconvert_plain", "network_length", "no_roads_report", "nudge_arms", "parked_faces",
           "read_labels", "read_truth", "record_stage", "scan_metrics", "scan_report", "skeleton_graph",
           "steps_across", "street_axis", "thin", "trim_unsupported", "write_plain", "write_turns"]

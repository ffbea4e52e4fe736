"""The scan road source's parameters and its network: arms (roads between nodes) and nodes (junctions, ends)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from twinkit import InputError
from twinkit.ranges import param
from twinkit.surface.density import RING_CAPTURE_SHARE


class NoRoads(InputError):
    """The scan holds no road: no carriageway, or no derived road kept its lanes on the scan (``derived``:
    roads were derived and the checks dropped them all). ``scan_source`` writes a map without roads."""

    def __init__(self, message: str, derived: bool = False):
        super().__init__(message)
        self.derived = derived


@dataclass
class ScanSourceParams:
    """road_source=scan's parameters (docs/roads.md "Roads from the scan"; its "Decisions" for the values)."""

    labels: str = param("auto", choices=("auto", "predicted", "gt", "none"),
                        help="labels drawing the road: auto = labels.npy when an earlier step wrote it, else the "
                             "curbs alone; predicted = labels.npy (required); gt = gt_labels.npy (benchmarks); "
                             "none = the curbs alone")
    raster_m: float = param(0.25, gt=0, le=2, help="top-view resolution of the carriageway mask (m)")
    curb_tol_m: float = param(0.07, ge=0, le=1,
                              help="height above the local lowest ground still on the carriageway, below the curb (m)")
    use_curbs: bool = param(True, help="false: the road labels alone draw the carriageway's edges")
    curb_max_spacing_m: float = param(0.10, ge=0, le=5,
                                      help="a cloud with a coarser median point spacing (points_meta.json) shows no "
                                           "curbs: the carriageway is the grey, up-facing, paved-labelled ground and "
                                           "no sidewalk lanes are made (0: always the curbs)")
    level_min_two_way_share: float = param(RING_CAPTURE_SHARE, ge=0, le=1,
                                           help="a cloud whose ground is mostly single scan lines (points_meta.json "
                                                "density.ground_two_way_share under this: a single spinning sweep, "
                                                "0.26-0.33 on real ones; street scans 0.99+) shows no kerb step: with "
                                                "labels, the road labels alone draw the carriageway, as "
                                                "use_curbs=false (0: never)")
    grey_max_saturation: float = param(0.10, gt=0, le=1,
                                       help="without curbs: faces with a more saturated colour ((max - min) / max of "
                                            "the vertices' RGB) are not carriageway (1: colour not used)")
    min_point_density: float = param(0.25, ge=0, le=1,
                                     help="without curbs, with the cloud: a pixel whose 2 m neighbourhood holds less "
                                          "than this share of the cloud's median density is not carriageway "
                                          "(water, unscanned gaps; 0: not used)")
    majority_m: float = param(1.5, ge=0, le=10,
                              help="without curbs: a carriageway pixel has most of the pixels in a square this wide "
                                   "paved-looking (single grey specks are not; 0: not used)")
    label_margin_m: float = param(1.5, ge=0, le=10,
                                  help="carriageway-level surface this far beyond the road labels is still road (m)")
    min_road_width_m: float = param(3.0, gt=0, help="narrower carriageway (driveways, gaps) is not a road (m)")
    bridge_m: float = param(6.0, ge=0, le=30,
                            help="a road's free end that points across a gap at most this long at more carriageway, "
                                 "over scanned level ground, is joined to it (a junction's mouth the 2D model called "
                                 "sidewalk or terrain cuts an arm off its junction; m; 0: no bridges)")
    bridge_max_step_m: float = param(0.2, ge=0, le=2,
                                     help="a bridge's ground lies within this of the straight line between the "
                                          "carriageway's heights at both its ends (m)")
    bridge_step_share: float = param(0.05, ge=0, le=1,
                                     help="the share of a bridge's ground that may lie farther than bridge_max_step_m "
                                          "off that line (a sweep's rough mesh, a verge rising at the swath's edge; "
                                          "a wall or planted island across the gap covers far more)")
    min_road_length_m: float = param(8.0, gt=0, help="shorter arms (spurs of the mask's corners) are pruned (m)")
    edge_percentile: float = param(75.0, ge=50, le=100,
                                   help="per side, this percentile of the edge distance along edge_window_m is the "
                                        "edge (cars only remove road)")
    edge_window_m: float = param(20.0, gt=0, help="length of road over which edge_percentile is taken (m)")
    lane_width_m: float = param(3.25, gt=0, le=10, help="nominal lane width, as the OSM route's default (m)")
    min_lane_width_m: float = param(2.5, gt=0, le=10,
                                    help="a road with less than this per direction has one lane, one way (m)")
    max_lane_width_m: float = param(4.5, gt=0, le=10, help="lanes are widened up to this before a strip is made (m)")
    min_strip_m: float = param(1.8, ge=0, le=10,
                               help="a remainder per side at least this wide is a parking strip at the curb (m)")
    curb_clearance_m: float = param(0.15, ge=0, le=2,
                                    help="widened lanes stop this short of the found curb; a no-traffic lane fills "
                                         "it (m)")
    strip_type: str = param("parking", choices=("parking", "driving", "none"),
                            help="the strip at the curb: parking = lane type none (no traffic), driving = another "
                                 "lane")
    sidewalks: bool = param(True, help="sidewalk lanes where the scan shows sidewalk beyond the curb")
    min_sidewalk_m: float = param(1.0, ge=0, le=20, help="narrower sidewalk surface makes no sidewalk lane (m)")
    max_sidewalk_m: float = param(6.0, gt=0, le=30, help="sidewalk lanes are at most this wide (m)")
    traffic_light_radius_m: float = param(12.0, ge=0,
                                          help="traffic-light labels within this of a junction's edge make it "
                                               "signalised (m)")
    min_traffic_light_vertices: int = param(20, ge=0,
                                            help="...with at least this many traffic-light vertices (0: no signals)")
    sample_m: float = param(2.0, gt=0, le=20, help="spacing of the road shape points (m)")
    lane_tol_m: float = param(0.3, gt=0, le=2,
                              help="lane check: a driving-lane sample is on the scan when the surface lies within "
                                   "this of the lane's height (m)")
    min_lane_support: float = param(0.8, ge=0, le=1,
                                    help="lane check: a road stretch or junction with a smaller share of its samples "
                                         "on the scan is cut out or taken apart, and netconvert runs again")
    lane_check_rounds: int = param(8, ge=0, le=20,
                                   help="at most this many lane checks and netconvert reruns; the loop ends sooner "
                                        "when a check finds nothing to change (the map that ships is then the map "
                                        "last checked)")
    edge_band_m: float = param(0.5, ge=0, le=3,
                               help="lane check: a side whose outermost band this wide is off the scan while the "
                                    "rest is on is narrowed by it per round (0: no narrowing; m)")
    lane_step_m: float = param(0.1, ge=0, le=2,
                               help="lane check: a larger height step between neighbouring samples across a lane "
                                    "puts the sample off the scan (a low wall; 0: no step test; m)")
    open_gap_m: float = param(8.0, ge=0, le=100,
                              help="lane check: a lane sample over no surface at all is off the scan when that "
                                   "unscanned patch (seen from above) reaches the mesh's outer border or is wider "
                                   "than this (the sparse far range between a sweep's rings, land beyond the "
                                   "scan's edge: twinkit.surface.watertight.OpenGround); a smaller enclosed patch "
                                   "is a hole lift_movables closes (its ground_hole_max_m) and is left to the drop "
                                   "test (m; 0: every hole is left)")
    end_unscanned_share: float = param(0.0, ge=0, le=1,
                                       help="lane check: from a road's free end (where the capture or the "
                                            "carriageway ends), a shape point with more than this share of its "
                                            "driving-lane samples over ground the scan never measured (open_gap_m) "
                                            "is cut back, up to the last such point: the road ends where its lanes "
                                            "lie whole on scanned ground (1: as inside a road, min_lane_support)")
    inner_unscanned_share: float = param(0.1, ge=0, le=1,
                                         help="lane check: inside a road, a shape point with more than this share "
                                              "of its driving-lane samples over ground the scan never measured "
                                              "(open_gap_m) is off the scan, whatever the rest (min_lane_support): "
                                              "two or more in a row split the road (1: the share rule alone)")
    turn_off_samples: int = param(6, ge=0,
                                  help="lane check: a junction's turn with at least this many driving-lane samples off "
                                       "the scanned surface for any reason (a raised verge or a kerb at the corner it "
                                       "cuts) is not made, when another turn leaves the same lane (0: never)")
    turn_unscanned_samples: int = param(3, ge=0,
                                        help="lane check: a junction's turn (a connecting road) with at least this "
                                             "many driving-lane samples over ground the scan never measured "
                                             "(open_gap_m) is not made (netconvert's connection deleted), when "
                                             "another turn leaves the same lane; the junction's share "
                                             "(min_lane_support) judges all its turns together and keeps one that "
                                             "cuts a corner the scan never saw (0: never)")
    lane_clear_m: float = param(2.0, ge=0, le=10,
                                help="lane check: a sample with anything over it lower than this above the lane is "
                                     "off the scan (a hedge, a low roof; 0: no test; m)")
    min_kept_share: float = param(0.5, ge=0, le=1,
                                  help="a warning when the checks keep less than this share of the road length "
                                       "first derived")
    timeout_s: float = param(300.0, gt=0, help="netconvert wall-clock limit (s)")


@dataclass
class Arm:
    """One road between two nodes of the network (a junction or an end)."""

    a: int
    b: int
    xy: np.ndarray  # (k, 2) axis, a -> b
    width_m: float  # carriageway, curb to curb
    sidewalk_left_m: float = 0.0  # left of a -> b
    sidewalk_right_m: float = 0.0
    z: np.ndarray | None = None
    # the heights of the right and left halves (a -> b): each direction's edge carries its own lanes' height,
    # so a cambered street's lanes sit on it (OpenDRIVE from netconvert has no cross slope)
    z_right: np.ndarray | None = None
    z_left: np.ndarray | None = None
    lanes: dict = field(default_factory=dict)


@dataclass
class Network:
    nodes: dict  # id -> {"xy": (x, y), "z": z, "kind": "junction" | "end", "signals": bool}
    arms: list
    mask: np.ndarray
    grid: object
    sidewalk_mask: np.ndarray | None
    stats: dict
    level_faces: np.ndarray | None = None  # faces on the carriageway level (below the curbs)
    level_z: np.ndarray | None = None  # the carriageway level's height per grid pixel (network.carriageway_level)
    # turns the lane check dropped: (node id, where the turn starts, where it ends), resolved to netconvert's edges
    # by netconvert.write_turns each round (the arms' indices change as they are cut)
    no_turns: list = field(default_factory=list)


def empty_network() -> Network:
    """A network without nodes or roads (what is drawn when the scan holds no road)."""
    return Network({}, [], np.zeros((1, 1), bool), None, None, {})

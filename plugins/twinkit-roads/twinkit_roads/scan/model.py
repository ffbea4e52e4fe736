"""The scan road source's parameters and its network: arms (roads between nodes) and nodes (junctions, ends)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from twinkit import InputError
from twinkit.ranges import param


ROAD, SIDEWALK, TRAFFIC_LIGHT = 0, 1, 6


class NoRoads(InputError):
    """The scan holds no road: no carriageway, or no derived road kept its lanes on the scan (``derived``:
    roads were derived and the checks dropped them all). ``scan_source`` writes a map without roads."""

    def __init__(self, message: str, derived: bool = False):
        super().__init__(message)
        self.derived = derived


@dataclass
class ScanSourceParams:
    labels: str = param("auto", choices=("auto", "predicted", "gt", "none"))  # auto: the segmentation's labels.npy when an earlier step wrote it, else the curbs alone; predicted: labels.npy (required); gt: gt_labels.npy (benchmarks); none: the curbs alone
    raster_m: float = param(0.25, gt=0, le=2)  # top-view resolution of the carriageway mask
    curb_tol_m: float = param(0.07, ge=0, le=1)  # height above the local lowest ground still on the carriageway (below the curb)
    use_curbs: bool = True  # false: the road labels alone draw the edges
    # the curb test needs a scan that resolves a 10-15 cm kerb: a cloud whose median point spacing
    # (points_meta.json) is coarser than this (aerial lidar) is read without curbs: the carriageway is the
    # road-labelled, up-facing, grey surface, and no sidewalk lanes are made (0: always the curbs)
    curb_max_spacing_m: float = param(0.10, ge=0, le=5)
    # without curbs: paved surface is grey; a face whose colour saturation ((max - min) / max of its
    # vertices' RGB) is above this is not carriageway (grass, gardens, roofs' tiles). 1: colour not used
    grey_max_saturation: float = param(0.10, gt=0, le=1)
    # without curbs, and with the cloud (points.ply): a carriageway is surface the scanner measured at its
    # usual density. Water and unscanned gaps return few lidar points and the mesh bridges them with
    # invented grey surface; a pixel whose 2 m neighbourhood holds less than this share of the cloud's
    # median density is not carriageway. 0: not used
    min_point_density: float = param(0.25, ge=0, le=1)
    # without curbs: a carriageway pixel has most of the pixels in a square this wide (half the narrowest
    # road) paved-looking; single grey specks (shadows, gravel, path stones) are not. 0: not used
    majority_m: float = param(1.5, ge=0, le=10)
    label_margin_m: float = param(1.5, ge=0, le=10)  # carriageway-level surface this far beyond the road labels is still road
    min_road_width_m: float = param(3.0, gt=0)  # narrower carriageway (driveways, gaps) is not a road
    min_road_length_m: float = param(8.0, gt=0)  # shorter arms (spurs of the mask's corners) are pruned
    edge_percentile: float = param(75.0, ge=50, le=100)  # per side: this percentile of the edge distance along a window (cars only remove road)
    edge_window_m: float = param(20.0, gt=0)  # ...over this length of road
    lane_width_m: float = param(3.25, gt=0, le=10)  # nominal lane width (the OSM route's default too)
    min_lane_width_m: float = param(2.5, gt=0, le=10)  # a road with less than this per direction has one lane, one way
    max_lane_width_m: float = param(4.5, gt=0, le=10)  # lanes are widened up to this before a strip is made
    min_strip_m: float = param(1.8, ge=0, le=10)  # remainder per side at least this wide: a parking strip at the curb
    curb_clearance_m: float = param(0.15, ge=0, le=2)  # widened lanes stop this short of the found curb (a no-traffic lane fills it)
    strip_type: str = param("parking", choices=("parking", "driving", "none"))  # parking -> lane type none (no traffic), driving -> another lane
    sidewalks: bool = True  # sidewalk lanes where the scan shows sidewalk beyond the curb
    min_sidewalk_m: float = param(1.0, ge=0, le=20)  # narrower sidewalk surface: no sidewalk lane
    max_sidewalk_m: float = param(6.0, gt=0, le=30)  # sidewalk lanes are at most this wide
    traffic_light_radius_m: float = param(12.0, ge=0)  # traffic-light labels within this of a junction's edge: a signalised junction
    min_traffic_light_vertices: int = param(20, ge=0)  # ...at least this many such vertices
    sample_m: float = param(2.0, gt=0, le=20)  # spacing of the road shape points
    # the map netconvert builds is checked against the scan (check_lanes): a driving-lane sample is on the
    # scan when the surface lies within lane_tol_m of the lane's height; a road's stretch, or a junction,
    # with less than min_lane_support of its samples on it (the lanes float over a bank or sink into a
    # slope) is cut out, or the junction taken apart, and netconvert runs again (up to lane_check_rounds)
    lane_tol_m: float = param(0.3, gt=0, le=2)
    min_lane_support: float = param(0.8, ge=0, le=1)
    lane_check_rounds: int = param(3, ge=0, le=10)
    # ...and a side of a road whose outermost edge_band_m is off the scan (more than 1 - min_lane_support of
    # its samples along the road) while the rest of that side is on is narrowed by it, per round (not below
    # min_road_width_m; sides with a sidewalk lane stay). 0: no narrowing
    edge_band_m: float = param(0.5, ge=0, le=3)
    # across a lane, the surface under neighbouring samples (a sixth of the lane's width apart) may differ
    # by at most lane_step_m: beyond a larger step (a low wall, a hedge's foot, a yard above the street) a
    # sample is off the scan even within lane_tol_m (a wheel catches on it). 0: no step test
    lane_step_m: float = param(0.1, ge=0, le=2)
    # ...and a sample with anything over it lower than lane_clear_m above the lane (a hedge, a wall's top, a
    # low roof) is off, whatever lies under it. 0: no such test
    lane_clear_m: float = param(2.0, ge=0, le=10)
    # when the checks (trim_unsupported, the lane check) keep less than this share of the road length first
    # derived, a warning says the map covers less of the streets than the scan shows
    min_kept_share: float = param(0.5, ge=0, le=1)
    timeout_s: float = param(300.0, gt=0)  # netconvert wall-clock limit


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


def empty_network() -> Network:
    """A network without nodes or roads (what is drawn when the scan holds no road)."""
    return Network({}, [], np.zeros((1, 1), bool), None, None, {})

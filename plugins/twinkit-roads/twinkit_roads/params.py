"""The parameters of the roads plugin's steps (plugin.py re-exports them; the recipe's steps.<name> keys)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List

from twinkit.ranges import param
from twinkit.surface.density import RING_CAPTURE_SHARE


@dataclass
class OverviewParams:
    px_per_m: float = param(4.0, gt=0, help="pixels per metre of the overview picture")
    max_px: int = param(3000, ge=16, help="at most this many pixels across; large networks are drawn coarser")


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


@dataclass
class ApplyParams:
    qa_px_per_m: float = param(20.0, gt=0, help="pixels per metre of the QA picture of the aligned network over the mesh")
    qa_max_px: int = param(4096, ge=16, help="at most this many pixels across the QA picture")
    trim_to_ground: bool = param(True, help="cut the map's ends (road ends without a link, netconvert's dead-end "
                                 "turnarounds) back until their lanes lie on the mesh (ground_ends.py, docs/roads.md "
                                 "'Roads on the ground'); false: the aligned map as it is")
    trim_step_m: float = param(0.25, gt=0, help="metres: lane samples along the roads for the trim, and the step by "
                               "which a turnaround's cut grows")
    trim_band_m: float = param(0.5, gt=0, help="metres: a lane sample has ground beneath when the mesh crosses its "
                               "vertical within this of the lane's height")
    trim_margin_m: float = param(0.5, ge=0, help="metres: cut this much farther in than the first cross-section on "
                                 "the ground")
    trim_max_m: float = param(10.0, ge=0, help="metres: an end is never cut back farther than this (reported instead)")
    trim_min_left_m: float = param(2.0, ge=0, help="metres: a road is not cut shorter than this (reported instead)")


@dataclass
class SignalParams:
    """place_signals: finding the scanned instances (link_m .. plate_depth_m: ``instances.find_instances``,
    CityScapes trainIds 5 pole, 6 light, 7 sign), poles carrying an unlabelled head (pole_heads .. head_clear_m:
    ``instances.find_pole_heads``), placing them (gate_m ..: ``signals.place_signals``)."""
    link_m: float = param(0.35, gt=0, help="metres: vertices of one label (pole, light, sign) closer than this belong to one cluster")
    min_vertices: int = param(12, ge=0, help="clusters with fewer vertices are label noise and are dropped")
    min_height_m: float = param(1.5, ge=0, help="metres: a light head or a sign plate hangs at least this high above the local ground")
    max_height_m: float = param(8.0, gt=0, help="metres: ... and at most this high")
    max_size_m: float = param(2.0, gt=0, help="metres: a cluster wider or taller than this is a mislabelled patch of something else")
    min_pole_vertices: int = param(3, ge=0, help="pole-labelled vertices below the cluster (within pole_radius_m) that show it hangs on a pole")
    pole_radius_m: float = param(0.6, gt=0, help="metres: radius around a cluster searched for the pole that carries it")
    ground_radius_m: float = param(3.0, gt=0, help="metres: the local ground under a signal is the 2nd percentile of the mesh's heights within this radius (street.ground.LocalGround, disc mode)")
    plate_depth_m: float = param(0.12, ge=0, help="metres: a 'light' cluster thinner than this across is a sign plate (light heads are boxes)")
    pole_heads: bool = param(True, help="look for poles carrying an unlabelled head: light candidates the labels missed, offered only to netconvert light heads no labelled light paired with")
    head_min_m: float = param(1.8, ge=0, help="metres: bottom of the head band above the local ground, for heads on poles")
    head_max_m: float = param(4.5, gt=0, help="metres: top of that head band")
    head_min_width_m: float = param(0.3, ge=0, help="metres: narrowest extent of the head band; a bare pole or a sign plate is thinner")
    head_max_width_m: float = param(1.0, gt=0, help="metres: widest extent of the head band")
    head_clear_m: float = param(0.8, ge=0, help="metres: no vertex at head height from here to 1.5 m off the pole's axis (keeps trees and walls out)")
    gate_m: float = param(15.0, gt=0, help="metres: a netconvert light group and a scanned light farther apart than this never pair")
    group_m: float = param(2.0, ge=0, help="metres: netconvert light signals of one road within this distance along s are one head")
    wrong_side_m: float = param(6.0, ge=0, help="metres: extra pairing cost of a light across the reference line from the lanes of its head")
    carla_light_shift_m: float = param(0.25, help="metres: CARLA moves lights this far along their heading on import (MapBuilder.cpp); the placement compensates")
    one_head: bool = param(True, help="netconvert's signals of one head (one per lane and turn arrow) become one signal whose validity covers their lanes; false: kept stacked")
    lights_on_ground: bool = param(True, help="traffic lights stand on the scanned ground under their head (zOffset = that ground above the road; 0 for netconvert's unpaired guesses): CARLA's light blueprint is a whole pole; false: zOffset = the scanned head's height")
    phase_plan: str = param("shape", choices=("shape", "approach", "netconvert"), help="junction signal plan (one OpenDRIVE controller per phase, named from its junction): shape = opposite approaches share a phase, approach = each approach alone, netconvert = leave netconvert's controller (CARLA then runs every light alone)")
    phases: Dict[str, List[List[str]]] = param(default_factory=dict, free=True, help="a junction signal plan to use instead of phase_plan: junction id (or 'default') -> phases, each a list of the compass points traffic comes from, e.g. {default: [[N, S], [E, W]]}; approaches named by no phase run alone")
    add_signs: bool = param(True, help="write the scanned traffic signs as OpenDRIVE signals")
    sign_max_road_m: float = param(12.0, gt=0, help="metres: a sign farther than this from every road's reference line is not written")
    qa_px_per_m: float = param(20.0, gt=0, help="pixels per metre of the signals' QA picture")


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
    min_two_way_share: float = param(RING_CAPTURE_SHARE, ge=0, le=1, help="a capture whose ground has a smaller share sampled both ways (points_meta.json density.ground_two_way_share: a single spinning sweep's rings) shows no kerb step, so no level to judge the lanes by: labels pass through unchanged")
    plateau: bool = param(True, help="a raised plateau that an agreeing sidewalk lane lies on becomes sidewalk (its road votes)")
    raster_m: float = param(0.1, gt=0, help="metres: pixel size of the lane raster")
    step_m: float = param(0.5, gt=0, help="metres: lanes are sampled this far apart along s")
    picture_px_per_m: float = param(10.0, gt=0, help="pixels per metre of the evidence picture")


@dataclass
class ParkingParams:
    enabled: bool = param(True, help="false: no parking lane is added (the outer lanes are still narrowed to the ground: outer_lanes_to_ground)")
    osm_tags: bool = param(True, help="an OSM parking:<side> / parking:both (or parking:lane:*) tag on the road's way asks for a parking lane")
    scanned_vehicles: bool = param(True, help="a scanned vehicle standing between the outermost driving lane and the kerb asks for a parking lane")
    default_width_m: float = param(2.2, gt=0, le=6, help="metres: width of a parking lane where the scan shows no kerb beside the driving lane")
    min_width_m: float = param(1.6, gt=0, help="metres: a kerb nearer than this to the driving lane leaves no room for a parking lane")
    max_width_m: float = param(3.2, gt=0, help="metres: a kerb farther than this is not read as the parking strip's (a wider strip gets default_width_m)")
    kerb_top_m: float = param(0.0, ge=0, le=1, help="metres: the lane runs this far past the kerb's foot, over its face (0: the sidewalk lane holds the kerb, as OpenDRIVE draws it; the drop test checks sidewalk lanes with a kerb's height band, parking lanes at the road's height)")
    min_kerb_samples: int = param(5, ge=1, help="kerb profiles (one per step_m along the lane) that must see the kerb before its distance is used")
    step_m: float = param(1.0, gt=0, help="metres: lane samples along s for the kerb profiles and the vehicles")
    outer_lanes_to_ground: bool = param(True, help="at the map's ends, give the lanes outside the driving lanes (sidewalk, parking) no width where their scanned ground ends before the road's end (ground_ends.trim_outer_lanes, docs/roads.md 'Roads on the ground'); false: the lanes as they are")
    outer_margin_m: float = param(0.5, ge=0, help="metres: an outer lane gets no width this much farther in than its first cross-section on the ground")


@dataclass
class CrosswalkParams:
    enabled: bool = param(True, help="false: aligned.xodr passes through without crosswalk objects")
    from_osm: bool = param(True, help="use OSM's crossings (highway=crossing nodes, footway=crossing ways)")
    from_scan: bool = param(True, help="look for painted zebras on the scanned ground (vertex colours seen from above)")
    raster_m: float = param(0.05, gt=0, le=0.25, help="metres: pixel size of the top view the zebras are looked for in")
    min_bars: int = param(3, ge=2, help="a zebra has at least this many white bars side by side")
    min_bars_alone: int = param(5, ge=2, help="a zebra that no OSM crossing confirms needs at least this many bars")
    match_m: float = param(4.0, ge=0, help="metres: an OSM crossing this close to a zebra's walking line is that zebra")
    width_m: float = param(3.0, gt=0, help="metres: the width (along the road) of a crosswalk OSM gives without paint in the scan")


@dataclass
class CarlaMapParams:
    frame_scale: str = param("auto", choices=("auto", "site", "true", "minimax"),
                             help="scale of the CARLA frame, as the CARLA package's frame_scale (docs/georeferencing.md)")
    tolerance_m: float = param(0.5, gt=0, help="metres: the error CARLA's geolocation may have at the map's lane "
                                               "centres (the CARLA package's geolocation_tolerance_m); a warning beyond")
    step_m: float = param(5.0, gt=0, help="metres between the lane-centre points CARLA's geolocation is measured at")

"""The options of the lift (site frame: metres, z up); the step's parameters (:class:`LiftParams`) set the
ones a user may change."""
from __future__ import annotations

from dataclasses import dataclass

from twinkit.ranges import param


@dataclass
class LiftOptions:
    """Every threshold of :func:`lift_movables`; see the package doc for the stages they belong to."""

    cell_m: float = param(0.25, gt=0, help="cell of the ground grid (m)")
    ground_window_m: float = param(4.0, gt=0, help="local ground search window, wider than the widest vehicle "
                                                   "(a bus is 2.55 m)")
    ground_tol_m: float = param(0.25, ge=0, help="up-facing vertices this far above the local lowest are not "
                                                 "ground (curbs are)")
    up_normal_z: float = param(0.85, ge=0, le=1, help="a vertex faces up when its normal's z is at least this")
    min_height_m: float = param(0.25, ge=0, help="movable-labelled vertices at most this above the ground are "
                                                 "ground")
    cut_height_m: float = param(0.10, ge=0, help="faces with every corner above this (inside the footprint) "
                                                 "belong to the object")
    cluster_gap_m: float = param(0.5, gt=0, help="candidate vertices closer than this are one object")
    min_vertical_share: float = param(0.15, ge=0, le=1, help="share of an object's vertices with |normal z| < "
                                                             "0.5 (walls)")
    margin_m: float = param(0.3, ge=0, help="footprint widening for the face growth")
    max_fill_extent_m: float = param(3.0, ge=0, help="a hole reaching farther than this beyond the footprint is "
                                                     "not filled")
    debris_margin_m: float = param(0.5, ge=0, help="small pieces left within the footprint + this go with the "
                                                   "object")
    debris_max_faces: int = param(200, ge=0, help="... when they have at most this many faces")
    patch_cell_m: float = param(0.2, ge=0, help="grid of the ground patch where a footprint stays uncovered; "
                                                "0 = no patch")
    fill_cell_m: float = param(0.1, ge=0, help="a closed hole under an object is filled on this grid at the "
                                               "ground's height (0: spanned at the ring's heights)")
    flatten_feet_m: float = param(0.5, ge=0, help="the hole's border inside the footprint, up to this high, is "
                                                  "lowered onto the ground (0: kept)")
    gap_max_m: float = param(1.0, ge=0, help="smaller spots a ray at the ground falls through, surface all "
                                             "round, get a patch; 0 = off")
    gap_cell_m: float = param(0.05, gt=0, help="... found and patched on this grid")
    small_loop_m: float = param(1.0, ge=0, help="a loop of open border this short at an object's foot is closed "
                                                "even when it is no hole seen from above (a fold of the cut-off "
                                                "feet); 0 = off")
    fin_min_m: float = param(0.2, ge=0, help="open pieces left standing at an object's foot higher than this "
                                             "(a kerb) go with it; 0 = off")
    ground_hole_max_m: float = param(8.0, ge=0, help="any other hole of the ground up to this wide is closed at "
                                                     "the ground's height (wider is an unscanned area); 0 = off")
    ground_contact_m: float = param(0.25, ge=0, help="an object is lifted only when its faces reach this close to "
                                                     "the ground (feet, tyres); higher: it floats (a tree's crown, a "
                                                     "ghost), it stays static")
    min_geometry_share: float = param(0.5, ge=0, le=1, help="... and when at least this share of its voted vertices "
                                                            "are movable to the 3D classifier (geometry_votes.npy); "
                                                            "0 = off")
    min_geometry_votes: int = param(20, ge=0, help="... judged only on at least this many voted vertices")

"""The classes of movable objects: which CityScapes classes move, the shape each may have, and how a
cluster of movable-labelled vertices gets its class (the votes of its labels, then its size)."""
from __future__ import annotations

import numpy as np

from twinkit import cityscapes as cs

from .options import LiftOptions

#: CityScapes trainIds of movable objects: person, rider, car, truck, bus, train, motorcycle, bicycle
MOVABLE = cs.MOVABLE
#: ground classes a filled patch can take (road, sidewalk, terrain)
GROUND = cs.GROUND
#: per class: (min top above ground m, max top m, max footprint length m, min vertices)
CLASS_LIMITS = {
    cs.PERSON: (0.9, 2.4, 1.6, 20),
    cs.RIDER: (0.9, 2.5, 2.6, 20),
    cs.CAR: (0.7, 2.6, 7.0, 40),
    cs.TRUCK: (1.2, 4.6, 14.0, 40),
    cs.BUS: (1.8, 4.6, 20.0, 40),
    cs.TRAIN: (1.8, 5.0, 40.0, 40),
    cs.MOTORCYCLE: (0.5, 2.0, 3.0, 20),
    cs.BICYCLE: (0.5, 1.9, 2.5, 20),
}
#: per class: the narrowest footprint (m, the oriented box's width) a scan of one leaves: a person seen from any
#: side is a body's depth (~0.2 m) or more; a car or bus shows a side and its roof. A thinner "object" is a sheet:
#: a ghost of a passer-by, a fence, a hedge's face
CLASS_MIN_WIDTH = {cs.PERSON: 0.2, cs.RIDER: 0.2, cs.CAR: 1.2, cs.TRUCK: 1.5, cs.BUS: 2.0,
                   cs.TRAIN: 2.0, cs.MOTORCYCLE: 0.2, cs.BICYCLE: 0.1}
#: actor names per class: "Person", "Car", ...
NAMES = {c: cs.NAMES[c].title() for c in MOVABLE}


def refine_class(cid: int, votes: np.ndarray, length: float, width: float) -> int:
    """The class by label votes, unless the size rules it out: a car, truck, bus or train narrower than
    1 m and shorter than 2.8 m is a two-wheeler (labels confuse them; a scan sees a motorcycle's side):
    motorcycle or bicycle by their votes, else by length (a motorcycle is 1.9 m or longer)."""
    if cid in cs.WIDE_VEHICLES and width < 1.0 and length < 2.8:
        if votes[cs.MOTORCYCLE] or votes[cs.BICYCLE]:
            return cs.MOTORCYCLE if votes[cs.MOTORCYCLE] >= votes[cs.BICYCLE] else cs.BICYCLE
        return cs.MOTORCYCLE if length >= 1.9 else cs.BICYCLE
    return cid


def why_not(cid: int, n: int, top: float, length: float, vert_share: float, opt: LiftOptions) -> str | None:
    """Why a cluster of ``n`` vertices, ``top`` m high, ``length`` m long, is no object of class ``cid``
    (None: it is one)."""
    lo_top, hi_top, max_len, min_n = CLASS_LIMITS[cid]
    if n < min_n:
        return "too_few_vertices"
    if top < lo_top:
        return "too_low"
    if top > hi_top:
        return "too_high"
    if length > max_len:
        return "too_long"
    if vert_share < opt.min_vertical_share:
        return "no_walls"
    return None


#: a vehicle the scanner saw is at least this wide (a side and the roof)
VEHICLE_MIN_WIDTH_M = 1.2
#: a truck by size alone is at least this high (lower and longer than a car: a row of cars, a wall)
TRUCK_MIN_TOP_M = 2.2
#: a second class by votes is tried when it has at least this share of the cluster's vertices
SECOND_VOTE_SHARE = 0.1


def choose_class(votes: np.ndarray, n: int, top: float, length: float, width: float, vert_share: float,
                 opt: LiftOptions, split_tried: bool = False) -> tuple[int, str | None, str]:
    """The class of a cluster: (class id, why it is no object or None, "labels" | "size").

    The class with the most votes, if the shape fits it (``CLASS_LIMITS``); else the next class by votes
    that has at least ``SECOND_VOTE_SHARE`` of them and fits; else, for a cluster with a vehicle's width,
    car or truck by size. The 2D model names a parked car "person" or "motorcycle" on uncoloured or
    oblique views (a real mobile scan without colour; the demo's seed 7), and a 4.5 x 1.9 x 1.5 m
    object with walls is a car whatever the votes say. A vehicle-wide cluster longer than a car is
    "too_long" until ``split_tried`` (it may be cars parked bumper to bumper, ``split_along``); then a
    truck by size if it is at least ``TRUCK_MIN_TOP_M`` high. Nothing is made of a cluster no class fits."""
    mv = np.asarray(votes)[list(MOVABLE)]
    order = [MOVABLE[i] for i in np.argsort(-mv, kind="stable") if mv[i] > 0] or [MOVABLE[0]]
    first = order[0]
    why = why_not(first, n, top, length, vert_share, opt)
    if why is None:
        return first, None, "labels"
    for c in order[1:]:
        if votes[c] >= SECOND_VOTE_SHARE * n and why_not(c, n, top, length, vert_share, opt) is None:
            return c, None, "labels"
    if width >= VEHICLE_MIN_WIDTH_M:
        if why_not(cs.CAR, n, top, length, vert_share, opt) is None:
            return cs.CAR, None, "size"
        if not split_tried and why_not(cs.CAR, n, top, 0.0, vert_share, opt) is None:
            return first, "too_long", "labels"  # a car's height and width, longer: maybe several (split_along)
        if top >= TRUCK_MIN_TOP_M and why_not(cs.TRUCK, n, top, length, vert_share, opt) is None:
            return cs.TRUCK, None, "size"
    return first, why, "labels"

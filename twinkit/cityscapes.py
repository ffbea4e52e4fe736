"""The CityScapes label set every plugin shares: trainIds 0-18, names, the official palette.

One definition for segmenters, image models, exporters and the report, so a class id means the
same thing and has the same colour everywhere. 255 is "unlabelled / ignore" (black).
"""
from __future__ import annotations

import numpy as np

#: trainId -> class name (cityscapesScripts' trainIds 0-18).
NAMES: tuple[str, ...] = (
    "road", "sidewalk", "building", "wall", "fence", "pole", "traffic light",
    "traffic sign", "vegetation", "terrain", "sky", "person", "rider", "car",
    "truck", "bus", "train", "motorcycle", "bicycle",
)
N_CLASSES = len(NAMES)
IGNORE = 255
IGNORE_RGB = (0, 0, 0)

#: every trainId by name (the order of :data:`NAMES`); use these, never a bare number.
(ROAD, SIDEWALK, BUILDING, WALL, FENCE, POLE, TRAFFIC_LIGHT, TRAFFIC_SIGN, VEGETATION, TERRAIN, SKY,
 PERSON, RIDER, CAR, TRUCK, BUS, TRAIN, MOTORCYCLE, BICYCLE) = range(N_CLASSES)
#: class name (as in :data:`NAMES`) -> trainId.
ID: dict[str, int] = {name: i for i, name in enumerate(NAMES)}

# ----------------------------------------------------------------------------- class groups
#: the walkable / drivable surface: road, sidewalk, terrain (what the local ground is made of).
GROUND: tuple[int, ...] = (ROAD, SIDEWALK, TERRAIN)
#: people and vehicles, the classes that move: person, rider, car, truck, bus, train, motorcycle, bicycle.
MOVABLE: tuple[int, ...] = (PERSON, RIDER, CAR, TRUCK, BUS, TRAIN, MOTORCYCLE, BICYCLE)
#: vehicles with four wheels or more: car, truck, bus, train.
WIDE_VEHICLES: tuple[int, ...] = (CAR, TRUCK, BUS, TRAIN)
#: street furniture: pole, traffic light, traffic sign.
STREET_FURNITURE: tuple[int, ...] = (POLE, TRAFFIC_LIGHT, TRAFFIC_SIGN)


#: the five coarse classes a labelling is first judged on (the labelled-scan benchmark, bench/bench_labelled.py):
#: ground = road, sidewalk, terrain; facade = building, wall, fence; vegetation; pole-like = pole,
#: traffic light, traffic sign; vehicle = car, truck, bus, train, motorcycle, bicycle. Person, rider and
#: sky are in none of them (left out of the coarse score).
COARSE: dict[str, tuple[int, ...]] = {
    "ground": GROUND,
    "facade": (BUILDING, WALL, FENCE),
    "vegetation": (VEGETATION,),
    "pole-like": STREET_FURNITURE,
    "vehicle": (CAR, TRUCK, BUS, TRAIN, MOTORCYCLE, BICYCLE),
}
#: coarse class names, in the order of the indices :func:`coarse_of` returns.
COARSE_NAMES: tuple[str, ...] = tuple(COARSE)


def coarse_of(labels: np.ndarray) -> np.ndarray:
    """trainIds of any shape -> coarse class index (into :data:`COARSE_NAMES`) of the same shape, int8;
    -1 for an id in no coarse class (person, rider, sky, 255, unknown ids)."""
    table = np.full(256, -1, np.int8)
    for i, members in enumerate(COARSE.values()):
        table[list(members)] = i
    labels = np.asarray(labels)
    return table[np.where((labels >= 0) & (labels < 256), labels, IGNORE).astype(np.uint8)]


def name_of(train_id: int) -> str:
    """Class name of a trainId; any other value (255, unknown ids) -> the number as text, e.g. ``"255"``."""
    return NAMES[train_id] if 0 <= train_id < N_CLASSES else str(int(train_id))

#: trainId -> sRGB colour of the official CityScapes palette, (19, 3) uint8.
PALETTE = np.array([
    (128, 64, 128), (244, 35, 232), (70, 70, 70), (102, 102, 156), (190, 153, 153),
    (153, 153, 153), (250, 170, 30), (220, 220, 0), (107, 142, 35), (152, 251, 152),
    (70, 130, 180), (220, 20, 60), (255, 0, 0), (0, 0, 142), (0, 0, 70),
    (0, 60, 100), (0, 80, 100), (0, 0, 230), (119, 11, 32),
], dtype=np.uint8)
PALETTE.setflags(write=False)


def lut() -> np.ndarray:
    """(256, 3) uint8 lookup table: palette colours for 0-18, black for every other id."""
    table = np.empty((256, 3), np.uint8)
    table[:] = IGNORE_RGB
    table[:N_CLASSES] = PALETTE
    return table


def colorize(labels: np.ndarray) -> np.ndarray:
    """trainIds of any shape -> RGB uint8 of the same shape plus a last axis of 3 (ignore/unknown -> black)."""
    labels = np.asarray(labels)
    ids = np.where((labels >= 0) & (labels < 256), labels, IGNORE).astype(np.uint8)
    return lut()[ids]


def nearest_class(rgb: np.ndarray) -> np.ndarray:
    """RGB (..., 3) -> trainId of the nearest palette colour (black and near-black -> 255)."""
    rgb = np.asarray(rgb, np.int32)
    cand = np.vstack([PALETTE.astype(np.int32), np.array([IGNORE_RGB], np.int32)])
    d = ((rgb[..., None, :] - cand) ** 2).sum(-1)
    idx = d.argmin(-1)
    return np.where(idx == N_CLASSES, IGNORE, idx).astype(np.uint8)


# ----------------------------------------------------------------------------- ASPRS classes (LAS/LAZ)
#: ASPRS classification code (LAS 1.4 R15, table 17) -> the CityScapes trainIds a point of that class may be.
#: The file's class is evidence about *what kind of thing* a point is, never about which of the finer
#: CityScapes classes: ASPRS "ground" is road, sidewalk or terrain, and only the views (and the 3D context)
#: tell which; "low vegetation" is grass (terrain) or a low plant (vegetation). Codes absent here (0 never
#: classified, 1 unclassified, 7/18 noise, 9 water and 10 rail, which CityScapes' 19 classes have no class
#: for, 12 overlap, 13/14 wires, 16 wire connector, 19+ overhead structures and user classes) are silent:
#: they add nothing, so nothing is invented where the file says nothing (docs/segmentation.md "File classes").
ASPRS_TO_TRAINIDS: dict[int, tuple[int, ...]] = {
    2: (ROAD, SIDEWALK, TERRAIN),        # ground
    3: (VEGETATION, TERRAIN),            # low vegetation: grass (terrain) or low plants
    4: (VEGETATION,),                    # medium vegetation: bushes, hedges
    5: (VEGETATION,),                    # high vegetation: trees
    6: (BUILDING, WALL),                 # building
    11: (ROAD,),                         # road surface (LAS 1.4)
    15: (POLE,),                         # transmission tower
    17: (ROAD, SIDEWALK),                # bridge deck: the surface that carries traffic
    20: (ROAD, SIDEWALK, TERRAIN),       # ignored ground (near a breakline): still ground
}
ASPRS_NAMES: dict[int, str] = {0: "never classified", 1: "unclassified", 2: "ground", 3: "low vegetation",
                               4: "medium vegetation", 5: "high vegetation", 6: "building", 7: "low noise",
                               9: "water", 10: "rail", 11: "road surface", 12: "overlap", 13: "wire guard",
                               14: "wire conductor", 15: "transmission tower", 16: "wire connector",
                               17: "bridge deck", 18: "high noise", 20: "ignored ground"}


def asprs_allowed() -> np.ndarray:
    """(256, 19) bool: row ``code`` marks the trainIds an ASPRS class allows; all False for a silent code."""
    table = np.zeros((256, N_CLASSES), bool)
    for code, ids in ASPRS_TO_TRAINIDS.items():
        table[code, list(ids)] = True
    return table

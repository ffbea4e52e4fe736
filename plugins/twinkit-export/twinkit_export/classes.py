"""CityScapes classes (trainIds), their palette, and the names CARLA 0.9.16 recognises.

CARLA's ``make import`` (``Util/BuildTools/Import.py`` -> ``MoveAssets`` commandlet, ``SSTags.h``)
moves every static mesh imported from a map FBX into ``/Game/<Package>/Static/<Folder>/<Map>``
by *substring* of the mesh name, tested in this order:

    "Road_Road" | "Roads_Road"          -> Static/Road      (tag Roads, 1)
    "Road_Marking" | "Roads_Marking"    -> Static/RoadLine  (tag RoadLines, 24)
    "Terrain"                           -> Static/Terrain   (tag Terrain, 10)
    "Road_Sidewalk" | "Roads_Sidewalk"  -> Static/SideWalk  (tag Sidewalks, 2)
    "Road_Curb" | "Road_Gutter" (+ "Roads_" forms) -> Static/SideWalk
    anything else                       -> Static/Terrain

and the Tagger gives a mesh the tag of that folder name (``ATagger::GetLabelByFolderName``).
So only road, sidewalk, (road marking) and terrain are tagged automatically; every other class
arrives tagged Terrain and is retagged by moving its mesh to ``Static/<carla_folder>`` in the
editor (the folder names are the Tagger's, e.g. ``Building``, ``Vegetation``, ``Car``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twinkit import cityscapes

UNLABELLED = cityscapes.IGNORE


@dataclass(frozen=True)
class ClassInfo:
    train_id: int  # CityScapes trainId (255 = unlabelled)
    name: str  # CityScapes class name
    color: tuple[int, int, int]  # CityScapes palette, sRGB 0-255
    carla_name: str  # sub-mesh / object / prim name
    carla_folder: str  # Static/<folder> the Tagger maps to the intended CARLA tag
    carla_tag: str  # intended carla.CityObjectLabel
    carla_tag_id: int  # its value in CARLA 0.9.16
    auto_tag: str  # tag CARLA 0.9.16's `make import` gives the mesh by name alone


# CARLA 0.9.16 counterparts of the CityScapes trainIds 0-18 (carla.CityObjectLabel values as reported by the
# carla==0.9.16 Python module): (sub-mesh name, Static/<folder>, intended tag, its id, tag given by name alone).
# The class names and colours are the shared definition in twinkit.cityscapes.
_CARLA: dict[int, tuple[str, str, str, int, str]] = {
    cityscapes.ROAD: ("Road_Road", "Road", "Roads", 1, "Roads"),
    cityscapes.SIDEWALK: ("Road_Sidewalk", "SideWalk", "Sidewalks", 2, "Sidewalks"),
    cityscapes.BUILDING: ("Building", "Building", "Buildings", 3, "Terrain"),
    cityscapes.WALL: ("Wall", "Wall", "Walls", 4, "Terrain"),
    cityscapes.FENCE: ("Fence", "Fence", "Fences", 5, "Terrain"),
    cityscapes.POLE: ("Pole", "Pole", "Poles", 6, "Terrain"),
    cityscapes.TRAFFIC_LIGHT: ("TrafficLight", "TrafficLight", "TrafficLight", 7, "Terrain"),
    cityscapes.TRAFFIC_SIGN: ("TrafficSign", "TrafficSign", "TrafficSigns", 8, "Terrain"),
    cityscapes.VEGETATION: ("Vegetation", "Vegetation", "Vegetation", 9, "Terrain"),
    cityscapes.TERRAIN: ("Terrain", "Terrain", "Terrain", 10, "Terrain"),
    cityscapes.SKY: ("Sky", "Sky", "Sky", 11, "Terrain"),
    cityscapes.PERSON: ("Pedestrian", "Pedestrian", "Pedestrians", 12, "Terrain"),
    cityscapes.RIDER: ("Rider", "Rider", "Rider", 13, "Terrain"),
    cityscapes.CAR: ("Car", "Car", "Car", 14, "Terrain"),
    cityscapes.TRUCK: ("Truck", "Truck", "Truck", 15, "Terrain"),
    cityscapes.BUS: ("Bus", "Bus", "Bus", 16, "Terrain"),
    cityscapes.TRAIN: ("Train", "Train", "Train", 17, "Terrain"),
    cityscapes.MOTORCYCLE: ("Motorcycle", "Motorcycle", "Motorcycle", 18, "Terrain"),
    cityscapes.BICYCLE: ("Bicycle", "Bicycle", "Bicycle", 19, "Terrain"),
}
CLASSES: tuple[ClassInfo, ...] = tuple(
    ClassInfo(i, cityscapes.NAMES[i], tuple(int(v) for v in cityscapes.PALETTE[i]), *_CARLA[i])
    for i in range(cityscapes.N_CLASSES)
) + (ClassInfo(UNLABELLED, "unlabelled", cityscapes.IGNORE_RGB, "Unlabeled", "(none)", "NONE", 0, "Terrain"),)

BY_ID: dict[int, ClassInfo] = {c.train_id: c for c in CLASSES}

#: substrings CARLA's MoveAssets commandlet tests; a map or package name must contain none of them,
#: or every sub-mesh's asset name (which UE may prefix with it) would match the wrong folder.
CARLA_NAME_KEYS = ("Road_Road", "Roads_Road", "Road_Marking", "Roads_Marking", "Terrain",
                   "Road_Sidewalk", "Roads_Sidewalk", "Road_Curb", "Roads_Curb", "Road_Gutter", "Roads_Gutter")


def carla_auto_folder(name: str) -> str:
    """The Static/<folder> CARLA 0.9.16's MoveAssets commandlet moves a mesh called ``name`` to."""
    if "Road_Road" in name or "Roads_Road" in name:
        return "Road"
    if "Road_Marking" in name or "Roads_Marking" in name:
        return "RoadLine"
    if "Terrain" in name:
        return "Terrain"
    for key in ("Sidewalk", "Curb", "Gutter"):
        if f"Road_{key}" in name or f"Roads_{key}" in name:
            return "SideWalk"
    return "Terrain"


def palette_lut() -> np.ndarray:
    """(256, 3) uint8: colour of every label value (unknown values black)."""
    lut = np.zeros((256, 3), np.uint8)
    for c in CLASSES:
        lut[c.train_id] = c.color
    return lut


def info(train_id: int) -> ClassInfo:
    """The class of a label value; values outside CityScapes get a generic ``Class_<id>`` entry."""
    c = BY_ID.get(int(train_id))
    if c is not None:
        return c
    return ClassInfo(int(train_id), f"class {train_id}", (0, 0, 0), f"Class_{int(train_id)}", "(none)", "NONE", 0,
                     "Terrain")

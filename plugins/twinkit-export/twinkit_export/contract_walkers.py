"""The package checker's crosswalk rule: what CARLA's pedestrian navigation gets as crosswalks.

CARLA 0.9.16 (carla-simulator/carla) gives walkers their crossings in two places, both from the map's
OpenDRIVE:

- ``make import`` builds the navmesh (``Util/BuildTools/Import.py`` build_binary_for_navigation runs
  ``Util/DockerUtils/dist/build.sh``): ``FBX2OBJ`` turns the map FBX into an OBJ with an area per node
  name (``Util/DockerUtils/fbx/src/FBX2OBJ.cpp`` SetMaterials: exact ``Road_Crosswalk`` -> crosswalk),
  then ``get_xodr_crosswalks.py`` writes ``crosswalks.obj`` from ``carla.Map.get_crosswalks()`` (one
  object per closed outline, a triangle fan from its first point, material ``crosswalk``) and
  ``addOBJ.py`` appends it to that OBJ, which ``RecastBuilder`` turns into the navmesh. So the OpenDRIVE
  crosswalk objects are the navmesh's crosswalk areas; a ``Road_Crosswalk`` FBX node would add more, but
  ``MoveAssetsCommandlet.cpp`` has no route for it (``Commandlet/SSTags.h`` names none) and would tag it
  Terrain.
- ``get_crosswalks`` (Map::GetAllCrosswalkZones, LibCarla/source/carla/road/Map.cpp) reads only
  ``<object type="crosswalk">`` outlines of ``cornerLocal`` points
  (LibCarla/source/carla/opendrive/parser/ObjectParser.cpp ObjectParser::Parse).

:func:`navmesh_crosswalks` emulates ``get_xodr_crosswalks.py`` on the package's OpenDRIVE;
:func:`check_crosswalks` is the rule.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

SRC_CROSSWALKS = ("Util/DockerUtils/dist/get_xodr_crosswalks.py + build.sh + addOBJ.py (navmesh input); "
                  "LibCarla/source/carla/opendrive/parser/ObjectParser.cpp (ObjectParser::Parse); "
                  "LibCarla/source/carla/road/Map.cpp (Map::GetAllCrosswalkZones)")

RULE = ("crosswalks", ("the navmesh's crosswalk areas are the OpenDRIVE crosswalk objects carla.Map.get_crosswalks "
                       "reports (closed cornerLocal outlines, folded into the navmesh OBJ by get_xodr_crosswalks.py); "
                       "as many as the scan and OSM show", SRC_CROSSWALKS))


@dataclass
class NavCrosswalks:
    """What ``get_xodr_crosswalks.py`` would write: ``outlines`` (lists of CARLA-frame (x, y, z) points, the
    closing point left out), ``triangles`` (the fan faces, material crosswalk), ``error`` (why the script
    would stop, '' when it runs through)."""

    outlines: list
    triangles: int
    error: str = ""


def navmesh_crosswalks(xodr_text: str) -> NavCrosswalks:
    """Emulate ``get_xodr_crosswalks.py``: walk ``get_crosswalks()``'s points; an outline ends at the point
    equal to its first one (exact float comparison, as the script does); its faces are the fan
    (first, j - 1, j) over the points before that. An outline that never closes runs the script past the end
    of the list (IndexError)."""
    from twinkit.street.lanes import LaneMap, OpenDriveError

    try:
        pts = [tuple(p) for p in LaneMap(xodr_text, "t").crosswalk_points().tolist()]
    except OpenDriveError as exc:
        return NavCrosswalks([], 0, str(exc))
    outlines, tri, i = [], 0, 0
    while i < len(pts):
        a, cur = i, []
        closed = False
        while i < len(pts):
            cur.append(pts[i])
            i += 1
            if i < len(pts) and pts[i] == pts[a]:
                i += 1
                closed = True
                break
        outlines.append(cur)
        tri += max(len(cur) - 2, 0)
        if not closed:
            return NavCrosswalks(outlines, tri, f"outline {len(outlines)} never returns to its first point: "
                                                f"get_xodr_crosswalks.py reads past the end (IndexError)")
    return NavCrosswalks(outlines, tri)


def crosswalk_objects(xodr_text: str) -> int:
    """How many ``<object type="crosswalk">`` the OpenDRIVE holds (ObjectParser::Parse's test on the type)."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.fromstring(xodr_text.encode("utf-8"))
    except ET.ParseError:
        return 0
    return sum(1 for o in root.iter("object") if o.get("type") == "crosswalk")


def check_crosswalks(rep, pkg: Path, maps: list, expect: int | None = None) -> dict:
    """The ``crosswalks`` rule on each map of the package description (``maps``: its entries; ``pkg``: the
    package folder): the navmesh's crosswalk outlines from the map's OpenDRIVE must build (closed, at least 3
    points each) and, with ``expect`` (how many crossings the scan and OSM show), number at least that.
    Adds violations to ``rep`` (a ContractReport); returns {map name: crosswalk count}."""
    counts: dict[str, int] = {}
    for m in maps:
        if not isinstance(m, dict) or "xodr" not in m:
            continue
        xodr = Path(pkg) / str(m["xodr"])
        if not xodr.is_file():
            continue  # the json rule reports it
        text = xodr.read_text(encoding="utf-8")
        nav = navmesh_crosswalks(text)
        name = str(m.get("name", xodr.stem))
        counts[name] = len(nav.outlines)
        if nav.error:
            rep.add("crosswalks", f"{xodr.name}: {nav.error}; the navmesh would have no crosswalk")
            continue
        written = crosswalk_objects(text)
        if written > len(nav.outlines):
            rep.add("crosswalks", f"{xodr.name}: {written} crosswalk objects, carla.Map reports {len(nav.outlines)}: "
                                  f"an outline without cornerLocal points is read as nothing (ObjectParser::Parse)")
        thin = [k + 1 for k, o in enumerate(nav.outlines) if len(o) < 3]
        if thin:
            rep.add("crosswalks", f"{xodr.name}: crosswalk outline(s) {thin} have fewer than 3 cornerLocal points "
                                  f"(CARLA reads no cornerRoad): no navmesh area")
        if expect is not None and len(nav.outlines) < expect:
            rep.add("crosswalks", f"{xodr.name}: carla.Map reports {len(nav.outlines)} crosswalks, the scan and OSM "
                                  f"show {expect}: walkers would cross only where the navmesh has a crosswalk "
                                  f"(run the place_crosswalks step)")
    return counts

"""Where CARLA's walkers and parked cars end up in a package: two rules of the package checker.

``sidewalk_blocks``: CARLA's pedestrian navmesh is built from the map FBX's node ``Road_Sidewalk`` (walkable)
and ``Road_Crosswalk`` (``Util/DockerUtils/fbx/src/FBX2OBJ.cpp``, ``SetMaterials``: exact node names; every
other node blocks), then Recast (``Util/DockerUtils/dist/build.sh``). A walker is spawned at a random
navmesh point (``LibCarla/source/carla/nav/Navigation.cpp``, ``GetRandomLocation``) and routed over the
navmesh (``Navigation::GetAgentRoute``, ``dtNavMeshQuery::findPath``), so a sidewalk piece apart from its
block's pavement is an island its walkers never leave. Rule: within each block (a region the OpenDRIVE's
carriageway lanes enclose) the ``Road_Sidewalk`` faces form one connected surface, and no small piece
(under 5 m^2) lies on the carriageway apart from every block's surface.

``parked_on_sidewalk``: a parked vehicle of ``actors.json`` (a wide vehicle: car, truck, bus, train) must not
stand on an OpenDRIVE sidewalk lane: ``Map::GetWaypoint`` (``LibCarla/source/carla/road/Map.cpp``) with the
``Sidewalk`` lane type finds a lane there (within half its width of its centre), so scripts that ask
which lane a car is on (``map.get_waypoint(loc, project_to_road=False, lane_type=Sidewalk)``) read a
car on the pavement, and the lane's walkers (sidewalk waypoints) run through it.

Frames: the package's FBX and OpenDRIVE share the package frame (right-handed, metres, z up; the FBX's raw
vertices are metres, docs/export.md); ``actors.json`` holds ``carla.Transform`` values (y = -north of that
frame), brought back with :func:`twinkit.street.lanes.from_carla`.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

SRC_NAVMESH = ("Util/DockerUtils/fbx/src/FBX2OBJ.cpp (SetMaterials); LibCarla/source/carla/nav/Navigation.cpp "
               "(GetRandomLocation, GetAgentRoute)")
SRC_WAYPOINT = "LibCarla/source/carla/road/Map.cpp (Map::GetWaypoint, GetClosestWaypointOnRoad)"

#: the rules of this module (merged into carla_contract.RULES)
RULES: dict[str, tuple[str, str]] = {
    "sidewalk_blocks": ("walkers spawn on the navmesh built from Road_Sidewalk / Road_Crosswalk and walk only "
                        "over connected navmesh: each block's sidewalk is one connected surface, none on the "
                        "carriageway apart from it", SRC_NAVMESH),
    "parked_on_sidewalk": ("Map::GetWaypoint with lane type Sidewalk finds a sidewalk lane within half its width "
                           "of a point: no parked vehicle of actors.json stands on one", SRC_WAYPOINT),
}

#: OpenDRIVE lane types of the carriageway (what separates blocks)
CARRIAGEWAY_TYPES = ("driving", "bidirectional", "parking", "shoulder", "biking", "stop", "entry", "exit",
                     "onramp", "offramp", "roadworks", "special1", "special2", "special3")
#: actors.json classes that are parked vehicles (four wheels or more)
PARKED_CLASSES = ("car", "truck", "bus", "train")


@dataclass
class BlockReport:
    """The sidewalk surfaces per block: ``blocks`` {block id: [component areas m^2, largest first]},
    ``stray`` areas of the pieces lying mostly on the carriageway, ``components`` in all."""

    blocks: dict[int, list[float]] = field(default_factory=dict)
    stray: list[float] = field(default_factory=list)
    components: int = 0

    @property
    def split_blocks(self) -> dict[int, list[float]]:
        return {b: a for b, a in self.blocks.items() if len(a) > 1}

    def summary(self) -> dict:
        return {"sidewalk_components": self.components, "blocks_with_sidewalk": len(self.blocks),
                "blocks_split": len(self.split_blocks), "stray_pieces": len(self.stray),
                "per_block_m2": {str(b): [round(x, 2) for x in a[:6]] for b, a in sorted(self.blocks.items())}}


def components(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, int]:
    """(component of each face (m,), count): faces sharing a vertex position are connected."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from .sidewalks import place_index

    f = place_index(vertices, 1e-3)[faces]  # an FBX splits vertices at UV and normal seams
    n = int(f.max()) + 1 if len(f) else 0
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]]])
    g = coo_matrix((np.ones(len(e), np.int8), (e[:, 0], e[:, 1])), shape=(n, n))
    k, lab = connected_components(g, directed=False)
    _, comp = np.unique(lab[f[:, 0]], return_inverse=True)
    return comp, int(comp.max()) + 1 if len(comp) else 0


def carriageway_blocks(xodr_text: str, lo: np.ndarray, hi: np.ndarray, cell_m: float = 0.2, seal_m: float = 0.3,
                       step_m: float = 0.5, edge_m: float = 5.0) -> tuple[np.ndarray, int]:
    """(grid (ny, nx) int32: 0 on the carriageway, else the block id; block count): the regions of the box
    ``lo``..``hi`` (x, y, the OpenDRIVE's frame) that the carriageway lanes (:data:`CARRIAGEWAY_TYPES`,
    :meth:`twinkit.street.lanes.LaneMap.lanes`) enclose, the lanes widened by ``seal_m`` so no gap between
    two lanes joins two blocks, and a lane that ends within ``edge_m`` of the box's border run on to it
    (a road cut short of the mesh's edge would join the blocks on its two sides around its end). Row j
    covers y from ``lo[1] + j cell_m``."""
    from PIL import Image, ImageDraw
    from scipy import ndimage

    from twinkit.street.lanes import LaneMap

    nx, ny = (np.ceil((np.asarray(hi) - lo) / cell_m).astype(int) + 1).tolist()
    img = Image.new("1", (nx, ny), 0)
    draw = ImageDraw.Draw(img)
    for ln in LaneMap(xodr_text, "blocks").lanes(step_m).per_lane():
        if not ln.is_type(*CARRIAGEWAY_TYPES)[0] or len(ln) < 2:
            continue
        left, right = ((b - lo) / cell_m for b in ln.borders())
        for i in range(len(ln) - 1):
            quad = [tuple(left[i]), tuple(left[i + 1]), tuple(right[i + 1]), tuple(right[i])]
            draw.polygon(quad, fill=1)
        c = ln.xyz[:, :2]
        for end, prev in ((0, 1), (-1, -2)):  # a lane ending near the box's border runs on to it
            if min((c[end] - lo).min(), (hi - c[end]).min()) <= edge_m:
                d = c[end] - c[prev]
                d = d / max(float(np.hypot(*d)), 1e-9) * (2 * edge_m / cell_m)
                draw.polygon([tuple(left[end]), tuple(left[end] + d), tuple(right[end] + d), tuple(right[end])],
                             fill=1)
    road = np.asarray(img, bool)
    if seal_m > 0:
        road = ndimage.binary_dilation(road, iterations=max(1, int(round(seal_m / cell_m))))
    blocks, n = ndimage.label(~road)
    return blocks.astype(np.int32), int(n)


def sidewalk_blocks(vertices: np.ndarray, faces: np.ndarray, xodr_text: str, cell_m: float = 0.2,
                    stray_max_m2: float = 5.0) -> BlockReport:
    """The ``Road_Sidewalk`` surface (``vertices`` (n, 3), ``faces`` (m, 3), the OpenDRIVE's frame) per block:
    each connected piece goes to the block that holds most of its area; a piece mostly on the carriageway
    (block 0) smaller than ``stray_max_m2`` is stray (a larger one is a surface of its own: a refuge island,
    a median; it joins the blocks through crosswalks)."""
    from twinkit.mesh.core import face_areas

    rep = BlockReport()
    if len(faces) == 0:
        return rep
    comp, k = components(vertices, faces)
    rep.components = k
    lo, hi = vertices[:, :2].min(0) - 1.0, vertices[:, :2].max(0) + 1.0
    grid, _ = carriageway_blocks(xodr_text, lo, hi, cell_m)
    c = vertices[faces, :2].mean(1)
    ij = np.floor((c - lo) / cell_m).astype(int)
    blk = grid[np.clip(ij[:, 1], 0, grid.shape[0] - 1), np.clip(ij[:, 0], 0, grid.shape[1] - 1)]
    area = face_areas(vertices, faces)
    for p in range(k):
        sel = comp == p
        votes = np.bincount(blk[sel], weights=area[sel])
        b, a = int(np.argmax(votes)), float(area[sel].sum())
        if b == 0:
            if a < stray_max_m2:
                rep.stray.append(a)
            continue
        rep.blocks.setdefault(b, []).append(a)
    for a in rep.blocks.values():
        a.sort(reverse=True)
    return rep


def parked_on_sidewalk(actors: list[dict], xodr_text: str) -> list[dict]:
    """The parked vehicles of ``actors`` (``actors.json`` entries: class in :data:`PARKED_CLASSES`, a
    ``transform`` in CARLA's frame) that stand on an OpenDRIVE sidewalk lane, each as
    {"name", "class", "road", "lane", "xy"} (xy in the OpenDRIVE's frame)."""
    from twinkit.street.lanes import LaneMap, from_carla

    cars = [a for a in actors if isinstance(a, dict) and str(a.get("class", "")).lower() in PARKED_CLASSES
            and isinstance(a.get("transform"), dict)]
    if not cars:
        return []
    xyz = from_carla(np.array([[a["transform"][k] for k in ("x", "y", "z")] for a in cars], float))
    hits = LaneMap(xodr_text, "parked").lane_at(xyz, "Sidewalk")
    return [{"name": a.get("name"), "class": a.get("class"), "road": h[0][0], "lane": h[0][2],
             "xy": [round(float(v), 2) for v in p[:2]]} for a, p, h in zip(cars, xyz, hits) if h is not None]


def sidewalk_lane_share(meshes: dict[str, tuple[np.ndarray, np.ndarray]], xodr_text: str, step_m: float = 0.5,
                        cell_m: float = 0.1) -> dict:
    """Which map node lies under the OpenDRIVE's sidewalk-lane centre samples (:meth:`LaneMap.lanes` every
    ``step_m``): the top-most face seen from above in a ``cell_m`` raster of ``meshes`` ({node: (vertices,
    faces)}, the OpenDRIVE's frame). Returns {"samples", "inside", "share_by_node" {node: share of the
    samples inside the mesh}}."""
    from twinkit.mesh.raster import face_raster
    from twinkit.street.lanes import LaneMap

    lanes = LaneMap(xodr_text, "share").lanes(step_m)
    xy = lanes.xyz[lanes.is_type("sidewalk"), :2]
    names = list(meshes)
    if not len(xy) or not names:
        return {"samples": int(len(xy)), "inside": 0, "share_by_node": {}}
    offs = np.cumsum([0] + [len(meshes[n][0]) for n in names])
    V = np.concatenate([meshes[n][0] for n in names])
    F = np.concatenate([meshes[n][1] + o for n, o in zip(names, offs[:-1])])
    node = np.concatenate([np.full(len(meshes[n][1]), i) for i, n in enumerate(names)])
    x0, y0 = V[:, 0].min(), V[:, 1].max()
    shape = (int((y0 - V[:, 1].min()) / cell_m) + 1, int((V[:, 0].max() - x0) / cell_m) + 1)
    r = face_raster(V, F, x0, y0, cell_m, shape, order=V[F, 2].mean(1))
    col = np.floor((xy[:, 0] - x0) / cell_m).astype(int)
    row = np.floor((y0 - xy[:, 1]) / cell_m).astype(int)
    ok = (row >= 0) & (row < shape[0]) & (col >= 0) & (col < shape[1])
    hit = np.full(len(xy), -1)
    hit[ok] = r[row[ok], col[ok]]
    inside = hit >= 0
    counts = np.bincount(node[hit[inside]], minlength=len(names))
    n_in = int(inside.sum())
    return {"samples": int(len(xy)), "inside": n_in,
            "share_by_node": {names[i]: round(float(c) / n_in, 4) for i, c in enumerate(counts) if c} if n_in else {}}


def check_sidewalks(rep, root: Path, pkg: Path, maps: list) -> None:
    """The two rules on the package: ``rep`` a carla_contract.ContractReport (violations added), ``root`` the
    folder holding ``Import/`` and ``actors.json``, ``pkg`` the package folder, ``maps`` its description's
    map entries."""
    from . import fbxbin

    actors = []
    if (root / "actors.json").is_file():
        try:
            actors = json.loads((root / "actors.json").read_text()).get("actors", [])
        except (ValueError, AttributeError):
            actors = []  # the actors rule reports an unreadable file
    for m in maps:
        if not isinstance(m, dict) or not (pkg / str(m.get("xodr", ""))).is_file() \
                or not (pkg / str(m.get("source", ""))).is_file():
            continue
        xodr = (pkg / str(m["xodr"])).read_text(encoding="utf-8")
        try:
            geo = {n: (v, f) for n, v, f in fbxbin.mesh_arrays(pkg / str(m["source"])) if n == "Road_Sidewalk"}
        except (fbxbin.FbxReadError, ValueError):
            continue  # the json rule reports an unreadable FBX
        if "Road_Sidewalk" in geo:
            br = sidewalk_blocks(*geo["Road_Sidewalk"], xodr)
            for b, areas in sorted(br.split_blocks.items()):
                rep.add("sidewalk_blocks", f"map {m.get('name')}: the sidewalk of block {b} is {len(areas)} separate "
                                           f"surfaces ({', '.join(f'{a:.1f}' for a in areas[:6])} m^2): walkers "
                                           f"spawned on the small ones never leave them")
            if br.stray:
                rep.add("sidewalk_blocks", f"map {m.get('name')}: {len(br.stray)} sidewalk pieces "
                                           f"({sum(br.stray):.1f} m^2) lie on the carriageway apart from every "
                                           f"block's sidewalk (navmesh islands)")
        for p in parked_on_sidewalk(actors, xodr):
            rep.add("parked_on_sidewalk", f"{p['name']} ({p['class']}) stands on the sidewalk lane {p['lane']} of "
                                          f"road {p['road']} at {p['xy']} (get_waypoint with lane type Sidewalk)")

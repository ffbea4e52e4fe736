"""One connected sidewalk surface per block: the sidewalk labels cleaned before the per-class split.

CARLA's pedestrian navmesh walks only on the map FBX's ``Road_Sidewalk`` node (and ``Road_Crosswalk``;
``Util/DockerUtils/fbx/src/FBX2OBJ.cpp`` ``SetMaterials``, then Recast in ``Util/DockerUtils/dist/build.sh``).
A fragment of sidewalk apart from its block's pavement is a navmesh island: a walker spawned there
(``world.get_random_location_from_navigation``) never leaves it. The scan's labels leave such fragments
where a pole's foot, a lamp, a lifted car or a mislabelled patch breaks the pavement, and single
sidewalk faces on the carriageway (a lone sidewalk vertex takes one face in the split,
:func:`twinkit_export.split.face_classes`).

The clean-up works on the faces' classes as the split gives them (same rule), per vertex label:

1. the sidewalk faces' connected components (faces sharing a vertex), by area;
2. the components of at least ``keep_m2`` are the surfaces; every other component (and every surface
   but the largest) is **joined** to a larger surface when a walkable path over the ground joins them
   within ``join_gap_m``: the shortest path over mesh edges whose ends are both ground classes (road,
   sidewalk, unlabelled) and whose slope stays under ``max_slope``, rising at most ``max_rise_m`` above
   the fragment's height and falling at most that or, in a sag, less than half the kerb (a kerb is higher,
   so a fragment on the carriageway is never joined over the kerb nor along its foot); the path's vertices
   become sidewalk, and the faces along it join the two;
3. a component that cannot be joined and is smaller than ``keep_m2`` is **dissolved**: its sidewalk
   vertices take the class most of their non-sidewalk neighbours have (road on the carriageway,
   terrain on a verge);
4. repeated (a join or a dissolve changes the faces around it) until nothing changes or ``rounds``.

Larger components that stay apart are kept and counted (a pavement cut by a wall or a building is
two surfaces): the report says how many remain.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from twinkit.cityscapes import IGNORE, ROAD, SIDEWALK
from twinkit.mesh.core import edges, face_areas
from twinkit.mesh.topology import vertex_faces


@dataclass
class SidewalkCleanup:
    """What :func:`connect_sidewalks` did; ``labels`` (n,) uint8 the cleaned per-vertex labels."""

    labels: np.ndarray
    components_before: int
    components_after: int
    joined: int = 0
    dissolved: int = 0
    relabelled_vertices: int = 0
    dissolved_m2: float = 0.0
    areas_after_m2: list[float] = field(default_factory=list)

    def stats(self) -> dict:
        return {"sidewalk_components_before": self.components_before,
                "sidewalk_components_after": self.components_after, "sidewalk_fragments_joined": self.joined,
                "sidewalk_fragments_dissolved": self.dissolved, "sidewalk_dissolved_m2": round(self.dissolved_m2, 3),
                "sidewalk_relabelled_vertices": self.relabelled_vertices,
                "sidewalk_component_areas_m2": [round(a, 2) for a in self.areas_after_m2[:12]]}


def place_index(vertices: np.ndarray, tol_m: float) -> np.ndarray:
    """(n,) int64: one index per place, shared by the vertices within ``tol_m`` of it (positions rounded to
    ``tol_m``): ``place_index(v, tol)[faces]`` are the faces over welded vertices (an FBX splits vertices at UV
    and normal seams; a modelled mesh keeps each part's own vertices)."""
    key = np.round(np.asarray(vertices, np.float64) / tol_m).astype(np.int64)
    return np.unique(key, axis=0, return_inverse=True)[1].reshape(-1)


def coincident_pairs(vertices: np.ndarray, tol_m: float = 1e-4) -> np.ndarray:
    """(k, 2) int64 pairs of distinct vertices at the same place (within ``tol_m``): the seams of a mesh whose
    parts are not welded (a modelled mesh keeps each part's vertices with its own class), which join the
    parts as shared vertices would."""
    inv = place_index(vertices, tol_m)
    order = np.argsort(inv, kind="stable")
    same = inv[order][1:] == inv[order][:-1]
    return np.c_[order[:-1][same], order[1:][same]].astype(np.int64)


def sidewalk_components(vertices: np.ndarray, faces: np.ndarray, face_class: np.ndarray,
                        cls: int = SIDEWALK, seams: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Components of the faces of class ``cls`` that share a vertex (or two vertices at one place, ``seams``:
    :func:`coincident_pairs`): (face index (k,), component of each of those faces (k,), area of each
    component (c,) m^2, largest first: component 0 is the largest)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    fi = np.flatnonzero(face_class == cls)
    if len(fi) == 0:
        return fi, np.zeros(0, np.int64), np.zeros(0)
    f = faces[fi]
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], np.zeros((0, 2), np.int64) if seams is None else seams])
    n = len(vertices)
    g = coo_matrix((np.ones(len(e), np.int8), (e[:, 0], e[:, 1])), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    _, comp = np.unique(lab[f[:, 0]], return_inverse=True)
    area = np.bincount(comp, weights=face_areas(vertices, f))
    order = np.argsort(-area, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return fi, rank[comp], area[order]


def _walk_graph(vertices: np.ndarray, faces: np.ndarray, labels: np.ndarray, max_slope: float,
                walk_classes: tuple[int, ...], seams: np.ndarray):
    """Sparse (n, n) graph of the mesh edges (and ``seams``, two vertices at one place) a walker may follow:
    both ends of a walkable class, slope (|dz| / horizontal length) at most ``max_slope``; weights the 3D
    lengths."""
    from scipy.sparse import coo_matrix

    n = len(vertices)
    e = edges(np.r_[faces, np.c_[seams, seams[:, 1]]], n)  # a seam as the triangle (a, b, b): its one edge
    d = vertices[e[:, 1]] - vertices[e[:, 0]]
    horiz = np.hypot(d[:, 0], d[:, 1])
    ok = np.isin(labels[e[:, 0]], walk_classes) & np.isin(labels[e[:, 1]], walk_classes)
    ok &= np.abs(d[:, 2]) <= max_slope * np.maximum(horiz, 1e-9) + 1e-9
    e, w = e[ok], np.maximum(np.linalg.norm(d[ok], axis=1), 1e-6)
    return coo_matrix((np.r_[w, w], (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n)).tocsr()


def _component_vertices(faces: np.ndarray, fi: np.ndarray, comp: np.ndarray, n: int) -> list[np.ndarray]:
    """Per component ``c`` the sorted vertices of its faces ``fi[comp == c]``."""
    key = np.unique(comp[:, None].astype(np.int64) * n + faces[fi])
    c, v = key // n, key % n
    return np.split(v, np.searchsorted(c, np.arange(1, int(comp.max(initial=-1)) + 1)))


def _dissolve_to(labels: np.ndarray, faces: np.ndarray, verts: np.ndarray, seams: np.ndarray, vf) -> int:
    """The class most of the non-sidewalk vertices sharing a face with ``verts`` (or with a vertex at the same
    place, ``seams``) carry (road when none); ``vf`` the faces of each vertex (``twinkit.mesh.topology.vertex_faces``)."""
    near = np.r_[verts, seams[np.isin(seams[:, 0], verts), 1], seams[np.isin(seams[:, 1], verts), 0]]
    touch = faces[np.unique(vf[near].indices)].ravel()
    around = labels[np.setdiff1d(touch, verts)]
    around = around[(around != SIDEWALK) & (around != IGNORE)]
    return int(np.bincount(around).argmax()) if len(around) else ROAD


#: the carriageway beside a pavement lies within this of any point of it (the kerb's height is read there)
KERB_REACH_M = 8.0


def _same_level(vertices: np.ndarray, path: np.ndarray, fragment: np.ndarray, surface: np.ndarray,
                max_rise_m: float, radius_m: float = 1.0, road_tree=None, road_z: np.ndarray | None = None) -> bool:
    """Whether a joining path keeps to one level: it rises and falls at most ``max_rise_m`` (or a sag's depth), no
    inner vertex more than ``max_rise_m`` above the fragment's median height, nor further below it than a sag
    (``max_rise_m``, or less than half the kerb: the fragment's
    height over the lowest tenth of the road's within ``KERB_REACH_M`` of the path; ``road_tree`` a cKDTree of
    the road vertices' xy, ``road_z`` their heights): Poisson's sag over a scan shadow across the pavement is the
    pavement's, the road at a kerb's foot is not. And the fragment's median height and the upper quartile of
    the heights of the ``surface`` vertices within ``radius_m`` of where the path arrives (the pavement's top)
    differ by at most ``max_rise_m``: a surface whose edge runs down a kerb face reaches the carriageway at its
    foot, the pavement beside it is a kerb higher."""
    z = vertices[:, 2]
    level = float(np.median(z[fragment]))
    inner = z[path[1:-1]] - level
    sag = max_rise_m
    if road_tree is not None and level - z[path].min() > max_rise_m:
        near = np.unique(np.concatenate(road_tree.query_ball_point(vertices[path, :2], KERB_REACH_M)).astype(int))
        below = road_z[near][road_z[near] < level - max_rise_m] if len(near) else np.zeros(0)
        if len(below):
            sag = max(sag, (level - float(np.percentile(below, 10))) / 2)
    if np.ptp(z[path]) > sag or inner.max(initial=0.0) > max_rise_m or -inner.min(initial=0.0) > sag:
        return False
    end = vertices[path[0], :2]
    near = surface[np.hypot(*(vertices[surface, :2] - end).T) <= radius_m]
    return abs(float(np.percentile(z[near], 75)) - level) <= max_rise_m if len(near) else True


def _join(graph, sources: np.ndarray, targets: np.ndarray, join_gap_m: float) -> np.ndarray | None:
    """The vertices of the shortest walkable path (within ``join_gap_m``) from any source to any target,
    or None."""
    from scipy.sparse.csgraph import dijkstra

    dist, pred, _ = dijkstra(graph, indices=sources, limit=join_gap_m, min_only=True, return_predecessors=True)
    reach = targets[np.isfinite(dist[targets])]
    if not len(reach):
        return None
    v = int(reach[np.argmin(dist[reach])])
    path = [v]
    while pred[v] >= 0:
        v = int(pred[v])
        path.append(v)
    return np.asarray(path, np.int64)


def connect_sidewalks(vertices: np.ndarray, faces: np.ndarray, labels: np.ndarray, *, join_gap_m: float = 1.5,
                      keep_m2: float = 20.0, max_slope: float = 0.35, max_rise_m: float = 0.05,
                      rounds: int = 4) -> SidewalkCleanup:
    """The labels with the sidewalk fragments joined or dissolved (see the module).

    vertices (n, 3) float site frame, metres; faces (m, 3) int; labels (n,) trainIds (255 unlabelled).
    join_gap_m: longest walkable path (m) that joins a fragment to a larger sidewalk surface; keep_m2: a
    surface at least this large (m^2) that cannot be joined stays, and only such surfaces are joined to;
    max_slope: steepest mesh edge (rise over run) a joining path may follow; max_rise_m: the most a joining
    path may rise and fall in all (m; a kerb is 0.06 m and more)."""
    from scipy.spatial import cKDTree

    from .split import face_classes

    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    lab = np.asarray(labels).astype(np.uint8).copy()
    walk = (ROAD, SIDEWALK, IGNORE)
    seams = coincident_pairs(vertices)
    fc, _ = face_classes(faces, lab)
    _, _, area0 = sidewalk_components(vertices, faces, fc, seams=seams)
    res = SidewalkCleanup(lab, len(area0), len(area0))
    vf = vertex_faces(faces, len(vertices))
    for _ in range(rounds):
        fi, comp, area = sidewalk_components(vertices, faces, fc, seams=seams)
        if len(area) <= 1:
            break
        graph = _walk_graph(vertices, faces, lab, max_slope, walk, seams)
        road = np.flatnonzero(lab == ROAD)
        road_tree, road_z = (cKDTree(vertices[road, :2]), vertices[road, 2]) if len(road) else (None, None)
        verts = _component_vertices(faces, fi, comp, len(vertices))
        anchors = max(1, int(np.count_nonzero(area >= keep_m2)))  # the surfaces a fragment may join
        changed = 0
        for c in range(len(area) - 1, 0, -1):
            targets = np.concatenate(verts[:min(c, anchors)])
            path = _join(graph, verts[c], targets, join_gap_m)
            if path is not None and not _same_level(vertices, path, verts[c], targets, max_rise_m,
                                                    road_tree=road_tree, road_z=road_z):
                path = None  # the path climbs a kerb: the fragment lies on another level
            if path is not None:
                new = path[lab[path] != SIDEWALK]
                lab[new] = SIDEWALK
                res.joined += 1
                res.relabelled_vertices += len(new)
                changed += 1
            elif area[c] < keep_m2:
                own = verts[c][lab[verts[c]] == SIDEWALK]
                lab[own] = _dissolve_to(lab, faces, own, seams, vf)
                res.dissolved += 1
                res.dissolved_m2 += float(area[c])
                res.relabelled_vertices += len(own)
                changed += 1
        fc, _ = face_classes(faces, lab)
        if not changed:
            break
    _, _, area = sidewalk_components(vertices, faces, fc, seams=seams)
    res.components_after, res.areas_after_m2 = len(area), [float(a) for a in area]
    res.labels = lab
    return res

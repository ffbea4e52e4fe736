"""Splitting a labelled mesh into one sub-mesh per class.

Labels are per vertex; a sub-mesh is a set of faces. Rules:

1. every face goes to exactly one class: the majority label of its three vertices; a face with
   three different labels goes to the smallest label value (CityScapes orders road, sidewalk, ...
   first, so the drivable surface stays closed); unlabelled (255) only wins a clear majority;
2. every vertex lies on at least one face of its own class: where a vertex's label lost every vote
   around it (a lone "pole" vertex in the road), one of its faces is given to its class instead;
0. before the split, degenerate faces (a repeated vertex, zero area) and duplicate faces (the same
   three vertices, in either winding; back-to-back twins) are dropped (:func:`twinkit.mesh.bad_faces`),
   so none reaches FBX, USD, GLB or the CARLA package; the vertices stay (labels still line up);
3. a sub-mesh holds the vertices of its faces. Vertices on a class border appear in both
   sub-meshes at the same position (no cracks); each copy keeps its *own* label in the
   ``class_id`` attribute, so per class, the count of vertices whose ``class_id`` equals the
   sub-mesh's class equals the label histogram, and these "own" counts add up to the source mesh.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from twinkit.mesh import Mesh, drop_bad_faces, vertex_normals

from .classes import info, palette_lut
from .classmesh import ClassPart, class_part, read_class_ply


def face_classes(faces: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, dict]:
    """(m,) uint8 class of every face, by the rules above; and counters.

    A lone vertex takes one of its faces only where that does not leave another vertex of the
    face without a face of its own class; vertices for which no such face exists (a triangle
    whose three corners have three labels) are reported as ``lone_vertices_left`` and travel as
    loose points of their class's sub-mesh.
    """
    lab = labels[faces].astype(np.int16)  # (m, 3)
    a, b, c = lab[:, 0], lab[:, 1], lab[:, 2]
    # majority: a pair agrees -> that label; all different -> smallest
    fc = np.where((a == b) | (a == c), a, np.where(b == c, b, np.minimum(np.minimum(a, b), c))).astype(np.uint8)
    n = len(labels)
    own_count = np.zeros(n, np.int64)
    for k in range(3):
        hit = fc == labels[faces[:, k]]
        np.add.at(own_count, faces[hit, k], 1)
    used = np.zeros(n, bool)
    used[faces.ravel()] = True
    lone = np.nonzero(used & (own_count == 0))[0]
    reassigned = 0
    if len(lone):
        # vertex -> incident faces (CSR)
        flat = faces.ravel()
        order = np.argsort(flat, kind="stable")
        starts = np.searchsorted(flat[order], np.arange(n + 1))
        face_of_corner = order // 3
        for v in lone.tolist():
            if own_count[v] > 0:
                continue  # fixed by an earlier reassignment
            lv = labels[v]
            for f in face_of_corner[starts[v]:starts[v + 1]].tolist():
                old = fc[f]
                corners = faces[f]
                if any(labels[u] == old and own_count[u] <= 1 for u in corners.tolist()):
                    continue  # would strand another vertex
                for u in corners.tolist():
                    if labels[u] == old:
                        own_count[u] -= 1
                fc[f] = lv
                for u in corners.tolist():
                    if labels[u] == lv:
                        own_count[u] += 1
                reassigned += 1
                break
    left = int(np.count_nonzero(used & (own_count == 0)))
    mixed = int(np.count_nonzero((a != b) | (a != c)))
    return fc, {"mixed_faces": mixed, "faces_given_to_lone_vertices": int(reassigned), "lone_vertices_left": left}


@dataclass
class SplitResult:
    meshes: list[ClassPart]
    stats: dict


def split_mesh(mesh: Mesh, labels: np.ndarray) -> SplitResult:
    """Split ``mesh`` by per-vertex ``labels`` ((n,) uint8 trainIds, 255 unlabelled)."""
    labels = np.asarray(labels)
    n = len(mesh.vertices)
    if labels.shape != (n,):
        raise ValueError(f"labels have shape {labels.shape}, the mesh has {n} vertices")
    labels = labels.astype(np.uint8)
    input_faces = mesh.n_faces
    mesh, bad = drop_bad_faces(mesh)
    normals = mesh.normals if mesh.normals is not None else vertex_normals(mesh.vertices, mesh.faces)
    corner_uv = mesh.corner_uv if mesh.corner_uv is not None else np.zeros((len(mesh.faces), 3, 2), np.float32)
    fc, stats = face_classes(mesh.faces, labels)
    lut = palette_lut()
    # vertices that are on no face of their own class: unreferenced ones, and lone vertices that
    # could not take a face; they travel as loose points of their class's sub-mesh
    own = np.zeros(n, bool)
    for k in range(3):
        hit = fc == labels[mesh.faces[:, k]]
        own[mesh.faces[hit, k]] = True
    loose = np.nonzero(~own)[0]
    meshes = []
    for cid in np.unique(np.concatenate([fc, labels[loose]])):
        sel = np.nonzero(fc == cid)[0]
        if len(sel) == 0:
            continue  # only loose vertices of this class: nothing to draw (counted below)
        f = mesh.faces[sel]
        vids = np.unique(f.ravel())
        extra = loose[labels[loose] == cid]
        extra = extra[~np.isin(extra, vids)]
        if len(extra):
            vids = np.concatenate([vids, extra])
        remap = np.full(n, -1, np.int64)
        remap[vids] = np.arange(len(vids))
        ci = info(int(cid))
        meshes.append(class_part(
            int(cid), ci.carla_name, vertices=mesh.vertices[vids], faces=remap[f], normals=normals[vids],
            colors=lut[labels[vids]], vertex_class=labels[vids], source_index=vids, corner_uv=corner_uv[sel]))
    own_total = sum(m.own_vertices for m in meshes)
    stats.update({
        "source_vertices": int(n), "input_faces": int(input_faces), "source_faces": int(len(mesh.faces)),
        "degenerate_faces_dropped": bad["degenerate_faces"], "duplicate_faces_dropped": bad["duplicate_faces"],
        "back_to_back_faces_dropped": bad["back_to_back_faces"],
        "classes": len(meshes),
        "exported_vertices": int(sum(m.mesh.n_vertices for m in meshes)),
        "own_vertices": int(own_total),
        "border_copies": int(sum(m.mesh.n_vertices - m.own_vertices for m in meshes)),
        "loose_vertices": int(len(loose)),
        "vertices_dropped": int(n - own_total),
    })
    return SplitResult(meshes, stats)


# ----------------------------------------------------------------------------- the class_meshes folder

MANIFEST = "classes.json"


@dataclass
class ClassSet:
    """The content of a ``class_meshes`` folder."""

    folder: Path
    meshes: list[ClassPart]
    texture: Path | None
    manifest: dict


def load_class_set(folder: Path) -> ClassSet:
    folder = Path(folder)
    man_path = folder / MANIFEST
    if not man_path.exists():
        raise FileNotFoundError(f"{folder}: no {MANIFEST}; run the split_classes step first")
    man = json.loads(man_path.read_text())
    meshes = [read_class_ply(folder / c["file"]) for c in man["classes"]]
    tex = folder / man["texture"] if man.get("texture") else None
    return ClassSet(folder, meshes, tex, man)

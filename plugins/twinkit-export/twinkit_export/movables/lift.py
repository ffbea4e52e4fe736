"""``lift_movables``: the movable objects cut out of the labelled mesh, the ground closed beneath them.

The stages, each in the module named after it: the ground (:func:`ground_under`, a
:class:`twinkit.street.ground.LocalGround`), the objects
(:mod:`.detect`, their classes in :mod:`.kinds`), the labels left (:func:`relabel_left`), the holes
(:mod:`.fill`)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from twinkit.mesh import Mesh
from twinkit.mesh.core import compact, vertex_normals
from twinkit.street.ground import LocalGround

from .detect import Instance, claim_debris, find_instances
from .fill import Additions, border_edges, close_object_holes, close_other_holes
from .kinds import GROUND, MOVABLE, NAMES
from .options import LiftOptions


@dataclass
class LiftResult:
    """The static mesh and the objects lifted out of it (site frame, metres)."""

    mesh: Mesh  # the static mesh (objects cut out, holes filled), unreferenced vertices dropped
    labels: np.ndarray  # its per-vertex labels
    instances: list[Instance]
    source: Mesh  # the input mesh (instances' faces index it)
    source_labels: np.ndarray
    report: dict = field(default_factory=dict)


def lift_movables(mesh: Mesh, labels: np.ndarray, opt: LiftOptions | None = None, log=None,
                  votes: np.ndarray | None = None) -> LiftResult:
    """Cut the movable objects out of ``mesh`` (per-vertex ``labels``, CityScapes trainIds; ``votes``: the 3D
    classifier's (n, 19) class probabilities per vertex, or None); see the package doc for the stages."""
    opt = opt or LiftOptions()
    labels = np.asarray(labels).astype(np.uint8)
    v = np.array(mesh.vertices, float)  # a copy: the objects' feet are lowered onto the ground below
    f = np.asarray(mesh.faces, np.int64)
    normals = np.asarray(mesh.normals if mesh.normals is not None else vertex_normals(v, f), float)
    grid = ground_under(v, normals, opt)
    h = v[:, 2] - grid.at(v[:, :2])
    mov = np.isin(labels, MOVABLE)
    rep: dict = {"movable_vertices": int(mov.sum()), "candidate_vertices": int((mov & (h > opt.min_height_m)).sum()),
                 "ground_cells": int(grid.has_z.sum()), "geometry_votes": votes is not None}
    instances, face_owner = find_instances(v, f, h, normals, labels, grid, opt, rep, votes)
    if instances:
        claim_debris(v, f, h, face_owner, instances, opt, rep)
    removed = face_owner >= 0
    rep["faces_lifted"] = int(removed.sum())
    touched = np.zeros(len(v), bool)
    touched[f[removed].ravel()] = True
    kept = f[~removed]
    tc = mesh.face_attrs.get("texcoord")
    sm = Additions(v, kept, relabel_left(v, kept, h, labels, mov, opt, rep),
                    None if tc is None else np.asarray(tc)[~removed])
    close_object_holes(sm, touched, grid, instances, opt, rep)
    close_other_holes(sm, grid, instances, opt, rep)
    out, out_labels = _static_mesh(mesh, f, sm, rep)
    rep.update(instances=len(instances), faces_added=int(sum(len(a) for a in sm.add_f)),
               by_class={NAMES[c]: sum(1 for i in instances if i.class_id == c) for c in MOVABLE
                         if any(i.class_id == c for i in instances)})
    if log is not None:
        log.info("lifted %d movable objects (%d faces); %d loops filled, %d left open; %d labels moved to "
                 "the surrounding class", len(instances), rep["faces_lifted"], rep["loops_filled"],
                 rep["loops_left_open"], rep["relabelled_vertices"])
    return LiftResult(out, out_labels, instances, mesh, labels, rep)


def ground_under(v: np.ndarray, normals: np.ndarray, opt: LiftOptions) -> LocalGround:
    """The ground under the objects (stage 1): on a ``cell_m`` grid, the up-facing vertices (normal z >=
    ``up_normal_z``) no higher than ``ground_tol_m`` above the lowest up-facing vertex within
    ``ground_window_m`` (at least 3 cells) are ground; a cell's height is their mean; cells without ground
    (under a car's roof) take the nearest ground cell's. ``v``, ``normals`` (n, 3) float64."""
    return LocalGround(v, normals[:, 2] >= opt.up_normal_z, cell_m=opt.cell_m, window="min",
                       window_m=opt.ground_window_m, min_window_cells=3, ground_tol_m=opt.ground_tol_m,
                       ground_stat="mean", fill="nearest")


def relabel_left(v: np.ndarray, kept: np.ndarray, h: np.ndarray, labels: np.ndarray, mov: np.ndarray,
                 opt: LiftOptions, rep: dict) -> np.ndarray:
    """The labels of the static mesh: movable-labelled vertices that stay (flat ground voted car, rejected
    clusters) take the label of the nearest non-movable vertex, a ground class when the vertex is at most
    ``min_height_m`` above the ground. (n,) uint8; ``relabelled_vertices`` goes to ``rep``."""
    from scipy.spatial import cKDTree

    new_labels = labels.copy()
    stay_mov = np.zeros(len(v), bool)
    stay_mov[np.unique(kept)] = True
    stay_mov &= mov
    nonmov = np.nonzero(~mov & (labels != 255))[0]
    ground_v = np.nonzero(np.isin(labels, GROUND))[0]
    if stay_mov.any() and len(nonmov):
        q = np.nonzero(stay_mov)[0]
        low = h[q] <= opt.min_height_m
        if len(ground_v) and low.any():
            _, nn = cKDTree(v[ground_v]).query(v[q[low]])
            new_labels[q[low]] = labels[ground_v[nn]]
        if (~low).any():
            _, nn = cKDTree(v[nonmov]).query(v[q[~low]])
            new_labels[q[~low]] = labels[nonmov[nn]]
    rep["relabelled_vertices"] = int(stay_mov.sum())
    return new_labels


def _static_mesh(mesh: Mesh, f: np.ndarray, sm: Additions, rep: dict) -> tuple[Mesh, np.ndarray]:
    """The static mesh out of ``sm`` (new vertices' normals from the faces, unreferenced vertices dropped) and
    its labels; ``new_open_border_m`` (open border the lift added, against the input's faces ``f``) goes to
    ``rep``."""
    verts, faces, labs, face_tc = sm.current()
    face_attrs = {} if face_tc is None else {"texcoord": face_tc.astype(np.float32) if sm.add_tc else face_tc}
    attrs = {}
    if mesh.normals is not None:
        nrm = np.vstack([np.asarray(mesh.normals, np.float32)] + ([np.tile(np.float32([0, 0, 1]), (len(sm.add_v), 1))]
                                                                   if sm.add_v else []))
        if sm.add_f:
            fresh = vertex_normals(verts, faces)
            moved = np.zeros(len(verts), bool)
            moved[np.vstack(sm.add_f).ravel()] = True
            nrm[moved] = fresh[moved]
        attrs["normals"] = nrm
    attrs["label"] = labs
    before = {tuple(e) for e in border_edges(f).tolist()}
    after = border_edges(faces)
    new = np.array([tuple(e) not in before for e in after.tolist()], bool) if len(after) else np.zeros(0, bool)
    rep["new_open_border_m"] = round(float(np.linalg.norm(verts[after[new, 0]] - verts[after[new, 1]], axis=1).sum())
                                     if new.any() else 0.0, 3)
    out = compact(Mesh(vertices=verts, faces=faces, attrs=attrs, face_attrs=face_attrs,
                       comments=list(mesh.comments), texture=mesh.texture))
    return out, out.attrs.pop("label")

"""The cues an object must show beyond its labels before it is lifted (issue 45: a tree part was lifted as a
pedestrian, another as a bicycle; the demo's ghost points as two pedestrians).

The labels that made the cluster (the fused labels of ``backproject``, mostly the view labels) are one
cue, the shape its class allows (:func:`.kinds.choose_class`) a second. An object is lifted only when it also

- **has a body**: its footprint is at least its class's ``CLASS_MIN_WIDTH`` wide (a person 0.2 m, a car
  1.2 m); a sheet (the demo's ghosts: 0.06-0.18 m; a hedge's face) is none;
- **stands on the ground**: its faces reach down to ``ground_contact_m`` above the local ground (a
  person's feet, a car's tyres; what the cut at ``cut_height_m`` leaves). A piece of a tree's crown, a
  ghost of a passer-by hanging in the air, a sign's plate do not;
- **is movable to the 3D classifier too** (the second label source, ``geometry_votes.npy`` of
  ``classify_geometry``): at least ``min_geometry_share`` of the cluster's vertices that have a vote
  have a movable class (person, rider, car, truck, bus, train, motorcycle, bicycle) as their most
  probable class. Trees, poles and walls are static to it. Without votes (a recipe without the 3D
  classifier) this cue is not used, and the report says so.

Everything in metres, site frame; ``h`` is a vertex's height above the lift's ground grid."""
from __future__ import annotations

import numpy as np

from .kinds import CLASS_MIN_WIDTH, MOVABLE
from .options import LiftOptions


def object_cues(vid: np.ndarray, ov: np.ndarray, h: np.ndarray, votes: np.ndarray | None) -> dict:
    """The cues of one object: ``vid`` its cluster's (movable-labelled) vertices, ``ov`` the vertices of its
    grown faces, ``h`` (n,) heights above the ground, ``votes`` (n, 19) geometry class probabilities or None.
    Keys: ``ground_gap_m`` (its lowest vertex above the ground), ``geometry_voted`` (the object's vertices with
    a vote: all of its surface, whatever their label), ``geometry_movable_share`` (of those, the share whose most
    probable class is movable; None without votes)."""
    out: dict = {"ground_gap_m": round(float(h[ov].min()) if len(ov) else float("inf"), 3)}
    if votes is None:
        out.update(geometry_voted=0, geometry_movable_share=None)
        return out
    vv = votes[ov]
    voted = vv.max(axis=1) > 0
    top = vv[voted].argmax(axis=1)
    out["geometry_voted"] = int(voted.sum())
    out["geometry_movable_share"] = round(float(np.isin(top, MOVABLE).mean()), 3) if voted.any() else None
    return out


def why_not_by_cues(cues: dict, opt: LiftOptions, class_id: int, width: float) -> str | None:
    """Why an object of class ``class_id`` (after :func:`.kinds.refine_class`), ``width`` m wide, that fits its
    class by labels and shape is still not lifted (None: it is): every cue it fails, joined by ``+``:
    ``too_thin``, ``floating`` (no ground contact), ``static_to_geometry`` (the 3D classifier calls it static)."""
    failed = []
    if width < CLASS_MIN_WIDTH.get(int(class_id), 0.0):
        failed.append("too_thin")
    if cues["ground_gap_m"] > opt.ground_contact_m:
        failed.append("floating")
    share = cues.get("geometry_movable_share")
    if share is not None and cues.get("geometry_voted", 0) >= opt.min_geometry_votes and share < opt.min_geometry_share:
        failed.append("static_to_geometry")
    return "+".join(failed) or None

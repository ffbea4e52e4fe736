"""The ``lift_movables`` step: movable objects out of the static mesh (algorithm in :mod:`.movables`).

Reads the labelled textured mesh (``textured_mesh.obj`` + mtl/png, per-vertex ``labels.npy``) and
writes, for the steps after it:

- ``textured_mesh.obj`` (+ ``.mtl``, ``.png``) and ``labels.npy`` again: the static mesh with the
  objects cut out and the ground closed beneath them. A step input resolves to the latest earlier
  artefact of its name, so ``split_classes`` (and everything after it) reads these without a
  change to its wiring, and a recipe without this step works as before.
- ``movables/``: one textured PLY per object (the class-mesh PLY format of ``split_classes``, site
  frame, ``texture.png`` beside them) and ``actors.json`` (class, oriented box, faces, suggested
  CARLA blueprint). The exporters read it as an optional input.

``lift: false`` (command line ``steps.lift_movables.lift=false``) keeps every object in the static
map: the mesh and labels pass through unchanged and ``actors.json`` lists no actor.
"""
from __future__ import annotations

import dataclasses
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

from twinkit import InputError, StepContext
from twinkit.ranges import param

ACTORS = "actors.json"


@dataclass
class LiftParams:
    """Lift vehicles, riders and pedestrians out of the static mesh (see twinkit_export.movables)."""

    lift: bool = True  # false: keep every movable object in the static map (files pass through unchanged)
    min_height_m: float = param(0.25, ge=0)  # movable-labelled surface at most this above the local ground is ground
    cut_height_m: float = param(0.10, ge=0)  # an object's faces start this far above the ground
    cluster_gap_m: float = param(0.5, gt=0)  # movable-labelled vertices closer than this are one object
    ground_window_m: float = param(4.0, gt=0)  # local ground search window, wider than any vehicle
    min_vertical_share: float = param(0.15, ge=0, le=1)  # an object has walls: this share of its vertices with a near-horizontal normal
    margin_m: float = param(0.3, ge=0)  # footprint widening when collecting an object's faces
    fill_cell_m: float = param(0.1, ge=0)  # holes left under an object are filled on this grid at the ground's height (0: fan)
    flatten_feet_m: float = param(0.5, ge=0)  # the object's cut-off feet up to this high are lowered onto the ground (0: kept)
    max_fill_extent_m: float = param(3.0, ge=0)  # holes reaching farther than this beyond an object's footprint stay open
    gap_max_m: float = param(1.0, ge=0)  # what no loop fill closes: spots up to this wide that a ray at the ground falls
    #                 through, with surface all round, get a ground patch (found on a 5 cm grid); 0 = off
    fin_min_m: float = param(0.2, ge=0)  # flaps left at an object's foot, on the open border, above this go with it (0: off)
    ground_hole_max_m: float = param(8.0, ge=0)  # every other hole of the ground up to this wide is closed on the ground
    #                         (the clean step's fill_ground_max_gap_m: a wider gap is unscanned and stays open); 0 = off


def _actor_json(inst, file: str) -> dict:
    from .classes import info
    from .movables import suggest_blueprint

    ci = info(inst.class_id)
    return {"id": inst.id, "name": inst.name, "class": ci.name, "class_id": inst.class_id, "file": file,
            "box": {"center": [round(float(x), 3) for x in inst.center],
                    "size": [round(float(x), 3) for x in inst.size],
                    "yaw_deg": round(float(inst.yaw_deg), 2)},
            "ground_z": round(float(inst.ground_z), 3), "faces": int(len(inst.faces)), "vertices": inst.vertices,
            "label_share": round(float(inst.label_share), 3), "class_by": inst.class_by,
            "blueprint": suggest_blueprint(inst.class_id, inst.size)}


def instance_mesh(res, inst):
    """The object's faces as a :class:`ClassMesh` (vertex_class = the object's class)."""
    import numpy as np

    from .classes import palette_lut
    from .classmesh import ClassMesh
    from twinkit.mesh.core import vertex_normals

    src = res.source
    f = np.asarray(src.faces, np.int64)[inst.faces]
    vids = np.unique(f)
    remap = np.full(src.n_vertices, -1, np.int64)
    remap[vids] = np.arange(len(vids))
    nrm = src.normals if src.normals is not None else vertex_normals(src.vertices, src.faces)
    tc = src.face_attrs.get("texcoord")
    uv = (np.asarray(tc, np.float32)[inst.faces].reshape(-1, 3, 2) if tc is not None
          else np.zeros((len(f), 3, 2), np.float32))
    cls = np.full(len(vids), inst.class_id, np.uint8)
    return ClassMesh(class_id=inst.class_id, name=inst.name, vertices=src.vertices[vids].astype(np.float64),
                     normals=np.asarray(nrm, np.float32)[vids], colors=palette_lut()[cls], vertex_class=cls,
                     source_index=vids.astype(np.int32), faces=remap[f].astype(np.int32), corner_uv=uv)


def lift_movables_step(params: LiftParams, ctx: StepContext, *, in_labels_npy: Path, in_textured_mesh_obj: Path,
                       out_textured_mesh_obj: Path, out_labels_npy: Path, out_movables_dir: Path) -> dict:
    """Cut vehicles, riders and pedestrians out of the static mesh; one PLY + actor entry per object."""
    import numpy as np

    from twinkit.jsonio import write_json
    from twinkit import artefacts as A

    from .classmesh import write_class_ply
    from .movables import NAMES, LiftOptions, lift_movables, open_border_near

    params = params or LiftParams()
    t0 = time.perf_counter()
    src_obj = Path(in_textured_mesh_obj)
    labels = A.read_labels(in_labels_npy)
    mesh = A.read_textured_obj(src_obj)
    if labels.ndim != 1 or len(labels) != mesh.n_vertices:
        raise InputError(f"{Path(in_labels_npy).name}: {labels.shape} labels for {mesh.n_vertices} vertices of "
                         f"{src_obj.name}; the labels must be per vertex of this mesh (re-run the segmentation on it)")
    out_obj = Path(out_textured_mesh_obj)
    mov_dir = Path(out_movables_dir)
    mov_dir.mkdir(parents=True, exist_ok=True)
    tex_name = None
    if mesh.texture is not None and Path(mesh.texture).exists():
        tex_name = out_obj.stem + Path(mesh.texture).suffix.lower()
        shutil.copyfile(mesh.texture, out_obj.parent / tex_name)
    frame = "site local: metres, x east, y north, z up; yaw counter-clockwise from east, of the long axis"
    if not params.lift:
        shutil.copyfile(src_obj, out_obj)
        mtl = src_obj.with_suffix(".mtl")
        if mtl.exists():
            shutil.copyfile(mtl, out_obj.with_suffix(".mtl"))
        A.write_labels(out_labels_npy, labels)
        write_json(mov_dir / ACTORS, {"lifted": False, "frame": frame, "texture": None, "actors": []})
        ctx.log.info("lift=false: movable objects stay in the static map")
        return {"lifted": False, "instances": 0}
    opt = LiftOptions(**{k: getattr(params, k) for k in (f.name for f in dataclasses.fields(LiftOptions))
                         if hasattr(params, k)})
    res = lift_movables(mesh, labels, opt, ctx.log)
    out = res.mesh
    tc = out.corner_uv if out.corner_uv is not None else np.zeros((out.n_faces, 3, 2), np.float32)
    A.write_textured_obj(out_obj, out.vertices, out.faces, tc, tex_name or "", normals=out.normals)
    A.write_labels(out_labels_npy, res.labels.astype(np.uint8))
    mtex = None
    if tex_name:
        mtex = "texture" + Path(tex_name).suffix
        shutil.copyfile(out_obj.parent / tex_name, mov_dir / mtex)
    actors = []
    for inst in res.instances:
        fname = f"{inst.name}.ply"
        write_class_ply(mov_dir / fname, instance_mesh(res, inst), mtex)
        actors.append(_actor_json(inst, fname))
        if inst.class_by == "size":
            ctx.log.info("lift_movables: %s at (%.1f, %.1f), %.1f x %.1f x %.1f m, is a %s by its size: the labels "
                         "named a class its shape rules out (%.0f %% of its vertices agree)", inst.name,
                         inst.center[0], inst.center[1], *inst.size, NAMES[inst.class_id].lower(),
                         100 * inst.label_share)
    before = open_border_near(mesh.faces, mesh.vertices, res.instances)
    after = open_border_near(out.faces, out.vertices, res.instances)
    rep = {**res.report, "open_border_near_objects_before_m": round(before, 3),
           "open_border_near_objects_after_m": round(after, 3)}
    write_json(mov_dir / ACTORS, {"lifted": True, "frame": frame, "texture": mtex, "source": src_obj.name,
                                  "report": rep, "actors": actors})
    return {"lifted": True, **rep, "static_faces": out.n_faces, "seconds": round(time.perf_counter() - t0, 2)}


def load_actors(folder: Path | None) -> tuple[dict, list]:
    """(actors.json content, [ClassMesh per actor]) of a ``movables`` folder; ({}, []) for None."""
    from .classmesh import read_class_ply

    if folder is None:
        return {}, []
    folder = Path(folder)
    p = folder / ACTORS
    if not p.exists():
        raise InputError(f"{folder}: no {ACTORS}; re-run the lift_movables step")
    import json

    data = json.loads(p.read_text())
    meshes = [read_class_ply(folder / a["file"]) for a in data.get("actors", [])]
    return data, meshes

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


@dataclass
class LiftParams:
    """Lift vehicles, riders and pedestrians out of the static mesh (see twinkit_export.movables)."""

    lift: bool = param(True, help="false: keep every movable object in the static map (files pass through "
                                  "unchanged)")
    min_height_m: float = param(0.25, ge=0, help="movable-labelled surface at most this above the local ground is "
                                                 "ground")
    cut_height_m: float = param(0.10, ge=0, help="an object's faces start this far above the ground")
    cluster_gap_m: float = param(0.5, gt=0, help="movable-labelled vertices closer than this are one object")
    ground_window_m: float = param(4.0, gt=0, help="local ground search window, wider than any vehicle")
    min_vertical_share: float = param(0.15, ge=0, le=1, help="an object has walls: this share of its vertices "
                                                             "with a near-horizontal normal")
    margin_m: float = param(0.3, ge=0, help="footprint widening when collecting an object's faces")
    fill_cell_m: float = param(0.1, ge=0, help="holes left under an object are filled on this grid at the "
                                               "ground's height (0: spanned at the ring's heights: a fan or ear clipping)")
    flatten_feet_m: float = param(0.5, ge=0, help="the object's cut-off feet up to this high are lowered onto "
                                                  "the ground (0: kept)")
    max_fill_extent_m: float = param(3.0, ge=0, help="holes reaching farther than this beyond an object's "
                                                     "footprint stay open")
    gap_max_m: float = param(1.0, ge=0, help="what no loop fill closes: spots up to this wide that a ray at the "
                                             "ground falls through, with surface all round, get a ground patch "
                                             "(found on a 5 cm grid); 0 = off")
    fin_min_m: float = param(0.2, ge=0, help="flaps left at an object's foot, on the open border, above this go "
                                             "with it (0: off)")
    ground_hole_max_m: float = param(8.0, ge=0, help="every other hole of the ground up to this wide is closed "
                                                     "on the ground (the clean step's fill_ground_max_gap_m: a "
                                                     "wider gap is unscanned and stays open); 0 = off")
    ground_contact_m: float = param(0.25, ge=0, help="an object is lifted only when it reaches this close to the "
                                                     "ground (feet, tyres); else it floats and stays static")
    min_geometry_share: float = param(0.5, ge=0, le=1, help="... and when at least this share of its vertices the "
                                                            "3D classifier voted on are movable to it; 0 = off")


def lift_movables_step(params: LiftParams, ctx: StepContext, *, in_labels_npy: Path, in_textured_mesh_obj: Path,
                       out_textured_mesh_obj: Path, out_labels_npy: Path, out_movables_dir: Path,
                       in_geometry_votes_npy: Path | None = None) -> dict:
    """Cut vehicles, riders and pedestrians out of the static mesh; one PLY + actor entry per object. An object
    must look like its class by its labels, its shape, its ground contact and the 3D classifier's votes
    (``geometry_votes.npy`` of ``classify_geometry``, when the recipe has it): :mod:`.movables.cues`."""
    import numpy as np

    from twinkit import artefacts as A
    from twinkit.jsonio import write_json

    from .movables import LiftOptions, lift_movables, open_border_near
    from .movables.actors import ACTORS, FRAME, write_actors

    params = params or LiftParams()
    t0 = time.perf_counter()
    with ctx.substep("read"):
        mesh, labels = _read_inputs(Path(in_textured_mesh_obj), Path(in_labels_npy))
    out_obj, mov_dir = Path(out_textured_mesh_obj), Path(out_movables_dir)
    mov_dir.mkdir(parents=True, exist_ok=True)
    tex_name = None
    if mesh.texture is not None and Path(mesh.texture).exists():
        tex_name = out_obj.stem + Path(mesh.texture).suffix.lower()
        shutil.copyfile(mesh.texture, out_obj.parent / tex_name)
    if not params.lift:
        _pass_through(Path(in_textured_mesh_obj), out_obj, labels, Path(out_labels_npy))
        write_json(mov_dir / ACTORS, {"lifted": False, "frame": FRAME, "texture": None, "actors": []})
        ctx.log.info("lift=false: movable objects stay in the static map")
        return {"lifted": False, "instances": 0}
    opt = LiftOptions(**{k: getattr(params, k) for k in (f.name for f in dataclasses.fields(LiftOptions))
                         if hasattr(params, k)})
    votes = None
    if in_geometry_votes_npy is not None and Path(in_geometry_votes_npy).exists():
        votes = A.read_class_votes(in_geometry_votes_npy, mesh.n_vertices, Path(in_textured_mesh_obj).name)
    else:
        ctx.log.warning("lift_movables: no geometry_votes.npy (no classify_geometry step): objects are judged by the "
                        "labels, their shape and their ground contact only")
    with ctx.substep("lift"):
        res = lift_movables(mesh, labels, opt, ctx.log, votes)
    with ctx.substep("write"):
        out = res.mesh
        tc = out.corner_uv if out.corner_uv is not None else np.zeros((out.n_faces, 3, 2), np.float32)
        A.write_textured_obj(out_obj, out.vertices, out.faces, tc, tex_name or "", normals=out.normals)
        A.write_labels(out_labels_npy, res.labels.astype(np.uint8))
        mtex = None
        if tex_name:
            mtex = "texture" + Path(tex_name).suffix
            shutil.copyfile(out_obj.parent / tex_name, mov_dir / mtex)
        actors = write_actors(mov_dir, res, mtex, ctx.log)
    with ctx.substep("open_border"):
        rep = {**res.report,
               "open_border_near_objects_before_m": round(open_border_near(mesh.faces, mesh.vertices, res.instances), 3),
               "open_border_near_objects_after_m": round(open_border_near(out.faces, out.vertices, res.instances), 3)}
    write_json(mov_dir / ACTORS, {"lifted": True, "frame": FRAME, "texture": mtex, "source": Path(in_textured_mesh_obj).name,
                                  "report": rep, "actors": actors})
    return {"lifted": True, **rep, "static_faces": out.n_faces, "seconds": round(time.perf_counter() - t0, 2)}


def _read_inputs(src_obj: Path, labels_npy: Path):
    """(the textured mesh, its per-vertex labels (n,)); InputError when unreadable or not per vertex."""
    from twinkit import artefacts as A

    labels = A.read_labels(labels_npy)
    mesh = A.read_textured_obj(src_obj)
    if labels.ndim != 1 or len(labels) != mesh.n_vertices:
        raise InputError(f"{labels_npy.name}: {labels.shape} labels for {mesh.n_vertices} vertices of "
                         f"{src_obj.name}; the labels must be per vertex of this mesh (re-run the segmentation on it)")
    return mesh, labels


def _pass_through(src_obj: Path, out_obj: Path, labels, out_labels_npy: Path) -> None:
    """``lift: false``: the mesh (with its .mtl) and the labels unchanged."""
    from twinkit import artefacts as A

    shutil.copyfile(src_obj, out_obj)
    mtl = src_obj.with_suffix(".mtl")
    if mtl.exists():
        shutil.copyfile(mtl, out_obj.with_suffix(".mtl"))
    A.write_labels(out_labels_npy, labels)

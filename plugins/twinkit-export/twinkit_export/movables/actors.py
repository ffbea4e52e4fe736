"""Actor writing: each lifted object as a CARLA blueprint suggestion, an entry of ``actors.json`` and a
textured PLY (the class-mesh format of ``split_classes``, site frame), and reading them back."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from twinkit import InputError
from twinkit import cityscapes as cs

#: the file of a ``movables`` folder that lists the actors
ACTORS = "actors.json"
#: the frame the boxes of ``actors.json`` are in
FRAME = "site local: metres, x east, y north, z up; yaw counter-clockwise from east, of the long axis"


#: CARLA 0.9.16 blueprints per class, with nominal (length, width, height) in metres. The ids are those of
#: carla-simulator/carla Docs/catalogue_vehicles.md and Docs/bp_library.md (0.9.16); the sizes are the
#: real models' nominal dimensions (manufacturer figures, rounded), not CARLA's bounding boxes, which a
#: running simulator reports (``actor.bounding_box``) -- close enough to pick a model by size.
BLUEPRINTS: dict[int, list[tuple[str, tuple[float, float, float]]]] = {
    cs.CAR: [("vehicle.micro.microlino", (2.52, 1.47, 1.50)),
         ("vehicle.mini.cooper_s_2021", (3.88, 1.73, 1.43)),
         ("vehicle.nissan.micra", (3.78, 1.67, 1.52)),
         ("vehicle.audi.a2", (3.83, 1.67, 1.55)),
         ("vehicle.citroen.c3", (3.94, 1.73, 1.52)),
         ("vehicle.seat.leon", (4.28, 1.82, 1.46)),
         ("vehicle.toyota.prius", (4.54, 1.76, 1.49)),
         ("vehicle.bmw.grandtourer", (4.56, 1.80, 1.61)),
         ("vehicle.tesla.model3", (4.69, 1.85, 1.44)),
         ("vehicle.ford.mustang", (4.78, 1.92, 1.38)),
         ("vehicle.audi.etron", (4.90, 1.94, 1.63)),
         ("vehicle.lincoln.mkz_2020", (4.93, 1.86, 1.48)),
         ("vehicle.dodge.charger_2020", (5.04, 1.91, 1.48)),
         ("vehicle.nissan.patrol_2021", (5.17, 1.99, 1.94))],
    cs.TRUCK: [("vehicle.mercedes.sprinter", (5.93, 2.02, 2.59)),
         ("vehicle.ford.ambulance", (6.40, 2.30, 2.80)),
         ("vehicle.carlamotors.carlacola", (5.20, 2.60, 2.60)),
         ("vehicle.carlamotors.firetruck", (8.50, 2.50, 3.30))],
    cs.BUS: [("vehicle.mitsubishi.fusorosa", (10.30, 2.40, 3.20))],
    cs.MOTORCYCLE: [("vehicle.vespa.zx125", (1.80, 0.70, 1.15)),
         ("vehicle.yamaha.yzf", (2.05, 0.70, 1.10)),
         ("vehicle.kawasaki.ninja", (2.00, 0.75, 1.10)),
         ("vehicle.harley-davidson.low_rider", (2.35, 0.90, 1.10))],
    cs.BICYCLE: [("vehicle.bh.crossbike", (1.75, 0.60, 1.05)),
         ("vehicle.diamondback.century", (1.75, 0.55, 1.05)),
         ("vehicle.gazelle.omafiets", (1.85, 0.65, 1.15))],
    cs.PERSON: [("walker.pedestrian.0001", (0.5, 0.5, 1.8))],
    cs.RIDER: [("walker.pedestrian.0001", (0.5, 0.5, 1.8))],  # CARLA has no rider; a walker, the bicycle is its own actor
}


def suggest_blueprint(class_id: int, size) -> dict | None:
    """The blueprint of the class whose nominal size is closest to ``size`` (length, width, height)
    by the sum of |log ratio| per axis; None for classes CARLA has no blueprint for (train)."""
    opts = BLUEPRINTS.get(int(class_id))
    if not opts:
        return None
    s = np.maximum(np.asarray(size, float), 0.05)
    best = min(opts, key=lambda o: float(np.abs(np.log(s / np.asarray(o[1]))).sum()))
    err = np.abs(np.log(s / np.asarray(best[1])))
    return {"id": best[0], "nominal_size_m": list(best[1]), "size_mismatch": round(float(err.max()), 3)}


def actor_json(inst, file: str) -> dict:
    from ..classes import info

    ci = info(inst.class_id)
    return {"id": inst.id, "name": inst.name, "class": ci.name, "class_id": inst.class_id, "file": file,
            "box": {"center": [round(float(x), 3) for x in inst.center],
                    "size": [round(float(x), 3) for x in inst.size],
                    "yaw_deg": round(float(inst.yaw_deg), 2)},
            "ground_z": round(float(inst.ground_z), 3), "faces": int(len(inst.faces)), "vertices": inst.vertices,
            "label_share": round(float(inst.label_share), 3), "class_by": inst.class_by, "cues": inst.cues,
            "blueprint": suggest_blueprint(inst.class_id, inst.size)}


def instance_mesh(res, inst):
    """The object's faces as a :class:`ClassPart` (every vertex labelled with the object's class)."""
    from ..classes import palette_lut
    from ..classmesh import class_part
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
    return class_part(inst.class_id, inst.name, vertices=src.vertices[vids], faces=remap[f],
                      normals=np.asarray(nrm, np.float32)[vids], colors=palette_lut()[cls], vertex_class=cls,
                      source_index=vids, corner_uv=uv)


def write_actors(mov_dir: Path, res, mtex: str | None, log=None) -> list[dict]:
    """One PLY per instance of the lift result ``res`` in ``mov_dir`` (texture file ``mtex`` beside them);
    returns their ``actors.json`` entries."""
    from ..classmesh import write_class_ply
    from .kinds import NAMES

    actors = []
    for inst in res.instances:
        fname = f"{inst.name}.ply"
        write_class_ply(Path(mov_dir) / fname, instance_mesh(res, inst), mtex)
        actors.append(actor_json(inst, fname))
        if inst.class_by == "size" and log is not None:
            log.info("lift_movables: %s at (%.1f, %.1f), %.1f x %.1f x %.1f m, is a %s by its size: the labels "
                     "named a class its shape rules out (%.0f %% of its vertices agree)", inst.name,
                     inst.center[0], inst.center[1], *inst.size, NAMES[inst.class_id].lower(),
                     100 * inst.label_share)
    return actors


def load_actors(folder: Path | None) -> tuple[dict, list]:
    """(actors.json content, [ClassPart per actor]) of a ``movables`` folder; ({}, []) for None."""
    from ..classmesh import read_class_ply

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

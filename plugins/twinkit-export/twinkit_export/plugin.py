"""twinkit export plugins (entry point ``export`` in group ``twinkit``).

Steps: ``gt_labels`` (ground-truth labels on the reconstructed mesh, a stand-in for the
segmentation), ``split_classes`` (one sub-mesh per class). Exporters: ``fbx``, ``usd``, ``gltf``,
``carla_package``. Heavy libraries (bpy, pxr, carla, open3d, PIL) are imported inside the steps.
"""
from __future__ import annotations

import json
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

from twinkit import InputError, StepContext, hookimpl
from twinkit.ranges import param

from .lift_step import LiftParams, lift_movables_step


# ----------------------------------------------------------------------------- parameters

@dataclass
class SplitParams:
    """Split the labelled, textured mesh into one sub-mesh per class."""

    max_texture_px: int = param(8192, ge=0, le=65536,
                                help="A larger texture atlas is downscaled to this size (px; 8192 is Unreal's "
                                     "default limit); 0 = keep the size.")
    sidewalk_cleanup: bool = param(True, help="Join or dissolve the sidewalk fragments so each block's sidewalk is one "
                                              "connected surface for CARLA's navmesh (sidewalks.py); false: the "
                                              "labels as they come.")
    sidewalk_join_gap_m: float = param(1.5, ge=0, help="Longest walkable path (m) over road-level ground of the "
                                                       "pavement that joins a sidewalk fragment to its surface.")
    sidewalk_keep_m2: float = param(20.0, ge=0, help="A sidewalk surface at least this large (m^2) is kept when it "
                                                     "cannot be joined; smaller fragments are dissolved into the "
                                                     "class around them.")
    sidewalk_max_slope: float = param(0.35, gt=0, help="Steepest mesh edge (rise over run) a joining path may follow.")
    sidewalk_max_rise_m: float = param(0.05, ge=0, help="A joining path rises and falls at most this much (m) off the "
                                                        "fragment's height (deeper only in a sag less than half the "
                                                        "kerb beside it), and the fragment lies within this of the "
                                                        "pavement it joins: a kerb (6 cm and more) is never crossed.")


@dataclass
class FbxParams:
    """FBX through Blender (bpy) in a subprocess."""

    embed_texture: bool = param(False, help="Embed the texture in the FBX too (a bigger file).")
    save_blend: bool = param(False, help="Also write twin.blend, for inspection in Blender.")


@dataclass
class UsdParams:
    """USD through usd-core."""

    validate: bool = param(True, help="Run usd-core's validators; an error fails the step.")
    semantics_taxonomy: str = param("class",
                                    help="Instance name of the SemanticsLabelsAPI (semantics:labels:<taxonomy>).")
    colliders: bool = param(True,
                            help="Add UsdPhysics collision (triangle mesh) to the static classes, not to the "
                                 "movable ones.")
    isaac_legacy_semantics: bool = param(True,
                                         help="Also write the older Semantics schema (SemanticsAPI), read by Isaac "
                                              "Sim before 5.0.")
    geo_schemas: bool = param(True,
                              help="Georeference the stage for its consumers: the Omniverse WGS84 reference "
                                   "position and a Cesium origin.")


@dataclass
class GltfParams:
    """GLB for viewing in a browser."""

    texture_format: str = param("jpeg", choices=("jpeg", "png"),
                                help="Texture encoding in the GLB: jpeg (smaller, for the web) or png (lossless).")
    jpeg_quality: int = param(90, ge=1, le=100, help="JPEG quality (1..100) with texture_format=jpeg.")
    unlit: bool = param(True,
                        help="Mark the materials unlit (KHR_materials_unlit): the texture already holds the "
                             "captured light.")
    variants: bool = param(True,
                           help='Add material variants (KHR_materials_variants): "photo" and "segmentation" (flat '
                                "class colours).")


@dataclass
class CarlaPackageParams:
    """CARLA import package (``Import/<Package>/``)."""

    package: str = param("", help='Package name; empty = "<Site>Twin" from the site name.')
    map_name: str = param("", help='Map name (the FBX and XODR file names); empty = "<Site>".')
    use_carla_materials: bool = param(False,
                                      help="Let CARLA replace the road, sidewalk and terrain materials by its own.")
    spawn_spacing_m: float = param(20.0, gt=0, help="Distance (m) between spawn points along a driving lane.")
    spawn_height_m: float = param(0.5, ge=0, help="Spawn points are raised this much (m) above the lane.")
    skip_junctions: bool = param(True, help="Put no spawn points inside junctions.")
    decals: bool = param(False,
                         help="Let CARLA add its default random road decals (dirt, cracks, tyre marks, road lines).")
    carla_version: str = param("0.9.16", help="The CARLA version the package is made for.")
    frame: str = param("carla", choices=("carla", "site"),
                       help="carla: a true-north frame at the base point, in which CARLA's geolocation works; site: "
                            "the site frame (CARLA's geolocation is then wrong).")
    frame_scale: str = param("auto", choices=("auto", "site", "true", "minimax"),
                             help="Scale of the carla frame: auto, site (rotation only), true (true metres) or "
                                  "minimax (see docs/georeferencing.md).")
    geolocation_radius_m: float = param(150.0, gt=0,
                                        help="Only for a twin without points: CARLA's geolocation is then held "
                                             "within geolocation_tolerance_m up to this distance (m) from the base "
                                             "point (else at the twin's own points).")
    geolocation_tolerance_m: float = param(0.5, gt=0,
                                           help="The error (m) CARLA's geolocation may have where the twin is (its "
                                                "meshes and map); a warning when the frame cannot meet it.")


# ----------------------------------------------------------------------------- helpers

def _georef(ctx: StepContext, in_site_json: Path | None) -> dict:
    from twinkit.geo import site_georef

    return site_georef(getattr(ctx, "site", None), in_site_json)


def _load_set(in_class_meshes_dir: Path):
    from .split import load_class_set

    try:
        return load_class_set(Path(in_class_meshes_dir))
    except FileNotFoundError as exc:
        raise InputError(str(exc)) from None


def _link_or_copy(src: Path, dst: Path) -> None:
    # a copy, not a hard link: the engine hard-links stored results into the numbered folders, and a
    # link to an input would make a hand edit of one step's texture look like an edit of another's
    shutil.copyfile(src, dst)


def _size(p: Path) -> int:
    p = Path(p)
    if p.is_dir():
        return sum(f.stat().st_size for f in p.rglob("*") if f.is_file())
    return p.stat().st_size if p.exists() else 0


def _camel(name: str) -> str:
    parts = [p for p in "".join(ch if ch.isalnum() else " " for ch in name).split() if p]
    out = "".join(p[:1].upper() + p[1:] for p in parts)
    return out if out and out[0].isalpha() else f"Site{out}"


# ----------------------------------------------------------------------------- steps

def _clean_sidewalks(params: SplitParams, mesh, labels, log):
    """(labels, stats): the sidewalk fragments joined or dissolved (sidewalks.py), or the labels as they come."""
    if not params.sidewalk_cleanup:
        return labels, {}
    from .sidewalks import connect_sidewalks

    sw = connect_sidewalks(mesh.vertices, mesh.faces, labels, join_gap_m=params.sidewalk_join_gap_m,
                           keep_m2=params.sidewalk_keep_m2, max_slope=params.sidewalk_max_slope,
                           max_rise_m=params.sidewalk_max_rise_m)
    log.info("sidewalk: %d surfaces -> %d (%d fragments joined, %d dissolved: %.1f m^2; %d vertices relabelled)",
             sw.components_before, sw.components_after, sw.joined, sw.dissolved, sw.dissolved_m2,
             sw.relabelled_vertices)
    return sw.labels, sw.stats()


def split_classes(params: SplitParams, ctx: StepContext, *, in_labels_npy: Path, in_textured_mesh_obj: Path,
                  out_class_meshes_dir: Path) -> dict:
    """One PLY per class (palette colours, class_id, source_index, face UVs) + classes.json + the texture."""
    import numpy as np

    from twinkit import artefacts as A

    from .classes import info
    from .classmesh import write_class_ply
    from .split import MANIFEST, split_mesh

    params = params or SplitParams()
    t0 = time.perf_counter()
    labels = A.read_labels(in_labels_npy)
    mesh = A.read_textured_obj(in_textured_mesh_obj)
    if labels.ndim != 1 or len(labels) != len(mesh.vertices):
        raise InputError(f"{Path(in_labels_npy).name}: {labels.shape} labels for {len(mesh.vertices)} vertices of "
                         f"{Path(in_textured_mesh_obj).name}; the labels must be per vertex of this mesh "
                         f"(re-run the segmentation on it)")
    if labels.dtype.kind not in "ui" or labels.min() < 0 or labels.max() > 255:
        raise InputError(f"{Path(in_labels_npy).name}: labels must be integers 0-255 (trainIds, 255 = unlabelled)")
    t_read = time.perf_counter() - t0
    labels, sidewalk = _clean_sidewalks(params, mesh, labels, ctx.log)
    res = split_mesh(mesh, labels.astype(np.uint8))
    out = Path(out_class_meshes_dir)
    out.mkdir(parents=True, exist_ok=True)
    tex_name = None
    tex_info = {}
    if mesh.texture is not None:
        from PIL import Image

        Image.MAX_IMAGE_PIXELS = None
        with Image.open(mesh.texture) as im:
            w, h = im.size
            tex_info = {"texture_px": [w, h]}
            limit = int(params.max_texture_px)
            tex_name = "texture" + mesh.texture.suffix.lower()
            if limit > 0 and max(w, h) > limit:
                s = limit / max(w, h)
                im2 = im.convert("RGB").resize((max(1, round(w * s)), max(1, round(h * s))), Image.LANCZOS)
                tex_name = "texture.png"
                im2.save(out / tex_name)
                tex_info["texture_downscaled_to"] = list(im2.size)
                ctx.log.warning("texture %dx%d downscaled to %dx%d (max_texture_px=%d)", w, h, *im2.size, limit)
            else:
                _link_or_copy(mesh.texture, out / tex_name)
    else:
        ctx.log.warning("%s: no texture found (map_Kd in the .mtl); exports will be untextured",
                        Path(in_textured_mesh_obj).name)
    classes = []
    for cm in res.meshes:
        ci = info(cm.class_id)
        fname = f"{cm.class_id:03d}_{cm.name}.ply"
        write_class_ply(out / fname, cm, tex_name)
        classes.append({"class_id": cm.class_id, "cityscapes": ci.name, "name": cm.name, "file": fname,
                        "vertices": cm.mesh.n_vertices, "own_vertices": cm.own_vertices, "faces": cm.mesh.n_faces,
                        "label_count": int(np.count_nonzero(labels == cm.class_id)),
                        "carla_tag": ci.carla_tag, "carla_auto_tag": ci.auto_tag, "carla_folder": ci.carla_folder,
                        "color": list(ci.color)})
    manifest = {"source": Path(in_textured_mesh_obj).name, "texture": tex_name, **tex_info,
                "frame": "site local: metres, x east, y north, z up", "stats": {**res.stats, **sidewalk},
                "classes": classes}
    (out / MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n")
    ctx.log.info("split %d vertices / %d faces into %d classes (%d border copies)", res.stats["source_vertices"],
                 res.stats["source_faces"], len(classes), res.stats["border_copies"])
    ctx.log.info("dropped before the split: %d degenerate faces, %d duplicate faces (%d of them back-to-back)",
                 res.stats["degenerate_faces_dropped"], res.stats["duplicate_faces_dropped"],
                 res.stats["back_to_back_faces_dropped"])
    return {**res.stats, **sidewalk, "read_s": round(t_read, 2), "total_s": round(time.perf_counter() - t0, 2),
            "per_class": {c["name"]: {"vertices": c["vertices"], "own": c["own_vertices"], "faces": c["faces"]}
                          for c in classes}}


# ----------------------------------------------------------------------------- exporters

def export_fbx(params: FbxParams, ctx: StepContext, *, in_class_meshes_dir: Path, out_twin_fbx: Path,
               in_site_json: Path | None = None) -> dict:
    """twin.fbx (+ twin.png beside it): one object per class, CARLA names, metres, Z up / -Y front."""
    from .fbx import FbxExportError, bpy_python, write_fbx

    params = params or FbxParams()
    t0 = time.perf_counter()
    cs = _load_set(in_class_meshes_dir)
    out = Path(out_twin_fbx)
    tex = None
    if cs.texture is not None:
        tex = out.with_suffix(cs.texture.suffix)
        _link_or_copy(cs.texture, tex)
    files = [cs.folder / c["file"] for c in cs.manifest["classes"] if c["faces"] > 0]
    blend = out.with_suffix(".blend") if params.save_blend else None
    try:
        write_fbx(files, tex, out, georef=_georef(ctx, in_site_json), embed_texture=params.embed_texture,
                  python=bpy_python(), log_path=Path(ctx.workdir) / "bpy.log", blend=blend)
    except FbxExportError as exc:
        raise InputError(str(exc)) if "needs Blender" in str(exc) else exc
    return {"objects": [c["name"] for c in cs.manifest["classes"] if c["faces"] > 0],
            "fbx_bytes": _size(out), "texture_bytes": _size(tex) if tex else 0,
            "seconds": round(time.perf_counter() - t0, 2)}


def export_usd(params: UsdParams, ctx: StepContext, *, in_class_meshes_dir: Path, out_twin_usd: Path,
               in_site_json: Path | None = None, in_movables_dir: Path | None = None) -> dict:
    """twin.usd (binary crate, + twin.png): Mesh prim per class, UsdPreviewSurface, semantic labels, georeference."""
    from .usd import validation_report, write_usd

    params = params or UsdParams()
    t0 = time.perf_counter()
    cs = _load_set(in_class_meshes_dir)
    out = Path(out_twin_usd)
    tex_name = None
    if cs.texture is not None:
        tex = out.with_suffix(cs.texture.suffix)
        _link_or_copy(cs.texture, tex)
        tex_name = tex.name
    from .movables.actors import load_actors

    _, movables = load_actors(in_movables_dir)  # lifted objects: /Site/Movables/<Name>, no collider
    stats = write_usd(cs.meshes, tex_name, out, _georef(ctx, in_site_json),
                      semantics_taxonomy=params.semantics_taxonomy, colliders=params.colliders,
                      old_semantics=params.isaac_legacy_semantics, geo_schemas=params.geo_schemas,
                      movables=movables)
    t_write = time.perf_counter() - t0
    metrics = {"prims": list(stats), "movables": len(movables), "colliders": [k for k, v in stats.items() if v["collider"]],
               "usd_bytes": _size(out), "write_s": round(t_write, 2)}
    if params.validate:
        rep = validation_report(out)
        metrics.update({"validation_errors": rep["errors"], "validation_warnings": rep["warnings"],
                        "validators": rep["validators"]})
        for msg in rep["messages"]:
            ctx.log.warning("usd validation: %s", msg)
        if rep["errors"]:
            raise RuntimeError(f"{out.name}: {rep['errors']} USD validation errors: {rep['messages'][:5]}")
    metrics["seconds"] = round(time.perf_counter() - t0, 2)
    return metrics


def export_gltf(params: GltfParams, ctx: StepContext, *, in_class_meshes_dir: Path, out_twin_glb: Path,
                in_site_json: Path | None = None) -> dict:
    """twin.glb: the photo texture, segmentation in _CLASS_COLOR / _CLASS_ID and a material variant; node per class."""
    from .gltf import write_glb

    params = params or GltfParams()
    if params.texture_format not in ("jpeg", "png"):
        raise InputError(f"gltf: texture_format={params.texture_format!r} must be jpeg or png")
    t0 = time.perf_counter()
    cs = _load_set(in_class_meshes_dir)
    stats = write_glb(cs.meshes, cs.texture, Path(out_twin_glb), _georef(ctx, in_site_json),
                      texture_format=params.texture_format, jpeg_quality=params.jpeg_quality, unlit=params.unlit,
                      variants=params.variants)
    return {"nodes": list(stats), "gltf_vertices": sum(s["vertices"] for s in stats.values()),
            "glb_bytes": _size(out_twin_glb), "seconds": round(time.perf_counter() - t0, 2)}


def _no_roads_map(xodr: Path) -> bool:
    """The map road_source=scan writes when the scan holds no road (userData twinkit_roads=none)."""
    from twinkit.artefacts import ArtefactError, read_opendrive
    from twinkit.geo.xodr import has_no_roads

    try:
        return has_no_roads(read_opendrive(xodr))
    except ArtefactError:  # unreadable: the package step says so when it reads the map
        return False


def _package_names(params: CarlaPackageParams, ctx: StepContext) -> tuple[str, str]:
    """(map name, package name): the params', else the site's name in CamelCase; checked against CARLA's rules."""
    from .carla_pkg import PackageError, check_names

    site_name = str((getattr(ctx, "site", None) or {}).get("name") or "Site")
    map_name = params.map_name or _camel(site_name)
    package = params.package or f"{map_name}Twin"
    try:
        check_names(package, map_name)
    except PackageError as exc:
        raise InputError(f"carla_package: {exc}") from None
    return map_name, package


def _map_spawn(text: str, xodr_name: str, map_name: str, frame, params: CarlaPackageParams):
    """(carla.Map of ``text``, spawn points in the package's frame); an InputError when there are none."""
    from .carla_frame import site_spawn
    from .carla_pkg import PackageError, lane_map, spawn_points

    try:
        lanes = lane_map(text, map_name)
        spawn = site_spawn(spawn_points(lanes, params.spawn_spacing_m, params.spawn_height_m, params.skip_junctions),
                           frame)
    except PackageError as exc:
        raise InputError(f"carla_package: {exc}") from None
    if not spawn:
        raise InputError(f"{xodr_name}: carla.Map found no driving lane outside junctions; "
                         f"check the OpenDRIVE (lanes of type 'driving')")
    return lanes, spawn


def _texture(in_twin_fbx: Path, cs) -> Path | None:
    """The texture beside the FBX (.png, .jpg, .jpeg), else the class set's."""
    fbx = Path(in_twin_fbx)
    return next((fbx.with_suffix(e) for e in (".png", ".jpg", ".jpeg") if fbx.with_suffix(e).exists()), None) \
        or cs.texture


def _write_package(out: Path, params: CarlaPackageParams, ctx: StepContext, **kw):
    """:func:`carla_pkg.write_package` with the params' options and Blender; its errors as the step's."""
    from .carla_pkg import PackageError, write_package
    from .fbx import FbxExportError, bpy_python

    try:
        return write_package(out, use_carla_materials=params.use_carla_materials, decals=params.decals,
                             python=bpy_python(), log_path=Path(ctx.workdir) / "bpy.log",
                             carla_version=params.carla_version, **kw)
    except PackageError as exc:
        raise InputError(f"carla_package: {exc}") from None
    except FbxExportError as exc:
        raise InputError(str(exc)) if "needs Blender" in str(exc) else exc


def _checked_summary(out: Path, package: str, expect_decals, expect_crosswalks: int | None = None,
                     ctx: StepContext | None = None) -> dict:
    """CARLA's import rules, read from its source (carla_contract): the package's summary, or a RuntimeError when
    a rule of the import breaks; the behaviour rules' violations (``BEHAVIOUR_RULES``) mark the step DEGRADED."""
    from .carla_contract import check_package
    from .contract_import import placement_summary

    rep = check_package(out, package, expect_decals=expect_decals, expect_crosswalks=expect_crosswalks)
    if rep.errors:
        raise RuntimeError("carla_package: the package breaks CARLA's import rules:\n  "
                           + "\n  ".join(str(v) for v in rep.errors))
    for v in rep.behaviour:
        if ctx is not None:
            ctx.degraded(f"in CARLA the twin would not behave like the street: {v}",
                         "the package is written; docs/export.md lists what each rule checks and how to fix it")
    return {**rep.summary(), "level_placement": placement_summary(out, package, rep)}


def _expected_crosswalks(path: Path | None) -> int | None:
    """The crosswalk count place_crosswalks wrote (crosswalks.json ``metrics.crosswalks``), None without it."""
    from twinkit.artefacts import read_crosswalks

    if path is None or not Path(path).is_file():
        return None
    return int(read_crosswalks(path).metrics["crosswalks"])


def _package_metrics(summ: dict, placed: dict, actors: list, out: Path) -> dict:
    """The metrics both kinds of package report: placed meshes, the contract's summary, the actors, the size."""
    return {"map_meshes": placed["map_meshes"], "props": placed["props"], "faces_by_tag": summ["faces_by_tag"],
            "wrong_terrain_share": summ["wrong_terrain_share"], "dropped_assets": summ["dropped_assets"],
            "walkable_faces": summ["walkable_faces"], "decals": summ["decals"], "actors": len(actors),
            "crosswalks": sum(summ.get("crosswalks", {}).values()),
            "level_placement": summ.get("level_placement"),
            "actor_blueprints": sorted({a["blueprint"] for a in actors if a["blueprint"]}),
            "package_bytes": _size(out)}


def export_carla_package(params: CarlaPackageParams, ctx: StepContext, *, in_twin_fbx: Path,
                         in_class_meshes_dir: Path, out_carla_import_dir: Path, out_spawn_points_json: Path,
                         in_aligned_xodr: Path | None = None, in_site_json: Path | None = None,
                         in_movables_dir: Path | None = None, in_crosswalks_json: Path | None = None) -> dict:
    """carla_import/Import/<Package>/: <Package>.json, <Map>.fbx (+ texture), <Map>.xodr, README; spawn points;
    the lifted movable objects as actors (actors.json, spawn_actors.py) and scanned props. ``crosswalks.json``
    (roads' place_crosswalks): how many crossings the package's navmesh must get."""
    from twinkit.artefacts import read_opendrive

    from .carla_actors import carla_actors, scanned_props, write_actor_files
    from .carla_frame import package_class_dir, package_frame, package_xodr, readme_frames, twin_points, write_frame_json
    from .carla_pkg import lane_map, xodr_georeference
    from .movables.actors import load_actors

    params = params or CarlaPackageParams()
    t0 = time.perf_counter()
    no_map_source = "none"
    if in_aligned_xodr is not None and _no_roads_map(Path(in_aligned_xodr)):
        no_map_source, in_aligned_xodr = "scan", None  # road_source=scan kept no road: said below
    if in_aligned_xodr is None:
        return _carla_props_only(params, ctx, in_twin_fbx=in_twin_fbx, in_class_meshes_dir=in_class_meshes_dir,
                                 out_carla_import_dir=out_carla_import_dir, out_spawn_points_json=out_spawn_points_json,
                                 in_site_json=in_site_json, in_movables_dir=in_movables_dir, t0=t0,
                                 source=no_map_source)
    xodr = Path(in_aligned_xodr)
    with ctx.substep("read"):
        text = read_opendrive(xodr)
        cs = _load_set(in_class_meshes_dir)
    # the package is written in CARLA's frame (true north at the base point), its geolocation measured where the
    # twin is: carla_frame.py
    with ctx.substep("frame"):
        frame = package_frame(getattr(ctx, "site", None), params.frame, params.frame_scale,
                              params.geolocation_radius_m, params.geolocation_tolerance_m, ctx.log,
                              points=twin_points(cs, text) if params.frame == "carla" else None)
        site_geo, text = xodr_georeference(text), package_xodr(text, frame, xodr.name)
        map_name, package = _package_names(params, ctx)
        lanes, spawn = _map_spawn(text, xodr.name, map_name, frame, params)
    with ctx.substep("meshes"):
        tex = _texture(in_twin_fbx, cs)
        georef = _georef(ctx, in_site_json)
        out = Path(out_carla_import_dir)
        work = Path(ctx.workdir) / "carla_frame_meshes"
        class_dir = package_class_dir(frame, cs, tex, work)
        mov_data, movables = load_actors(in_movables_dir)
        scanned = scanned_props(movables, map_name, frame, work / "scanned", tex.name if tex else None)
    with ctx.substep("write"):
        pkg, placed = _write_package(out, params, ctx, package=package, map_name=map_name, class_dir=class_dir,
                                     classes=cs.manifest["classes"], texture=tex, xodr_text=text, spawn=spawn,
                                     georef=georef, frames=lambda g: readme_frames(frame, g), scanned=scanned)
        shutil.rmtree(work, ignore_errors=True)
        write_frame_json(out / "carla_frame.json", frame, site_geo)
        actors = carla_actors(mov_data.get("actors", []), frame, map_name)
        if in_movables_dir is not None:
            write_actor_files(out, actors, map_name=map_name, package=package, source=mov_data)
        shutil.copyfile(out / "spawn_points.json", out_spawn_points_json)
    # the package must hold what `make import` needs, and its OpenDRIVE must parse
    with ctx.substep("check"):
        lane_map((pkg / f"{map_name}.xodr").read_text(), map_name)
        summ = _checked_summary(out, package, params.decals, _expected_crosswalks(in_crosswalks_json), ctx)
    pl = summ["level_placement"]
    ctx.log.info("carla_package: %.1f %% of the static faces end in the map level after make import and %s "
                 "(make import alone: %.1f %%)", 100 * pl["placed_share"], pl["script"],
                 100 * pl["placed_share_import_only"])
    m = _package_metrics(summ, placed, actors, out)
    return {"package": package, "map": map_name, "spawn_points": len(spawn),
            "topology_edges": len(lanes.topology()), **{k: v for k, v in m.items() if k != "package_bytes"},
            "xodr_georeference": xodr_georeference(text), "package_bytes": m["package_bytes"],
            "frame": frame.to_json() if frame is not None else "site",
            "seconds": round(time.perf_counter() - t0, 2)}


def _carla_props_only(params: CarlaPackageParams, ctx: StepContext, *, in_twin_fbx: Path, in_class_meshes_dir: Path,
                      out_carla_import_dir: Path, out_spawn_points_json: Path, in_site_json: Path | None,
                      in_movables_dir: Path | None, t0: float, source: str = "none") -> dict:
    """The package of a twin without a road network (``road_source=none``, or ``source`` 'scan': the scan kept no
    road): no map, every class a prop.

    CARLA's import needs an OpenDRIVE beside a map's FBX (Import.py copies it, builds the navmesh and
    the traffic manager's binary from it; a map entry without one fails), so a map is not written;
    the README and ``spawn_points.json`` say so, and so does the log."""
    from .carla_actors import carla_actors, scanned_props, write_actor_files
    from .carla_pkg import NO_MAP_WHY, no_map_note
    from .movables.actors import load_actors

    map_name, package = _package_names(params, ctx)
    cs = _load_set(in_class_meshes_dir)
    tex = _texture(in_twin_fbx, cs)
    georef = _georef(ctx, in_site_json)
    out = Path(out_carla_import_dir)
    work = Path(ctx.workdir) / "carla_frame_meshes"
    mov_data, movables = load_actors(in_movables_dir)
    scanned = scanned_props(movables, map_name, None, work / "scanned", tex.name if tex else None)
    geo_text = ", ".join(f"{k} {v}" for k, v in georef.items() if k in ("crs", "lat", "lon", "alt"))
    frames = (f"The props are in the site frame (x east, y north, z up, metres, origin at the base point "
              f"({geo_text})); spawned at a map's origin they lie where the twin's coordinates put them. Unreal "
              f"mirrors y on import.")
    pkg, placed = _write_package(out, params, ctx, package=package, map_name=map_name, class_dir=Path(cs.folder),
                                 classes=cs.manifest["classes"], texture=tex, xodr_text=None, spawn=[],
                                 georef=georef, frames=lambda g: frames, scanned=scanned, no_map_source=source)
    shutil.rmtree(work, ignore_errors=True)
    actors = carla_actors(mov_data.get("actors", []), None, map_name)
    if in_movables_dir is not None:
        write_actor_files(out, actors, map_name=map_name, package=package, source=mov_data, has_map=False)
    shutil.copyfile(out / "spawn_points.json", out_spawn_points_json)
    summ = _checked_summary(out, package, None, ctx=ctx)
    ctx.note("no road network")  # the run's status says it beside "ok" (docs/engine.md "Quality gates")
    ctx.log.warning("%s: the CARLA package %s has no map and no OpenDRIVE; its %d class meshes are props (no spawn "
                    "points, no drivable lanes; %s/README.md)", NO_MAP_WHY.get(source, NO_MAP_WHY["none"]), package,
                    len(placed["props"]), package)
    return {"package": package, "map": None, "opendrive": False, "note": no_map_note(source), "spawn_points": 0,
            "topology_edges": 0, **_package_metrics(summ, {**placed, "map_meshes": []}, actors, out), "frame": "site",
            "seconds": round(time.perf_counter() - t0, 2)}


# ----------------------------------------------------------------------------- registration

@hookimpl
def twinkit_register_steps(register):
    register("lift_movables", lift_movables_step, params=LiftParams,
             description="vehicles, riders, pedestrians out of the static mesh as actors; ground closed beneath")
    register("split_classes", split_classes, params=SplitParams,
             description="one sub-mesh per CityScapes class, CARLA names, palette colours")
    from .ground_check import DropTestParams, drop_test_step

    register("drop_test", drop_test_step, params=DropTestParams,
             description="vertical rays over every driving, parking and sidewalk lane: does the static mesh hold them up")


@hookimpl
def twinkit_register_exporters(register):
    register("fbx", export_fbx, params=FbxParams, description="FBX via Blender (bpy): CARLA names, metres, Z up")
    register("usd", export_usd, params=UsdParams, description="USD via usd-core: prims per class, semantics, geo")
    register("gltf", export_gltf, params=GltfParams, description="GLB for browsers: photo texture; segmentation as attribute and variant")
    from .preflight import carla_package_preflight

    register("carla_package", export_carla_package, params=CarlaPackageParams, preflight=carla_package_preflight,
             description="CARLA 0.9.16 import package with OpenDRIVE and spawn points")

"""The artefact catalogue: every file that one plugin's step writes and another plugin's step reads.

Each entry (:data:`CATALOGUE`, keyed by file name) has a format, a schema (a dataclass with a ``VERSION``:
:mod:`twinkit.artefacts.schemas` for JSON, :mod:`twinkit.artefacts.files` for the rest), ONE reader and ONE
writer. Plugins read and write these files only through them (``tests/test_artefacts.py`` fails on a hand
read or write); the engine checks each catalogued output after its step ran (:func:`check_output`), and a
file that breaks its schema fails the step. The table is in docs/engine.md, "Artefacts between plugins".

Frames and units: every geometry is in the site frame (metres; x east, y north, z up).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from . import files as F
from .schemas import (ArtefactError, CamerasSite, Crosswalks, DemoCameras, GroundControl, JsonSchema, PointsMeta,
                      RoadsTruth, SiteInfo)

if TYPE_CHECKING:
    import numpy as np

__all__ = [
    "Artefact", "ArtefactError", "CATALOGUE", "check_output", "lookup",
    "read_points_meta", "write_points_meta", "read_cameras_site", "write_cameras_site",
    "read_demo_cameras", "write_demo_cameras", "read_gcp", "write_gcp", "read_roads_truth", "write_roads_truth",
    "read_crosswalks", "write_crosswalks",
    "read_site_info", "write_site_info", "read_labels", "write_labels", "read_class_votes", "write_class_votes", "read_points", "write_points",
    "read_textured_mesh", "write_textured_mesh", "read_clean_mesh", "write_clean_mesh", "read_gt_mesh",
    "write_gt_mesh", "read_textured_obj", "write_textured_obj", "read_opendrive", "write_opendrive", "read_osm",
    "write_osm", "list_photos",
    "write_photo", "PointsMeta", "CamerasSite", "DemoCameras", "GroundControl", "RoadsTruth", "SiteInfo",
    "Crosswalks",
]


# ----------------------------------------------------------------------------- JSON

def _read_json_doc(schema: type[JsonSchema], path: str | Path):
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except OSError as exc:
        raise ArtefactError(f"{path}: cannot be read ({exc}); {schema.FIX}") from None
    except ValueError as exc:
        raise ArtefactError(f"{path}: not valid JSON ({exc}); {schema.FIX}") from None
    return schema.from_json(data, path)


def _write_json_doc(schema: type[JsonSchema], path: str | Path, doc: JsonSchema | dict) -> None:
    from twinkit.jsonio import json_default, write_json

    data: Any
    if isinstance(doc, schema):
        data = doc.to_json()
    else:  # validated as it will read back; written as given (the same bytes as before the catalogue)
        schema.from_json(json.loads(json.dumps(doc, default=json_default)), path)
        data = doc
    write_json(path, data, indent=schema.INDENT)




def read_points_meta(path: str | Path, points: str | Path | np.ndarray | None = None) -> PointsMeta:
    """``points_meta.json`` -> :class:`PointsMeta`.

    A file without the ``density`` block (schema version 1, the photo branch before twinkit 43) gets it
    measured from ``points`` ((n, 3) float array, metres, or the path of ``points.ply``) when given, with
    ``density["filled_from_points"] = True``; without ``points`` it is an :class:`ArtefactError` that says so.
    A block without ``ground_two_way_share`` (written before 30 Nov 2026) gets that one measured from ``points``
    when given (else it stays absent). Other missing fields are always an error."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ArtefactError(f"{path}: not a readable JSON file ({exc}); {PointsMeta.FIX}") from None
    if isinstance(data, dict) and "density" not in data:
        if points is None:
            raise ArtefactError(f"{path}: no 'density' block: written by an older twinkit (points_meta.json schema "
                                f"v1), so the point spacing is unknown; {PointsMeta.FIX}")
        data = dict(data, density=dict(_measure(points), filled_from_points=True))
    elif (isinstance(data, dict) and isinstance(data.get("density"), dict) and points is not None
          and "ground_two_way_share" not in data["density"]):
        data = dict(data, density=dict(data["density"], ground_two_way_share=_measure(points)["ground_two_way_share"]))
    return PointsMeta.from_json(data, path)


def _measure(points: str | Path | np.ndarray) -> dict:
    import numpy as np

    from twinkit.surface import density

    xyz = read_points(points).vertices if isinstance(points, (str, Path)) else np.asarray(points)
    return density.measure(np.asarray(xyz, np.float64))


def write_points_meta(path: str | Path, meta: PointsMeta | dict, points: np.ndarray | None = None) -> None:
    """Write ``points_meta.json``; a ``meta`` without ``density`` gets it measured from ``points`` ((n, 3),
    metres; :func:`twinkit.surface.density.measure`). Raises :class:`ArtefactError` when it stays incomplete."""
    if isinstance(meta, dict) and "density" not in meta and points is not None:
        meta = dict(meta, density=_measure(points))
    _write_json_doc(PointsMeta, path, meta)


def read_cameras_site(path: str | Path) -> CamerasSite:
    """``cameras_site.json`` -> :class:`CamerasSite` (every camera has image, K, R_world_from_camera, center,
    width, height)."""
    return _read_json_doc(CamerasSite, path)


def write_cameras_site(path: str | Path, doc: CamerasSite | dict) -> None:
    """Write ``cameras_site.json`` (validated first)."""
    _write_json_doc(CamerasSite, path, doc)


def read_demo_cameras(path: str | Path) -> DemoCameras:
    """``cameras.json`` (the demo site's true cameras) -> :class:`DemoCameras`."""
    return _read_json_doc(DemoCameras, path)


def write_demo_cameras(path: str | Path, doc: DemoCameras | dict) -> None:
    """Write ``cameras.json`` (validated first; indent 1 as the demo site always wrote it)."""
    _write_json_doc(DemoCameras, path, doc)


def read_gcp(path: str | Path) -> GroundControl:
    """``gcp.json`` -> :class:`GroundControl` (a ``points`` list; twinkit's or OpenSfM's layout)."""
    return _read_json_doc(GroundControl, path)


def write_gcp(path: str | Path, doc: GroundControl | dict) -> None:
    """Write ``gcp.json`` (validated first)."""
    _write_json_doc(GroundControl, path, doc)


def read_roads_truth(path: str | Path) -> RoadsTruth:
    """``roads_truth.json`` -> :class:`RoadsTruth`."""
    return _read_json_doc(RoadsTruth, path)


def write_roads_truth(path: str | Path, doc: RoadsTruth | dict) -> None:
    """Write ``roads_truth.json`` (validated first)."""
    _write_json_doc(RoadsTruth, path, doc)


def read_crosswalks(path: str | Path) -> Crosswalks:
    """``crosswalks.json`` -> :class:`Crosswalks`."""
    return _read_json_doc(Crosswalks, path)


def write_crosswalks(path: str | Path, doc: Crosswalks | dict) -> None:
    """Write ``crosswalks.json`` (validated first)."""
    _write_json_doc(Crosswalks, path, doc)


def read_site_info(path: str | Path) -> SiteInfo:
    """``site.json`` -> :class:`SiteInfo`."""
    return _read_json_doc(SiteInfo, path)


def write_site_info(path: str | Path, doc: SiteInfo | dict) -> None:
    """Write ``site.json`` (validated first)."""
    _write_json_doc(SiteInfo, path, doc)


# ----------------------------------------------------------------------------- arrays, meshes, text

def read_labels(path: str | Path, n_vertices: int | None = None, mesh_name: str = "the mesh") -> np.ndarray:
    """``labels.npy`` / ``gt_labels.npy`` -> (n,) integer trainIds (uint8 as written; 255 = unlabelled).

    ``n_vertices``: when given, a count that differs is an :class:`ArtefactError` naming ``mesh_name``."""
    import numpy as np

    path = Path(path)
    fix = F.LabelsNpy.FIX if "gt_" not in path.name else "re-run transfer_gt_labels"
    try:
        arr = np.load(path)
    except Exception as exc:  # noqa: BLE001
        raise ArtefactError(f"{path}: not a readable .npy label array ({exc}); {fix}") from None
    if arr.ndim != 1 or arr.dtype.kind not in "iu":
        raise ArtefactError(f"{path}: labels must be a 1-D integer array (one trainId per vertex), found "
                            f"{arr.dtype} {arr.shape}; {fix}")
    if n_vertices is not None and len(arr) != n_vertices:
        raise ArtefactError(f"{path}: {len(arr)} labels for the {n_vertices} vertices of {mesh_name}; give the "
                            f"per-vertex labels of this mesh ({fix})")
    return arr


def write_labels(path: str | Path, labels: np.ndarray) -> None:
    """Write (n,) trainIds as a 1-D ``uint8`` ``.npy``; raises :class:`ArtefactError` on values outside 0-255."""
    import numpy as np

    arr = np.asarray(labels)
    if arr.ndim != 1 or arr.dtype.kind not in "iub":
        raise ArtefactError(f"{path}: labels must be a 1-D integer array, got {arr.dtype} {arr.shape}")
    if arr.dtype != np.uint8:
        if len(arr) and (int(arr.min()) < 0 or int(arr.max()) > 255):
            raise ArtefactError(f"{path}: labels must be trainIds 0-255 (255 = unlabelled)")
        arr = arr.astype(np.uint8)
    np.save(path, arr)


def read_class_votes(path: str | Path, n_vertices: int | None = None, mesh_name: str = "the mesh") -> np.ndarray:
    """``geometry_votes.npy`` -> (n, 19) float32 class probabilities per vertex (zero row: no vote); checks
    the shape and, given ``n_vertices``, that it matches the mesh."""
    import numpy as np

    path = Path(path)
    F.ClassVotesNpy.check(path)
    arr = np.load(path)
    if n_vertices is not None and len(arr) != n_vertices:
        raise ArtefactError(f"{path}: {len(arr)} vote rows for {n_vertices} vertices of {mesh_name}; "
                            f"{F.ClassVotesNpy.FIX}")
    return arr


def write_class_votes(path: str | Path, votes: np.ndarray) -> None:
    """Write ``geometry_votes.npy`` from (n, 19) class probabilities (cast to float32)."""
    import numpy as np

    arr = np.asarray(votes, np.float32)
    if arr.ndim != 2 or arr.shape[1] != 19:
        raise ArtefactError(f"{path}: class votes must be (n_vertices, 19), got {arr.shape}")
    np.save(Path(path), arr)


def read_points(path: str | Path):
    """``points.ply`` -> :class:`twinkit.mesh.Mesh` (vertices (n, 3) float64, ``attrs`` normals/colors/...)."""
    from twinkit.mesh import read_ply

    try:
        return read_ply(Path(path))
    except Exception as exc:  # noqa: BLE001
        raise ArtefactError(f"{path}: not a readable PLY ({exc}); {F.PointsPly.FIX}") from None


def write_points(path: str | Path, cloud, **kw) -> None:
    """Write ``points.ply`` from a :class:`twinkit.mesh.Mesh` without faces (``kw`` to ``write_ply``)."""
    from twinkit.mesh import write_ply

    write_ply(path, cloud, **kw)


def read_textured_mesh(path: str | Path):
    """``textured_mesh.ply`` -> :class:`twinkit.mesh.Mesh` with faces and texture (``read_mesh``'s checks)."""
    from twinkit.mesh import read_mesh

    return _with_faces(read_mesh(Path(path)), path, F.TexturedMeshPly.FIX)


def _with_faces(mesh, path, fix: str):
    if mesh.n_faces == 0:
        raise ArtefactError(f"{path}: the mesh has no faces; {fix}")
    return mesh


def write_textured_mesh(path: str | Path, mesh, **kw) -> None:
    """Write ``textured_mesh.ply`` from a :class:`twinkit.mesh.Mesh` with faces."""
    from twinkit.mesh import write_ply

    write_ply(path, mesh, **kw)


def read_clean_mesh(path: str | Path):
    """``clean_mesh.ply`` -> :class:`twinkit.mesh.Mesh` (``read_ply``: vertices (n, 3) float64, faces (m, 3))."""
    from twinkit.mesh import read_ply

    try:
        mesh = read_ply(Path(path))
    except Exception as exc:  # noqa: BLE001
        raise ArtefactError(f"{path}: not a readable PLY mesh ({exc}); {F.CleanMeshPly.FIX}") from None
    return _with_faces(mesh, path, F.CleanMeshPly.FIX)


def write_clean_mesh(path: str | Path, mesh, **kw) -> None:
    """Write ``clean_mesh.ply`` from a :class:`twinkit.mesh.Mesh` with faces."""
    from twinkit.mesh import write_ply

    write_ply(path, mesh, **kw)


def read_gt_mesh(path: str | Path):
    """``gt_mesh.ply`` -> :class:`twinkit.mesh.Mesh` (``read_mesh``'s checks). The demo site writes ``label``
    on faces and vertices; a site's own ground truth may name it otherwise (``class``, ...), which each
    reader's label lookup handles."""
    from twinkit.mesh import read_mesh

    return _with_faces(read_mesh(Path(path)), path, F.GtMeshPly.FIX)


def write_gt_mesh(path: str | Path, mesh, **kw) -> None:
    """Write ``gt_mesh.ply`` from a :class:`twinkit.mesh.Mesh` carrying ``label`` (faces or vertices)."""
    from twinkit.mesh import write_ply

    if "label" not in mesh.attrs and "label" not in mesh.face_attrs:
        raise ArtefactError(f"{path}: a ground-truth mesh needs a 'label' on faces or vertices")
    write_ply(path, mesh, **kw)


def read_textured_obj(path: str | Path):
    """``textured_mesh.obj`` (+ its MTL and texture) -> :class:`twinkit.mesh.Mesh` (``read_obj``)."""
    from twinkit.mesh import read_obj

    try:
        return read_obj(Path(path))
    except Exception as exc:  # noqa: BLE001
        raise ArtefactError(f"{path}: not a readable OBJ ({exc}); {F.TexturedObj.FIX}") from None


def write_textured_obj(path: str | Path, vertices, faces, uv, texture_name: str, **kw) -> None:
    """Write ``textured_mesh.obj`` + MTL (:func:`twinkit.mesh.write_obj`'s arguments)."""
    from twinkit.mesh import write_obj

    write_obj(Path(path), vertices, faces, uv, texture_name, **kw)


def _read_text(path: str | Path, fix: str) -> str:
    try:
        return Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ArtefactError(f"{path}: cannot be read as UTF-8 text ({exc}); {fix}") from None


def read_opendrive(path: str | Path) -> str:
    """``aligned.xodr`` -> its OpenDRIVE XML text."""
    return _read_text(path, F.OpenDrive.FIX)


def write_opendrive(path: str | Path, text: str) -> None:
    """Write ``aligned.xodr`` (UTF-8 OpenDRIVE XML text)."""
    Path(path).write_text(text, encoding="utf-8")


def read_osm(path: str | Path) -> Path:
    """``roads.osm`` -> its path, checked to be OpenStreetMap XML (root ``<osm>``), for an OSM library
    (osmium, or the roads plugin's reader) to parse."""
    F.OsmXml.check(Path(path))
    return Path(path)


def write_osm(path: str | Path, text: str) -> None:
    """Write ``roads.osm`` (UTF-8 OpenStreetMap XML text)."""
    Path(path).write_text(text, encoding="utf-8")


def list_photos(folder: str | Path) -> list[Path]:
    """The photos of a ``photos/`` folder (top level, JPEG/PNG/TIFF), sorted by name."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ArtefactError(f"{folder}: not a folder of photos; {F.PhotosDir.FIX}")
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in F.PHOTO_EXTS)


def write_no_photos(folder: str | Path, why: str) -> None:
    """A ``photos/`` folder left empty on purpose, saying ``why`` in its ``NO_PHOTOS.txt``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / F.PhotosDir.NONE_FILE).write_text(why.rstrip() + "\n")


def why_no_photos(folder: str | Path) -> str | None:
    """Why a ``photos/`` folder was left empty on purpose (its ``NO_PHOTOS.txt``), None when it does not say."""
    why = Path(folder) / F.PhotosDir.NONE_FILE
    return why.read_text().strip() if why.is_file() else None


def write_photo(folder: str | Path, name: str, data: bytes) -> Path:
    """Put one encoded photo (``data``: the JPEG/PNG bytes) into a ``photos/`` folder; returns its path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).write_bytes(data)
    return folder / name


# ----------------------------------------------------------------------------- the catalogue

@dataclass(frozen=True)
class Artefact:
    """One catalogued file: ``name`` (file or folder name), ``format``, ``schema`` (with ``VERSION``), the
    steps that write and read it (``plugin:step``) and its one reader and writer."""

    name: str
    format: str
    schema: Any  # a JsonSchema subclass or a schema class of twinkit.artefacts.files
    writers: tuple[str, ...]
    readers: tuple[str, ...]
    read: Callable[..., Any]
    write: Callable[..., Any]

    @property
    def version(self) -> int:
        return int(self.schema.VERSION)

    @property
    def ports(self) -> tuple[str, str]:
        """The step parameters that read and write it: (``in_<stem>_<ext>``, ``out_<stem>_<ext>``)."""
        stem, _, ext = self.name.partition(".")
        port = f"{stem}_{ext or 'dir'}"
        return f"in_{port}", f"out_{port}"

    def check(self, path: str | Path) -> None:
        """Raise :class:`ArtefactError` when the file at ``path`` breaks the schema (cheap: headers only for
        PLY and NumPy files, a full parse for JSON)."""
        if issubclass(self.schema, JsonSchema):
            self.read(path)
        else:
            self.schema.check(Path(path))


def _entry(name, fmt, schema, read, write, *, writers: str, readers: str) -> tuple[str, Artefact]:
    return name, Artefact(name, fmt, schema, tuple(writers.split()), tuple(readers.split()), read, write)


#: file name -> :class:`Artefact`, for every file that crosses a plugin boundary.
CATALOGUE: dict[str, Artefact] = dict([
    _entry("points.ply", "PLY cloud", F.PointsPly, read_points, write_points,
           writers="photo:dense pointcloud:read_cloud",
           readers="export:drop_test pointcloud:bake_texture pointcloud:clean_mesh "
                   "pointcloud:evaluate_reconstruction pointcloud:reconstructor/poisson roads:road_source/scan "
                   "segmentation:backproject segmentation:classify_geometry segmentation:sample_views tiles:merge_tiles "
                   "tiles:plan_tiles"),
    _entry("points_meta.json", "JSON", PointsMeta, read_points_meta, write_points_meta,
           writers="photo:dense pointcloud:read_cloud",
           readers="roads:road_evidence roads:road_source/scan segmentation:backproject segmentation:classify_geometry"),
    _entry("textured_mesh.ply", "PLY mesh", F.TexturedMeshPly, read_textured_mesh, write_textured_mesh,
           writers="photo:photo_texture pointcloud:bake_texture",
           readers="photo:photo_texture pointcloud:evaluate_reconstruction roads:align_roads roads:apply_alignment "
                   "roads:parking_lanes roads:place_crosswalks roads:place_signals roads:road_evidence roads:road_source/scan segmentation:backproject "
                   "segmentation:classify_geometry segmentation:import_labels segmentation:photo_views segmentation:render_views "
                   "segmentation:sample_views segmentation:segmenter/felzenszwalb segmentation:segmenter/vertices "
                   "segmentation:transfer_gt_labels tiles:evaluate_seam_labels"),
    _entry("clean_mesh.ply", "PLY mesh", F.CleanMeshPly, read_clean_mesh, write_clean_mesh,
           writers="pointcloud:clean_mesh tiles:merge_tiles",
           readers="pointcloud:bake_texture pointcloud:simplify"),
    _entry("textured_mesh.obj", "OBJ + MTL", F.TexturedObj, read_textured_obj, write_textured_obj,
           writers="export:lift_movables photo:photo_texture pointcloud:bake_texture",
           readers="export:drop_test export:lift_movables export:split_classes"),
    _entry("labels.npy", "NumPy uint8 (n,)", F.LabelsNpy, read_labels, write_labels,
           writers="export:lift_movables roads:road_evidence segmentation:backproject "
                   "segmentation:import_labels segmentation:transfer_gt_labels",
           readers="export:lift_movables export:split_classes roads:align_roads roads:parking_lanes "
                   "roads:place_crosswalks roads:place_signals roads:road_evidence roads:road_source/scan segmentation:evaluate_segmentation "
                   "segmentation:import_labels tiles:evaluate_seam_labels"),
    _entry("gt_labels.npy", "NumPy uint8 (n,)", F.LabelsNpy, read_labels, write_labels,
           writers="segmentation:transfer_gt_labels",
           readers="roads:road_evidence roads:road_source/scan segmentation:evaluate_segmentation "
                   "segmentation:predict_views tiles:evaluate_seam_labels"),
    _entry("geometry_votes.npy", "NumPy float32 (n, 19)", F.ClassVotesNpy, read_class_votes, write_class_votes,
           writers="segmentation:classify_geometry",
           readers="export:lift_movables segmentation:backproject"),
    _entry("gt_mesh.ply", "PLY mesh with label", F.GtMeshPly, read_gt_mesh, write_gt_mesh,
           writers="demo-site:site_generator/demo_intersection",
           readers="pointcloud:evaluate_reconstruction segmentation:transfer_gt_labels"),
    _entry("aligned.xodr", "OpenDRIVE XML", F.OpenDrive, read_opendrive, write_opendrive,
           writers="roads:apply_alignment roads:parking_lanes roads:place_crosswalks roads:place_signals",
           readers="export:drop_test export:exporter/carla_package roads:parking_lanes roads:place_crosswalks "
                   "roads:place_signals "
                   "roads:road_evidence"),
    _entry("roads.osm", "OSM XML", F.OsmXml, read_osm, write_osm,
           writers="demo-site:site_generator/demo_intersection",
           readers="roads:road_source/file segmentation:photo_views segmentation:sample_views"),
    _entry("roads_truth.json", "JSON", RoadsTruth, read_roads_truth, write_roads_truth,
           writers="demo-site:site_generator/demo_intersection",
           readers="roads:apply_alignment roads:road_source/scan"),
    _entry("crosswalks.json", "JSON", Crosswalks, read_crosswalks, write_crosswalks,
           writers="roads:place_crosswalks",
           readers="export:exporter/carla_package"),
    _entry("site.json", "JSON", SiteInfo, read_site_info, write_site_info,
           writers="demo-site:site_generator/demo_intersection",
           readers="export:exporter/carla_package export:exporter/fbx export:exporter/gltf export:exporter/usd"),
    _entry("cameras.json", "JSON", DemoCameras, read_demo_cameras, write_demo_cameras,
           writers="demo-site:site_generator/demo_intersection",
           readers="photo:georeference photo:sfm"),
    _entry("gcp.json", "JSON", GroundControl, read_gcp, write_gcp,
           writers="demo-site:site_generator/demo_intersection",
           readers="photo:georeference"),
    _entry("cameras_site.json", "JSON", CamerasSite, read_cameras_site, write_cameras_site,
           writers="photo:georeference",
           readers="photo:dense photo:photo_texture photo:roi segmentation:photo_views"),
    _entry("photos", "folder of JPEG/PNG", F.PhotosDir, list_photos, write_photo,
           writers="demo-site:site_generator/demo_intersection",
           readers="photo:dense photo:georeference photo:photo_texture photo:sfm segmentation:photo_views"),
])


def lookup(filename: str) -> Artefact | None:
    """The catalogue entry of a file or folder name (``points_meta.json``, ``photos``), or None."""
    return CATALOGUE.get(filename)


def check_output(path: str | Path, step: str = "") -> None:
    """The engine's check of a step's output: raise :class:`ArtefactError` when ``path`` is a catalogued
    artefact that breaks its schema (nothing happens for other files)."""
    art = lookup(Path(path).name)
    if art is not None:
        art.check(path)

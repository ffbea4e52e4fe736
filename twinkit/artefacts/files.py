"""The schemas of the non-JSON artefacts between plugins (PLY, OBJ, NumPy, XML, photo folders) and their
cheap checks: a check reads a PLY's or ``.npy``'s header only, never the body, so the engine can run it
after every step.

Each schema is a frozen dataclass with a ``VERSION``, the file it describes and what it requires.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from .schemas import ArtefactError


def ply_header(path: Path) -> dict[str, tuple[int, list[str]]]:
    """A PLY header without its body: element name -> (count, property names).

    Raises ValueError when the file is not a PLY."""
    elements: dict[str, tuple[int, list[str]]] = {}
    current = None
    with open(path, "rb") as fh:
        if fh.readline().strip() != b"ply":
            raise ValueError("not a PLY file (no 'ply' magic)")
        for _ in range(10_000):
            line = fh.readline()
            if not line:
                raise ValueError("truncated PLY header (no end_header)")
            t = line.decode("ascii", "replace").split()
            if not t:
                continue
            if t[0] == "end_header":
                return elements
            if t[0] == "element" and len(t) == 3:
                current = t[1]
                elements[current] = (int(t[2]), [])
            elif t[0] == "property" and current is not None:
                elements[current][1].append(t[-1])
    raise ValueError("PLY header too long")


@dataclass(frozen=True)
class PlySchema:
    """A binary PLY (:mod:`twinkit.mesh.ply`): vertices ``x y z`` (float32, metres, site frame), optional
    ``nx ny nz``, ``red green blue`` (uint8) and scalar properties; ``faces`` (triangles) when
    ``FACES``; a per-vertex or per-face ``label`` (uint8 trainIds) when ``LABEL``."""

    VERSION: ClassVar[int] = 1
    FILE: ClassVar[str] = ""
    FIX: ClassVar[str] = "re-run the step that wrote it"
    FACES: ClassVar[bool] = False
    LABEL: ClassVar[bool] = False

    @classmethod
    def check(cls, path: Path) -> None:
        """Raise :class:`ArtefactError` when the header does not declare what the schema requires."""
        try:
            head = ply_header(path)
        except (OSError, ValueError) as exc:
            raise ArtefactError(f"{path}: not a readable PLY ({exc}); {cls.FIX}") from None
        n, props = head.get("vertex", (0, []))
        if not {"x", "y", "z"} <= set(props):
            raise ArtefactError(f"{path}: the vertex element lacks x, y, z ({cls.FILE} schema v{cls.VERSION}); "
                                f"{cls.FIX}")
        if cls.FACES and "face" not in head:
            raise ArtefactError(f"{path}: a mesh is expected but the PLY has no faces ({cls.FILE} schema "
                                f"v{cls.VERSION}); {cls.FIX}")
        if cls.LABEL and "label" not in props and "label" not in head.get("face", (0, []))[1]:
            raise ArtefactError(f"{path}: no 'label' property on faces or vertices ({cls.FILE} schema "
                                f"v{cls.VERSION}); {cls.FIX}")


class PointsPly(PlySchema):
    """``points.ply``: the site-frame cloud (no faces)."""

    FILE = "points.ply"
    FIX = "re-run the step that wrote it (read_cloud, or dense on the photo branch)"


class TexturedMeshPly(PlySchema):
    """``textured_mesh.ply``: the textured triangle mesh (per-face ``texcoord``, ``comment TextureFile``)."""

    FILE = "textured_mesh.ply"
    FIX = "re-run the texture step (bake_texture or photo_texture)"
    FACES = True


class CleanMeshPly(PlySchema):
    """``clean_mesh.ply``: the cleaned triangle mesh in the site frame (the point-cloud branch's clean_mesh,
    or the tiled branch's merge_tiles), before simplification and texturing."""

    FILE = "clean_mesh.ply"
    FIX = "re-run the step that wrote it (clean_mesh, or merge_tiles on the tiled branch)"
    FACES = True


class GtMeshPly(PlySchema):
    """``gt_mesh.ply``: a ground-truth mesh with a ``label`` (trainId) on faces or vertices."""

    FILE = "gt_mesh.ply"
    FIX = "give a mesh with a uchar 'label' per face or vertex (re-run the site step on the demo site)"
    FACES = True
    LABEL = True


@dataclass(frozen=True)
class LabelsNpy:
    """``labels.npy`` / ``gt_labels.npy``: one CityScapes trainId per vertex of ``textured_mesh``,
    a 1-D ``uint8`` array (255 = unlabelled)."""

    VERSION: ClassVar[int] = 1
    FILE: ClassVar[str] = "labels.npy"
    FIX: ClassVar[str] = "re-run the segmentation"
    DTYPE: ClassVar[str] = "uint8"

    @classmethod
    def check(cls, path: Path) -> None:
        import numpy as np

        try:
            arr = np.load(path, mmap_mode="r")
        except Exception as exc:  # noqa: BLE001
            raise ArtefactError(f"{path}: not a readable .npy label array ({exc}); {cls.FIX}") from None
        if arr.ndim != 1 or arr.dtype != cls.DTYPE:
            raise ArtefactError(f"{path}: labels must be a 1-D uint8 array (one trainId per vertex), found "
                                f"{arr.dtype} {arr.shape} ({cls.FILE} schema v{cls.VERSION}); {cls.FIX}")


@dataclass(frozen=True)
class ClassVotesNpy:
    """``geometry_votes.npy``: per vertex of ``textured_mesh`` one probability per CityScapes trainId,
    a 2-D ``float32`` array (n_vertices, 19); an all-zero row: no vote for that vertex."""

    VERSION: ClassVar[int] = 1
    FILE: ClassVar[str] = "geometry_votes.npy"
    FIX: ClassVar[str] = "re-run classify_geometry"
    DTYPE: ClassVar[str] = "float32"

    @classmethod
    def check(cls, path: Path) -> None:
        import numpy as np

        try:
            arr = np.load(path, mmap_mode="r")
        except Exception as exc:  # noqa: BLE001
            raise ArtefactError(f"{path}: not a readable .npy vote array ({exc}); {cls.FIX}") from None
        if arr.ndim != 2 or arr.shape[1] != 19 or arr.dtype != cls.DTYPE:
            raise ArtefactError(f"{path}: class votes must be a float32 (n_vertices, 19) array, found "
                                f"{arr.dtype} {arr.shape} ({cls.FILE} schema v{cls.VERSION}); {cls.FIX}")


@dataclass(frozen=True)
class XmlSchema:
    """A UTF-8 XML text whose root element is ``ROOT``."""

    VERSION: ClassVar[int] = 1
    FILE: ClassVar[str] = ""
    ROOT: ClassVar[str] = ""
    FIX: ClassVar[str] = "re-run the step that wrote it"

    @classmethod
    def check(cls, path: Path) -> None:
        import xml.etree.ElementTree as ET

        try:
            with open(path, "rb") as fh:  # the root element only: the first event
                root = next(ET.iterparse(fh, events=("start",)))[1]
        except (OSError, ET.ParseError, StopIteration) as exc:
            raise ArtefactError(f"{path}: not a readable XML file ({exc}); {cls.FIX}") from None
        if root.tag != cls.ROOT:
            raise ArtefactError(f"{path}: the root element is <{root.tag}>, not <{cls.ROOT}> ({cls.FILE} schema "
                                f"v{cls.VERSION}); {cls.FIX}")


class OpenDrive(XmlSchema):
    """``aligned.xodr``: the OpenDRIVE map in the site frame (root ``<OpenDRIVE>``; road_source=scan's map of
    a scan without roads carries userData ``twinkit_roads=none``)."""

    FILE = "aligned.xodr"
    ROOT = "OpenDRIVE"
    FIX = "re-run apply_alignment (or the scan road source)"


class OsmXml(XmlSchema):
    """``roads.osm``: OpenStreetMap XML (root ``<osm>``) with the site's roads."""

    FILE = "roads.osm"
    ROOT = "osm"
    FIX = "give an OpenStreetMap .osm XML file (re-run the site step on the demo site)"


PHOTO_EXTS = (".jpg", ".jpeg", ".png", ".tif", ".tiff")


@dataclass(frozen=True)
class PhotosDir:
    """``photos/``: a folder of photos (JPEG, PNG or TIFF) at its top level; the demo site adds
    ``labels/`` (trainId PNGs of the same names) beside them. A folder left empty on purpose (a generated
    site whose recipe reads no photo) says why in ``NO_PHOTOS.txt``."""

    VERSION: ClassVar[int] = 1
    FILE: ClassVar[str] = "photos"
    FIX: ClassVar[str] = "put the photos (JPEG/PNG) in the folder"
    NONE_FILE: ClassVar[str] = "NO_PHOTOS.txt"

    @classmethod
    def check(cls, path: Path) -> None:
        if not Path(path).is_dir():
            raise ArtefactError(f"{path}: not a folder ({cls.FILE} schema v{cls.VERSION}); {cls.FIX}")
        if (Path(path) / cls.NONE_FILE).is_file():
            return
        if not any(p.suffix.lower() in PHOTO_EXTS for p in Path(path).iterdir()):
            raise ArtefactError(f"{path}: holds no photo ({', '.join(PHOTO_EXTS)}); {cls.FIX}")


@dataclass(frozen=True)
class TexturedObj:
    """``textured_mesh.obj``: the textured mesh as OBJ (``v``/``vt``/``f``), its ``.mtl`` beside it naming
    the texture (``map_Kd``)."""

    VERSION: ClassVar[int] = 1
    FILE: ClassVar[str] = "textured_mesh.obj"
    FIX: ClassVar[str] = "re-run the texture step"

    @classmethod
    def check(cls, path: Path) -> None:
        try:
            with open(path, "rb") as fh:
                head = fh.read(1 << 16)
        except OSError as exc:
            raise ArtefactError(f"{path}: not readable ({exc}); {cls.FIX}") from None
        if head and b"\nv " not in b"\n" + head:
            raise ArtefactError(f"{path}: no vertex ('v ') line at its start: not an OBJ mesh ({cls.FILE} schema "
                                f"v{cls.VERSION}); {cls.FIX}")

"""The per-class sub-meshes of the export and their PLY files (through the one PLY path, twinkit.mesh).

Frames and units: positions are in the site frame (metres, x east, y north, z up, origin at the
site base point). UVs follow the OBJ convention (origin bottom left, v up).

A class PLY is binary little-endian: vertex ``double x y z``, ``float nx ny nz``, ``uchar red green
blue`` (CityScapes palette), ``uchar class_id`` (each vertex's own label), ``int source_index``;
face ``list uchar int vertex_indices`` and ``list uchar float texcoord`` (6 per face); comments
``twinkit-export class <id> <name>`` and ``TextureFile <name>``. MeshLab and CloudCompare read it.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from twinkit.mesh import Mesh, read_ply, write_ply


@dataclass
class ClassPart:
    """One class's part of the export: its identity and its sub-mesh.

    class_id: the part's class (trainId); name: its CARLA-style name (e.g. ``Road_Road``)
    mesh: the sub-mesh, site frame, metres: ``vertices`` (n, 3) float64, ``faces`` (m, 3) int32,
    ``attrs`` ``normals`` (n, 3) float32, ``colors`` (n, 3) uint8 CityScapes palette of each vertex's own
    label, ``class_id`` (n,) uint8 each vertex's own label (border vertices keep theirs), ``source_index``
    (n,) int32 index of the vertex in the source mesh; ``face_attrs["texcoord"]`` (m, 6) float32
    (OBJ convention, v up; ``mesh.corner_uv`` gives it as (m, 3, 2))
    """

    class_id: int
    name: str
    mesh: Mesh

    @property
    def own_vertices(self) -> int:
        """How many of the sub-mesh's vertices carry the part's own class."""
        return int(np.count_nonzero(self.mesh.attrs["class_id"] == self.class_id))


def class_part(class_id: int, name: str, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray,
               colors: np.ndarray, vertex_class: np.ndarray, source_index: np.ndarray,
               corner_uv: np.ndarray) -> ClassPart:
    """A :class:`ClassPart` from its arrays (shapes as there; ``corner_uv`` (m, 3, 2)), cast to the PLY dtypes."""
    mesh = Mesh(vertices=np.asarray(vertices, np.float64), faces=np.asarray(faces, np.int32),
                attrs={"normals": np.asarray(normals, np.float32), "colors": np.asarray(colors, np.uint8),
                       "class_id": np.asarray(vertex_class, np.uint8),
                       "source_index": np.asarray(source_index, np.int32)},
                face_attrs={"texcoord": np.asarray(corner_uv, np.float32).reshape(-1, 6)})
    return ClassPart(class_id=int(class_id), name=name, mesh=mesh)


def write_class_ply(path: Path, part: ClassPart, texture_name: str | None) -> None:
    """Binary PLY readable by MeshLab/CloudCompare: palette colours, class_id, source_index, face texcoords."""
    comments = [f"twinkit-export class {part.class_id} {part.name}"]
    if texture_name:
        comments.append(f"TextureFile {texture_name}")
    m = part.mesh
    mesh = Mesh(vertices=m.vertices, faces=m.faces, attrs=dict(m.attrs), face_attrs=dict(m.face_attrs),
                comments=comments)
    write_ply(path, mesh, xyz_dtype="f8")


def read_class_ply(path: Path) -> ClassPart:
    """Read a file written by :func:`write_class_ply`."""
    path = Path(path)
    m = read_ply(path)
    if "source_index" not in m.attrs or "class_id" not in m.attrs:
        raise ValueError(f"{path}: not a twinkit-export class mesh (re-run split_classes)")
    class_id, name = 255, ""
    for c in m.comments:
        parts = c.split()
        if c.startswith("twinkit-export class") and len(parts) >= 3:
            class_id, name = int(parts[2]), " ".join(parts[3:])
    faces = m.faces if m.faces is not None else np.zeros((0, 3), np.int64)
    tc = m.face_attrs.get("texcoord", np.zeros((len(faces), 6), np.float32))
    return class_part(
        class_id, name, vertices=m.vertices, faces=faces, normals=np.asarray(m.normals, np.float32),
        colors=m.colors, vertex_class=np.asarray(m.attrs["class_id"], np.uint8).copy(),
        source_index=np.asarray(m.attrs["source_index"]).astype(np.int32),
        corner_uv=np.asarray(tc).reshape(-1, 3, 2))

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
class ClassMesh:
    """One class's sub-mesh.

    class_id: the sub-mesh's class (trainId)
    vertices: (n, 3) float64 metres, site frame; normals (n, 3) float32
    colors: (n, 3) uint8 CityScapes palette of each vertex's own label
    vertex_class: (n,) uint8 each vertex's own label (border vertices keep theirs)
    source_index: (n,) int32 index of the vertex in the source mesh
    faces: (m, 3) int32; corner_uv (m, 3, 2) float32 (OBJ convention, v up)
    """

    class_id: int
    name: str
    vertices: np.ndarray
    normals: np.ndarray
    colors: np.ndarray
    vertex_class: np.ndarray
    source_index: np.ndarray
    faces: np.ndarray
    corner_uv: np.ndarray

    @property
    def n_vertices(self) -> int:
        return int(len(self.vertices))

    @property
    def n_faces(self) -> int:
        return int(len(self.faces))

    @property
    def own_vertices(self) -> int:
        return int(np.count_nonzero(self.vertex_class == self.class_id))


def write_class_ply(path: Path, cm: ClassMesh, texture_name: str | None) -> None:
    """Binary PLY readable by MeshLab/CloudCompare: palette colours, class_id, source_index, face texcoords."""
    comments = [f"twinkit-export class {cm.class_id} {cm.name}"]
    if texture_name:
        comments.append(f"TextureFile {texture_name}")
    mesh = Mesh(vertices=cm.vertices, faces=cm.faces,
                attrs={"normals": cm.normals, "colors": cm.colors,
                       "class_id": np.asarray(cm.vertex_class, np.uint8),
                       "source_index": np.asarray(cm.source_index, np.int32)},
                face_attrs={"texcoord": np.asarray(cm.corner_uv, np.float32).reshape(-1, 6)},
                comments=comments)
    write_ply(path, mesh, xyz_dtype="f8")


def read_class_ply(path: Path) -> ClassMesh:
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
    return ClassMesh(
        class_id=class_id, name=name,
        vertices=m.vertices,
        normals=np.asarray(m.normals, np.float32),
        colors=m.colors,
        vertex_class=np.asarray(m.attrs["class_id"], np.uint8).copy(),
        source_index=np.asarray(m.attrs["source_index"]).astype(np.int32),
        faces=faces.astype(np.int32),
        corner_uv=np.asarray(tc).reshape(-1, 3, 2).astype(np.float32),
    )

"""Reading the textured OBJ and reading/writing the per-class PLY files.

Frames and units: positions are in the site frame (metres, x east, y north, z up, origin at the
site base point), as written by the texture step. UVs follow the OBJ convention (origin bottom
left, v up).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass
class TexturedMesh:
    """A triangle mesh with per-corner UVs.

    vertices: (n, 3) float64, metres, site frame
    faces: (m, 3) int64 vertex indices
    corner_uv: (m, 3, 2) float32, OBJ convention (v up)
    normals: (n, 3) float32 unit vertex normals, or None
    texture: path of the diffuse texture image, or None
    """

    vertices: np.ndarray
    faces: np.ndarray
    corner_uv: np.ndarray | None
    normals: np.ndarray | None = None
    texture: Path | None = None
    comments: list[str] = field(default_factory=list)


def _floats(lines: list[str], ncols: int, what: str, path: Path) -> np.ndarray:
    if not lines:
        return np.zeros((0, ncols), np.float64)
    arr = np.array(" ".join(lines).split(), dtype=np.float64)
    if arr.size % ncols:
        # rows with a different column count (e.g. "vt u v w" or "v x y z r g b"): slow path
        rows = [ln.split()[:ncols] for ln in lines]
        try:
            arr = np.array(rows, dtype=np.float64)
        except ValueError as exc:
            raise ValueError(f"{path}: malformed '{what}' lines ({exc})") from None
        return arr
    return arr.reshape(-1, ncols)


def read_obj(path: Path) -> TexturedMesh:
    """Read a triangulated (or polygonal: fan-triangulated) OBJ with its MTL's ``map_Kd`` texture."""
    path = Path(path)
    text = path.read_text()
    v, vt, vn, f = [], [], [], []
    mtllibs = []
    for ln in text.splitlines():
        if ln.startswith("v "):
            v.append(ln[2:])
        elif ln.startswith("vt "):
            vt.append(ln[3:])
        elif ln.startswith("vn "):
            vn.append(ln[3:])
        elif ln.startswith("f "):
            f.append(ln[2:])
        elif ln.startswith("mtllib "):
            mtllibs.append(ln[7:].strip())
    verts = _floats(v, 3, "v", path)
    uvs = _floats(vt, 2, "vt", path) if vt else None
    nrms = _floats(vn, 3, "vn", path) if vn else None
    if not f:
        raise ValueError(f"{path}: no faces")
    # corners "a/b/c", "a//c", "a/b" or "a"
    first = f[0].split()[0]
    nslash = first.count("/")
    has_vt = nslash >= 1 and "//" not in first
    has_vn = nslash == 2
    ncomp = 1 + int(has_vt) + int(has_vn)
    flat = " ".join(f).replace("//", " ").replace("/", " ").split()
    n_corner_rows = [len(s.split()) for s in f[:1]]
    tri = len(flat) == len(f) * 3 * ncomp and n_corner_rows[0] == 3
    if tri:
        idx = np.array(flat, dtype=np.int64).reshape(len(f), 3, ncomp)
    else:  # polygons: fan triangulation
        rows = []
        for s in f:
            corners = [[int(x) for x in c.replace("//", "/").split("/") if x != ""] for c in s.split()]
            for k in range(1, len(corners) - 1):
                rows.append([corners[0], corners[k], corners[k + 1]])
        idx = np.array(rows, dtype=np.int64)
    # OBJ indices are 1-based; negative indices count from the end
    def fix(col: np.ndarray, n: int) -> np.ndarray:
        return np.where(col < 0, col + n, col - 1)

    faces = fix(idx[:, :, 0], len(verts))
    corner_uv = None
    if has_vt and uvs is not None:
        corner_uv = uvs[fix(idx[:, :, 1], len(uvs))].astype(np.float32)
    normals = None
    if has_vn and nrms is not None:
        nidx = fix(idx[:, :, ncomp - 1], len(nrms))
        normals = np.zeros((len(verts), 3), np.float32)
        normals[faces.ravel()] = nrms[nidx.ravel()]
    texture = None
    for lib in mtllibs:
        mtl = path.parent / lib
        if mtl.exists():
            m = re.search(r"^\s*map_Kd\s+(.+?)\s*$", mtl.read_text(), re.M)
            if m:
                cand = path.parent / m.group(1).split()[-1]
                if cand.exists():
                    texture = cand
                    break
    if texture is None:
        for ext in (".png", ".jpg", ".jpeg"):
            if path.with_suffix(ext).exists():
                texture = path.with_suffix(ext)
                break
    if faces.min() < 0 or faces.max() >= len(verts):
        raise ValueError(f"{path}: face indices out of range")
    return TexturedMesh(verts, faces, corner_uv, normals, texture)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(n, 3) float32 area-weighted unit vertex normals."""
    fn = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    vn = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(vn, faces[:, k], fn)
    ln = np.linalg.norm(vn, axis=1, keepdims=True)
    ln[ln == 0] = 1.0
    return (vn / ln).astype(np.float32)


# ----------------------------------------------------------------------------- class PLY files

_VERTEX_DTYPE = np.dtype([
    ("x", "<f8"), ("y", "<f8"), ("z", "<f8"),
    ("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4"),
    ("red", "u1"), ("green", "u1"), ("blue", "u1"),
    ("class_id", "u1"), ("source_index", "<i4"),
])
_FACE_DTYPE = np.dtype([
    ("n", "u1"), ("vertex_indices", "<i4", (3,)),
    ("nt", "u1"), ("texcoord", "<f4", (6,)),
])


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
    vert = np.empty(cm.n_vertices, _VERTEX_DTYPE)
    vert["x"], vert["y"], vert["z"] = cm.vertices.T
    vert["nx"], vert["ny"], vert["nz"] = cm.normals.T
    vert["red"], vert["green"], vert["blue"] = cm.colors.T
    vert["class_id"] = cm.vertex_class
    vert["source_index"] = cm.source_index
    face = np.empty(cm.n_faces, _FACE_DTYPE)
    face["n"] = 3
    face["vertex_indices"] = cm.faces
    face["nt"] = 6
    face["texcoord"] = cm.corner_uv.reshape(-1, 6)
    header = ["ply", "format binary_little_endian 1.0",
              f"comment twinkit-export class {cm.class_id} {cm.name}"]
    if texture_name:
        header.append(f"comment TextureFile {texture_name}")
    header += [f"element vertex {cm.n_vertices}",
               "property double x", "property double y", "property double z",
               "property float nx", "property float ny", "property float nz",
               "property uchar red", "property uchar green", "property uchar blue",
               "property uchar class_id", "property int source_index",
               f"element face {cm.n_faces}",
               "property list uchar int vertex_indices",
               "property list uchar float texcoord",
               "end_header"]
    with open(path, "wb") as fh:
        fh.write(("\n".join(header) + "\n").encode("ascii"))
        fh.write(vert.tobytes())
        fh.write(face.tobytes())


def read_class_ply(path: Path) -> ClassMesh:
    """Read a file written by :func:`write_class_ply` (fixed layout; not a general PLY reader)."""
    path = Path(path)
    with open(path, "rb") as fh:
        data = fh.read()
    end = data.find(b"end_header\n")
    if end < 0:
        raise ValueError(f"{path}: not a PLY file")
    header = data[:end].decode("ascii").splitlines()
    nv = nf = 0
    class_id, name = 255, ""
    for ln in header:
        parts = ln.split()
        if ln.startswith("element vertex"):
            nv = int(parts[2])
        elif ln.startswith("element face"):
            nf = int(parts[2])
        elif ln.startswith("comment twinkit-export class"):
            class_id, name = int(parts[3]), " ".join(parts[4:])
    if "property int source_index" not in header:
        raise ValueError(f"{path}: not a twinkit-export class mesh (re-run split_classes)")
    off = end + len(b"end_header\n")
    vert = np.frombuffer(data, _VERTEX_DTYPE, nv, off)
    face = np.frombuffer(data, _FACE_DTYPE, nf, off + nv * _VERTEX_DTYPE.itemsize)
    return ClassMesh(
        class_id=class_id, name=name,
        vertices=np.column_stack([vert["x"], vert["y"], vert["z"]]),
        normals=np.column_stack([vert["nx"], vert["ny"], vert["nz"]]).astype(np.float32),
        colors=np.column_stack([vert["red"], vert["green"], vert["blue"]]),
        vertex_class=vert["class_id"].copy(),
        source_index=vert["source_index"].astype(np.int32),
        faces=face["vertex_indices"].astype(np.int32),
        corner_uv=face["texcoord"].reshape(-1, 3, 2).astype(np.float32),
    )

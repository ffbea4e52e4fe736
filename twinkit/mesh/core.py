"""The one mesh / cloud type of twinkit and the per-face / per-vertex operations on it.

A mesh or cloud is plain numpy arrays:

- ``vertices``: (n, 3) float64, metres, site frame (x east, y north, z up)
- ``faces``: (m, 3) int64 vertex indices (counter-clockwise seen from outside), or None for a cloud
- ``attrs``: per-vertex arrays keyed by name; conventional names are ``normals`` (n, 3) float32,
  ``colors`` (n, 3) uint8 sRGB, ``label`` (n,) uint8 CityScapes trainId, and scalars such as
  ``density``, ``dist_to_cloud_m``, ``intensity``, ``classification``, ``scanner``
- ``face_attrs``: per-face arrays; ``texcoord`` (m, 6) float32 is the per-corner UV
  (u0 v0 u1 v1 u2 v2, OBJ convention: origin bottom left, v up), ``label`` (m,) a face label
- ``comments``: PLY header comments (``TextureFile name`` names the texture beside the file)
- ``texture``: path of the diffuse texture image of a textured mesh, or None
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass
class Mesh:
    vertices: np.ndarray  # (n, 3) float64
    faces: np.ndarray | None = None  # (m, 3) int64
    attrs: dict[str, np.ndarray] = field(default_factory=dict)
    face_attrs: dict[str, np.ndarray] = field(default_factory=dict)
    comments: list[str] = field(default_factory=list)
    texture: Path | None = None

    @property
    def n_vertices(self) -> int:
        return int(len(self.vertices))

    @property
    def n_faces(self) -> int:
        return 0 if self.faces is None else int(len(self.faces))

    @property
    def colors(self) -> np.ndarray | None:
        """(n, 3) uint8 vertex colours, or None."""
        return self.attrs.get("colors")

    @property
    def normals(self) -> np.ndarray | None:
        """(n, 3) float32 vertex normals, or None."""
        return self.attrs.get("normals")

    @property
    def corner_uv(self) -> np.ndarray | None:
        """(m, 3, 2) float32 per-corner texture coordinates (v up), from ``face_attrs["texcoord"]``, or None."""
        tc = self.face_attrs.get("texcoord")
        return None if tc is None else np.asarray(tc, np.float32).reshape(-1, 3, 2)


def compact(mesh: Mesh, keep_faces: np.ndarray | None = None) -> Mesh:
    """Keep the faces selected by ``keep_faces`` ((m,) bool mask) and drop unreferenced vertices."""
    assert mesh.faces is not None  # a mesh, not a cloud
    faces = mesh.faces if keep_faces is None else mesh.faces[keep_faces]
    face_attrs = {k: (v if keep_faces is None else v[keep_faces]) for k, v in mesh.face_attrs.items()}
    used = np.zeros(mesh.n_vertices, bool)
    used[faces.ravel()] = True
    remap = np.full(mesh.n_vertices, -1, np.int64)
    remap[used] = np.arange(int(used.sum()))
    return Mesh(vertices=mesh.vertices[used], faces=remap[faces],
                attrs={k: v[used] for k, v in mesh.attrs.items()}, face_attrs=face_attrs,
                comments=list(mesh.comments), texture=mesh.texture)


def face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(m,) float64 triangle areas, m^2."""
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(m, 3) float64 unit face normals (right-hand rule over the corner order)."""
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    n = np.cross(b - a, c - a)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.maximum(ln, 1e-30)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals, (n, 3) float32 (zero for unreferenced vertices)."""
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    fn = np.cross(b - a, c - a)
    n = len(vertices)
    vn = np.zeros_like(vertices)
    for i in range(3):
        for k in range(3):
            vn[:, k] += np.bincount(faces[:, i], weights=fn[:, k], minlength=n)
    ln = np.linalg.norm(vn, axis=1, keepdims=True)
    return (vn / np.maximum(ln, 1e-30)).astype(np.float32)


def edges(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Unique undirected edges ``(e, 2) int64`` (a < b) of a triangle mesh, sorted by (a, b).

    Deduplicated through a sparse matrix (linear-time CSR build) rather than sorting
    64-bit keys: 0.35 s instead of 1-4 s for 2M faces."""
    import scipy.sparse as sp

    f = np.asarray(faces)
    if len(f) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    a = np.concatenate([f[:, 0], f[:, 1], f[:, 2]])
    b = np.concatenate([f[:, 1], f[:, 2], f[:, 0]])
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    keep = lo != hi
    lo, hi = lo[keep], hi[keep]
    m = sp.csr_matrix((np.ones(len(lo), dtype=np.int8), (lo, hi)), shape=(n_vertices, n_vertices))
    m.sum_duplicates()
    rows = np.repeat(np.arange(n_vertices, dtype=np.int64), np.diff(m.indptr))
    return np.column_stack([rows, m.indices.astype(np.int64)])

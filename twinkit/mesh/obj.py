"""Textured OBJ + MTL reading and writing.

Frames and units: positions in the site frame (metres, x east, y north, z up, origin at the site
base point). UVs follow the OBJ convention (origin bottom left, v up).
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .core import Mesh


def _parse(text: str, dtype) -> np.ndarray | None:
    """Whitespace-separated numbers with numpy's C parser (several times faster than a Python
    conversion per token); None when the text holds anything else (the caller's slow path says what)."""
    import warnings

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)  # numpy < 2.3 warns and stops at bad data
            return np.fromstring(text, dtype=dtype, sep=" ")
    except ValueError:
        return None


def _floats(lines: list[str], ncols: int, what: str, path: Path) -> np.ndarray:
    if not lines:
        return np.zeros((0, ncols), np.float64)
    arr = _parse(" ".join(lines), np.float64)
    if arr is None or arr.size != len(lines) * ncols:
        # rows with a different column count (e.g. "vt u v w" or "v x y z r g b"): slow path
        rows = [ln.split()[:ncols] for ln in lines]
        try:
            arr = np.array(rows, dtype=np.float64)
        except ValueError as exc:
            raise ValueError(f"{path}: malformed '{what}' lines ({exc})") from None
        return arr
    return arr.reshape(-1, ncols)


def read_obj(path: Path) -> Mesh:
    """Read a triangulated (or polygonal: fan-triangulated) OBJ with its MTL's ``map_Kd`` texture.

    Returns a :class:`Mesh`: vertices (n, 3) float64; faces (m, 3) int64; per-corner UVs (when the
    faces have ``vt`` indices) as ``face_attrs["texcoord"]`` (m, 6) float32 (``Mesh.corner_uv``
    gives (m, 3, 2)); vertex normals (when given) as ``attrs["normals"]`` (n, 3) float32; the
    texture path (MTL ``map_Kd``, else an image with the same stem) as ``Mesh.texture``."""
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
    flat = _parse(" ".join(f).replace("//", " ").replace("/", " "), np.int64)
    tri = flat is not None and flat.size == len(f) * 3 * ncomp and len(f[0].split()) == 3
    if tri and flat is not None:
        idx = flat.reshape(len(f), 3, ncomp)
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
    attrs = {"normals": normals} if normals is not None else {}
    face_attrs = {"texcoord": corner_uv.reshape(-1, 6)} if corner_uv is not None else {}
    return Mesh(vertices=verts, faces=faces, attrs=attrs, face_attrs=face_attrs, texture=texture)



def write_mtl(path: Path, material: str, texture_name: str, *, comment: str | None = "twinkit-pointcloud",
              dissolve: bool = True) -> None:
    """The MTL of a textured OBJ: one material ``material`` (white, unlit: ``illum 1``) whose ``map_Kd`` is
    ``texture_name`` (a file next to it); ``comment`` (a ``#`` line first) and ``dissolve`` (a ``d 1`` line,
    opaque) as the file's producer writes them."""
    head = f"# {comment}\n" if comment is not None else ""
    d = "d 1\n" if dissolve else ""
    Path(path).write_text(f"{head}newmtl {material}\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\n{d}illum 1\nmap_Kd {texture_name}\n")


def write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, texture_name: str,
              normals: np.ndarray | None = None, material: str = "twinkit_texture", *,
              comment: str | None = None, mtl_comment: str | None = "twinkit-pointcloud", mtl_dissolve: bool = True,
              decimals: int = 6, uv_decimals: int = 7, groups: list[tuple[str | None, int]] | None = None) -> None:
    """Write an OBJ + MTL beside it (same stem; :func:`write_mtl`), the one OBJ writer.

    ``vertices`` (n, 3) metres, written with ``decimals``; ``faces`` (m, 3) 0-based; ``uv`` in [0, 1], v up,
    either per corner (m, 3, 2: corners with equal UVs, rounded to ``uv_decimals``, share a ``vt``) or per
    vertex (n, 2: ``vt`` i is vertex i's); optional unit ``normals`` (n, 3). ``comment``: the ``#`` lines
    at the top (``\n`` separates lines; None: the vertex and face count). ``groups``: (name, face count)
    runs in face order, each preceded by ``g name`` (the counts add up to m). The MTL's ``map_Kd`` names
    ``texture_name``; ``mtl_comment`` and ``mtl_dissolve`` go to :func:`write_mtl`."""
    path = Path(path)
    mtl = path.with_suffix(".mtl")
    write_mtl(mtl, material, texture_name, comment=mtl_comment, dissolve=mtl_dissolve)
    m = len(faces)
    uv = np.asarray(uv)
    if uv.ndim == 3:  # per corner: share vt between corners with identical UVs (corners of the same chart)
        vt, inv = _unique_rows(np.round(uv.reshape(-1, 2), uv_decimals))
        t1 = inv.reshape(m, 3) + 1
    else:
        vt, t1 = uv, None
    if comment is None:
        comment = f"twinkit-pointcloud textured mesh: {len(vertices)} vertices, {m} faces"
    with open(path, "w") as fh:
        fh.write("".join(f"# {ln}\n" for ln in comment.split("\n")))
        fh.write(f"mtllib {mtl.name}\n")
        _rows(fh, vertices, "v" + f" %.{decimals}f" * 3)
        _rows(fh, vt, "vt" + f" %.{uv_decimals}f" * 2)
        if normals is not None:
            _rows(fh, normals, "vn %.4f %.4f %.4f")
        fh.write(f"usemtl {material}\n")
        f1 = faces + 1
        if t1 is None:
            t1 = f1
        if normals is not None:
            arr = np.stack([f1[:, 0], t1[:, 0], f1[:, 0], f1[:, 1], t1[:, 1], f1[:, 1], f1[:, 2], t1[:, 2], f1[:, 2]], axis=1)
            fmt = "f %d/%d/%d %d/%d/%d %d/%d/%d"
        else:
            arr = np.stack([f1[:, 0], t1[:, 0], f1[:, 1], t1[:, 1], f1[:, 2], t1[:, 2]], axis=1)
            fmt = "f %d/%d %d/%d %d/%d"
        start = 0
        for name, count in groups or [(None, m)]:
            if name is not None:
                fh.write(f"g {name}\n")
            _rows(fh, arr[start:start + count], fmt)
            start += count


def _unique_rows(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(a, axis=0, return_inverse=True)`` for (k, 2) float rows (sorted by the first column, then
    the second), through one lexsort: 4x faster than numpy's row unique (a sort of structured records)."""
    order = np.lexsort((a[:, 1], a[:, 0]))
    s = a[order]
    new = np.ones(len(s), bool)
    new[1:] = (s[1:, 0] != s[:-1, 0]) | (s[1:, 1] != s[:-1, 1])
    inv = np.empty(len(a), np.int64)
    inv[order] = np.cumsum(new) - 1
    return s[new], inv


def _rows(fh, arr: np.ndarray, fmt: str, chunk: int = 100_000) -> None:
    """``np.savetxt(fh, arr, fmt=fmt)`` with the same bytes, 2-3x faster: one %-format per chunk of rows."""
    line = fmt + "\n"
    for s in range(0, len(arr), chunk):
        part = arr[s:s + chunk]
        fh.write((line * len(part)) % tuple(part.ravel().tolist()))

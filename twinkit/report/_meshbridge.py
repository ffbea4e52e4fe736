"""The report's own PLY reader and GLB writer, kept in one module.

The lead replaces this module with ``twinkit.mesh`` (``twinkit.mesh.read_ply``, ``twinkit.mesh.glb.write_glb``)
at integration: every user in ``twinkit.report`` and in the plugins' report sections imports these names
from here and nowhere else, so swapping this one module is the whole change. The code is unchanged from
the former ``twinkit/report.py``.
"""
from __future__ import annotations

import json
import os
import struct
from pathlib import Path

import numpy as np

__all__ = ["Mesh", "read_ply", "write_glb", "decimate", "ply_vertex_count"]

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


class Mesh:
    def __init__(self, xyz: np.ndarray, faces: np.ndarray, colors: np.ndarray | None, labels: np.ndarray | None):
        self.xyz, self.faces, self.colors, self.labels = xyz, faces, colors, labels


def read_ply(path: Path) -> Mesh:
    """Vertices, triangles, vertex colours and a vertex ``label`` property of a PLY (fast path: binary with
    fixed-length face lists, read with numpy in one go; anything else through plyfile)."""
    with open(path, "rb") as f:
        head = b""
        while not head.endswith(b"end_header\n") and not head.endswith(b"end_header\r\n"):
            line = f.readline()
            if not line:
                raise ValueError(f"{path}: no PLY header")
            head += line
        body_at = f.tell()
    lines = head.decode("ascii", "replace").splitlines()
    fmt = next((ln.split()[1] for ln in lines if ln.startswith("format")), "")
    elements: list[list] = []
    for ln in lines:
        t = ln.split()
        if not t:
            continue
        if t[0] == "element":
            elements.append([t[1], int(t[2]), []])
        elif t[0] == "property" and elements:
            elements[-1][2].append(t[1:])
    if fmt not in ("binary_little_endian", "binary_big_endian"):
        return _read_ply_slow(path)
    end = "<" if fmt == "binary_little_endian" else ">"
    data = np.memmap(path, dtype=np.uint8, mode="r", offset=body_at)
    pos = 0
    out: dict[str, np.ndarray] = {}
    for name, count, props in elements:
        fields = []
        for p in props:
            if p[0] == "list":
                # peek at the first row's count to make the list fixed-length
                ctype, itype, pname = _PLY_TYPES[p[1]], _PLY_TYPES[p[2]], p[3]
                off = pos + sum(np.dtype(end + t).itemsize * (n or 1) for _, t, n in fields)
                if count == 0:
                    n = 3
                else:
                    n = int(np.frombuffer(data[off:off + np.dtype(ctype).itemsize], dtype=end + ctype)[0])
                fields.append((pname + "__n", ctype, 0))
                fields.append((pname, itype, n))
            else:
                fields.append((p[1], _PLY_TYPES[p[0]], 0))
        dt = np.dtype([(n, end + t) if not k else (n, end + t, (k,)) for n, t, k in fields])
        nbytes = dt.itemsize * count
        arr = np.frombuffer(data[pos:pos + nbytes], dtype=dt, count=count)
        for n, _, k in fields:
            if n.endswith("__n") and count and not np.all(arr[n] == arr[n][0]):
                return _read_ply_slow(path)  # variable-length lists
        out[name] = arr
        pos += nbytes
    v = out.get("vertex")
    if v is None:
        raise ValueError(f"{path}: no vertex element")
    xyz = np.column_stack([v["x"], v["y"], v["z"]]).astype(np.float64)
    faces = np.zeros((0, 3), np.int64)
    fe = out.get("face")
    if fe is not None and len(fe):
        key = "vertex_indices" if "vertex_indices" in fe.dtype.names else "vertex_index"
        idx = np.asarray(fe[key])
        if idx.ndim == 2 and idx.shape[1] == 3:
            faces = idx.astype(np.int64)
        elif idx.ndim == 2 and idx.shape[1] == 4:
            faces = np.concatenate([idx[:, [0, 1, 2]], idx[:, [0, 2, 3]]]).astype(np.int64)
    names = v.dtype.names
    colors = None
    if all(c in names for c in ("red", "green", "blue")):
        colors = np.column_stack([v["red"], v["green"], v["blue"]])
        if colors.dtype != np.uint8:
            colors = (np.clip(colors.astype(np.float64), 0, 1) * 255).astype(np.uint8) \
                if colors.dtype.kind == "f" else colors.astype(np.uint8)
    labels = np.asarray(v["label"]).astype(np.uint8) if "label" in names else None
    return Mesh(xyz, faces, colors, labels)


def _read_ply_slow(path: Path) -> Mesh:
    from plyfile import PlyData

    ply = PlyData.read(str(path))
    v = ply["vertex"]
    names = v.data.dtype.names
    xyz = np.column_stack([np.asarray(v[c], np.float64) for c in ("x", "y", "z")])
    colors = np.column_stack([np.asarray(v[c]) for c in ("red", "green", "blue")]).astype(np.uint8) \
        if all(c in names for c in ("red", "green", "blue")) else None
    labels = np.asarray(v["label"]).astype(np.uint8) if "label" in names else None
    faces = np.zeros((0, 3), np.int64)
    if "face" in ply:
        fn = ply["face"].data.dtype.names
        key = "vertex_indices" if "vertex_indices" in fn else "vertex_index"
        rows = [r for r in ply["face"].data[key] if len(r) >= 3]
        tris = []
        for r in rows:
            for k in range(1, len(r) - 1):
                tris.append((r[0], r[k], r[k + 1]))
        faces = np.asarray(tris, np.int64).reshape(-1, 3)
    return Mesh(xyz, faces, colors, labels)


# =========================================================================== top-down orthophotos


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    c = np.asarray(c, np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def write_glb(path: Path, xyz: np.ndarray, faces: np.ndarray, colors: np.ndarray | None,
              seg_colors: np.ndarray | None) -> None:
    """A GLB of one triangle mesh in glTF's frame (y up: site x, z, -y).

    ``COLOR_0`` holds the segmentation colours when given (the convention of twinkit's exported GLBs),
    else the texture colours; with both, the texture colours go to the application attribute
    ``_TEXCOLOR``. Colours are stored linear (glTF), as normalised uint16 RGBA."""
    centre = (xyz.min(0) + xyz.max(0)) / 2
    centre[2] = xyz[:, 2].min()
    p = xyz - centre
    pos = np.column_stack([p[:, 0], p[:, 2], -p[:, 1]]).astype("<f4")
    attrs: list[tuple[str, np.ndarray, int, str, bool]] = [("POSITION", pos, 5126, "VEC3", False)]

    def col(c):
        lin = _srgb_to_linear(c[:, :3])
        rgba = np.ones((len(c), 4))
        rgba[:, :3] = lin
        return np.round(rgba * 65535).astype("<u2")

    if seg_colors is not None:
        attrs.append(("COLOR_0", col(seg_colors), 5123, "VEC4", True))
        if colors is not None:
            attrs.append(("_TEXCOLOR", col(colors), 5123, "VEC4", True))
    elif colors is not None:
        attrs.append(("COLOR_0", col(colors), 5123, "VEC4", True))
    idx = np.ascontiguousarray(faces, dtype="<u4").ravel()
    blobs, views, accessors = [], [], []
    offset = 0

    def add(arr: np.ndarray, target: int) -> int:
        nonlocal offset
        b = arr.tobytes()
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(b), "target": target})
        pad = (-len(b)) % 4
        blobs.append(b + b"\0" * pad)
        offset += len(b) + pad
        return len(views) - 1

    prim_attrs = {}
    for name, arr, ctype, atype, norm in attrs:
        acc = {"bufferView": add(arr, 34962), "componentType": ctype, "count": int(len(arr)), "type": atype}
        if norm:
            acc["normalized"] = True
        if name == "POSITION":
            acc["min"] = [float(x) for x in arr.min(0)]
            acc["max"] = [float(x) for x in arr.max(0)]
        accessors.append(acc)
        prim_attrs[name] = len(accessors) - 1
    accessors.append({"bufferView": add(idx, 34963), "componentType": 5125, "count": int(len(idx)),
                      "type": "SCALAR"})
    gltf = {
        "asset": {"version": "2.0", "generator": "twinkit.report"},
        "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "twin", "extras": {"site_origin_m": [float(x) for x in centre]}}],
        "meshes": [{"primitives": [{"attributes": prim_attrs, "indices": len(accessors) - 1, "material": 0}]}],
        "materials": [{"name": "twin", "doubleSided": True,
                       "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0.0,
                                                "roughnessFactor": 1.0}}],
        "buffers": [{"byteLength": offset}], "bufferViews": views, "accessors": accessors,
    }
    js = json.dumps(gltf, separators=(",", ":")).encode()
    js += b" " * ((-len(js)) % 4)
    binary = b"".join(blobs)
    total = 12 + 8 + len(js) + 8 + len(binary)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
    with open(tmp, "wb") as f:
        f.write(struct.pack("<4sII", b"glTF", 2, total))
        f.write(struct.pack("<I4s", len(js), b"JSON") + js)
        f.write(struct.pack("<I4s", len(binary), b"BIN\0") + binary)
    tmp.replace(path)


def decimate(xyz: np.ndarray, faces: np.ndarray, max_faces: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, faces, index of the nearest original vertex for each new vertex)."""
    if len(faces) <= max_faces:
        return xyz, faces, np.arange(len(xyz))
    try:
        import fast_simplification

        nv, nf = fast_simplification.simplify(xyz.astype(np.float32), faces.astype(np.int32),
                                              target_reduction=1 - max_faces / len(faces))
        nv = np.asarray(nv, np.float64)
        from scipy.spatial import cKDTree

        _, near = cKDTree(xyz).query(nv, k=1)
        return nv, np.asarray(nf, np.int64), near
    except ImportError:  # keep a random subset of faces
        rng = np.random.default_rng(0)
        keep = np.sort(rng.choice(len(faces), max_faces, replace=False))
        f = faces[keep]
        used, inv = np.unique(f, return_inverse=True)
        return xyz[used], inv.reshape(-1, 3), used


def _ply_vertex_count(p: Path) -> int:
    try:
        with open(p, "rb") as f:
            for _ in range(200):
                line = f.readline()
                if not line or line.startswith(b"end_header"):
                    break
                t = line.split()
                if len(t) == 3 and t[0] == b"element" and t[1] == b"vertex":
                    return int(t[2])
    except OSError:
        pass
    return 0


#: the header-only vertex count (the report matches label arrays by it without reading the mesh)
ply_vertex_count = _ply_vertex_count

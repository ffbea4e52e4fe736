"""A small reader for binary FBX (7.x): the node tree, mesh objects, materials and texture paths.

Enough for checking a CARLA package without Blender or the FBX SDK: which mesh objects a file
holds (names, face counts, custom properties such as ``class_id``), their materials, and the
texture file names. Format: a 27-byte header, then node records ``end offset, property count,
property bytes, name length, name, properties, child records`` (32-bit fields before version
7500, 64-bit from 7500 on), closed by an all-zero record; array properties may be zlib-compressed.
"""
from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

MAGIC = b"Kaydara FBX Binary  \x00"


class FbxReadError(ValueError):
    pass


@dataclass
class Node:
    name: str
    props: list
    children: list["Node"] = field(default_factory=list)

    def child(self, name: str) -> "Node | None":
        return next((c for c in self.children if c.name == name), None)

    def all(self, name: str) -> list["Node"]:
        return [c for c in self.children if c.name == name]


_SCALAR = {"Y": "<h", "C": "<?", "I": "<i", "F": "<f", "D": "<d", "L": "<q"}
_ARRAY = {"f": np.float32, "d": np.float64, "l": np.int64, "i": np.int32, "b": np.bool_}


def _read_props(buf: memoryview, pos: int, count: int) -> tuple[list, int]:
    out = []
    for _ in range(count):
        code = chr(buf[pos])
        pos += 1
        if code in _SCALAR:
            fmt = _SCALAR[code]
            (v,) = struct.unpack_from(fmt, buf, pos)
            pos += struct.calcsize(fmt)
            out.append(v)
        elif code in _ARRAY:
            n, enc, clen = struct.unpack_from("<III", buf, pos)
            pos += 12
            raw = bytes(buf[pos:pos + clen])
            pos += clen
            out.append(("array", code, n, enc, raw))  # decoded on demand (array_values)
        elif code in "SR":
            (n,) = struct.unpack_from("<I", buf, pos)
            pos += 4
            raw = bytes(buf[pos:pos + n])
            pos += n
            out.append(raw.decode("utf-8", "replace") if code == "S" else raw)
        else:
            raise FbxReadError(f"unknown property type {code!r} at byte {pos - 1}")
    return out, pos


def array_values(prop) -> np.ndarray:
    """The numbers of an array property (decompressing it when needed)."""
    _, code, n, enc, raw = prop
    data = zlib.decompress(raw) if enc == 1 else raw
    return np.frombuffer(data, dtype=_ARRAY[code], count=n)


def _read_nodes(buf: memoryview, pos: int, end: int, wide: bool) -> tuple[list[Node], int]:
    head = "<QQQB" if wide else "<IIIB"
    hsize = struct.calcsize(head)
    nodes = []
    while pos + hsize <= end:
        end_off, nprops, plen, nlen = struct.unpack_from(head, buf, pos)
        if end_off == 0:  # null record: end of this list
            pos += hsize
            break
        name = bytes(buf[pos + hsize:pos + hsize + nlen]).decode("ascii", "replace")
        p = pos + hsize + nlen
        props, p2 = _read_props(buf, p, nprops)
        if p2 != p + plen:
            raise FbxReadError(f"node {name!r}: property bytes do not add up")
        children = []
        if p2 < end_off:
            children, _ = _read_nodes(buf, p2, end_off, wide)
        nodes.append(Node(name, props, children))
        pos = end_off
    return nodes, pos


def read_tree(path: Path) -> tuple[int, list[Node]]:
    """(version, top-level nodes) of a binary FBX file."""
    data = Path(path).read_bytes()
    if not data.startswith(MAGIC):
        raise FbxReadError(f"{path}: not a binary FBX file (ASCII FBX is not read here)")
    (version,) = struct.unpack_from("<I", data, 23)
    nodes, _ = _read_nodes(memoryview(data), 27, len(data), version >= 7500)
    return version, nodes


def _object_name(prop: str) -> str:
    # "Name\x00\x01Class" in binary FBX
    return prop.split("\x00\x01")[0] if isinstance(prop, str) else str(prop)


@dataclass
class FbxModel:
    name: str
    faces: int
    properties: dict
    materials: list[str]


@dataclass
class FbxSummary:
    version: int
    meshes: list[FbxModel]
    materials: list[str]
    textures: list[dict]  # {"FileName": ..., "RelativeFilename": ...} of every Texture and Video object


def summarize(path: Path) -> FbxSummary:
    version, nodes = read_tree(path)
    top = {n.name: n for n in nodes}
    objects = top.get("Objects")
    if objects is None:
        raise FbxReadError(f"{path}: no Objects section")
    geoms, models, mats = {}, {}, {}
    textures = []
    for o in objects.children:
        oid = o.props[0] if o.props else None
        if o.name == "Geometry" and len(o.props) > 2 and o.props[2] == "Mesh":
            pvi = o.child("PolygonVertexIndex")
            n = int(np.count_nonzero(array_values(pvi.props[0]) < 0)) if pvi is not None else 0
            geoms[oid] = n
        elif o.name == "Model" and len(o.props) > 2 and o.props[2] == "Mesh":
            p70 = o.child("Properties70")
            props = {}
            for p in (p70.all("P") if p70 is not None else []):
                if len(p.props) >= 5 and "U" in str(p.props[3]):  # user properties
                    props[p.props[0]] = p.props[4]
            models[oid] = (_object_name(o.props[1]), props)
        elif o.name == "Material":
            mats[oid] = _object_name(o.props[1])
        elif o.name in ("Texture", "Video"):
            entry = {"object": o.name, "name": _object_name(o.props[1])}
            for key in ("FileName", "RelativeFilename"):
                c = o.child(key)
                if c is not None and c.props:
                    entry[key] = c.props[0]
            textures.append(entry)
    conns = top.get("Connections")
    model_geom, model_mats = {}, {}
    for c in (conns.all("C") if conns is not None else []):
        if len(c.props) >= 3 and c.props[0] == "OO":
            child, parent = c.props[1], c.props[2]
            if child in geoms and parent in models:
                model_geom[parent] = child
            elif child in mats and parent in models:
                model_mats.setdefault(parent, []).append(mats[child])
    meshes = [FbxModel(name, geoms.get(model_geom.get(mid), 0), props, model_mats.get(mid, []))
              for mid, (name, props) in models.items()]
    return FbxSummary(version, meshes, sorted(set(mats.values())), textures)


def _unit_scale(top: dict) -> float:
    """Metres per file unit: GlobalSettings' UnitScaleFactor is centimetres per unit (1 when absent)."""
    gs = top.get("GlobalSettings")
    p70 = gs.child("Properties70") if gs is not None else None
    for p in (p70.all("P") if p70 is not None else []):
        if p.props and p.props[0] == "UnitScaleFactor" and len(p.props) >= 5:
            return float(p.props[4]) / 100.0
    return 0.01


def _model_transform(model: Node) -> tuple[np.ndarray, np.ndarray]:
    """(scale (3,), translation (3,)) of a model's Lcl Scaling / Lcl Translation; ValueError for a rotation."""
    scale, shift = np.ones(3), np.zeros(3)
    p70 = model.child("Properties70")
    for p in (p70.all("P") if p70 is not None else []):
        if not p.props or len(p.props) < 7:
            continue
        v = np.array([float(x) for x in p.props[4:7]])
        if p.props[0] == "Lcl Scaling":
            scale = v
        elif p.props[0] == "Lcl Translation":
            shift = v
        elif p.props[0] == "Lcl Rotation" and np.abs(v).max() > 1e-9:
            raise FbxReadError(f"model {_object_name(model.props[1])!r} is rotated (Lcl Rotation {v.tolist()}); "
                               "only baked vertices are read")
    return scale, shift


def mesh_arrays(path: Path) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(model name, vertices (n, 3) float64 in metres, triangles (m, 3) int64) of every mesh model of a binary
    FBX: vertices with the model's scale and translation and the file's unit applied (a rotated model is an
    :class:`FbxReadError`); polygons split into triangle fans. The file's own axes (twinkit writes Z up, the
    frame of the package's OpenDRIVE)."""
    _, nodes = read_tree(path)
    top = {n.name: n for n in nodes}
    objects = top.get("Objects")
    if objects is None:
        raise FbxReadError(f"{path}: no Objects section")
    unit = _unit_scale(top)
    geoms, models = {}, {}
    for o in objects.children:
        oid = o.props[0] if o.props else None
        if o.name == "Geometry" and len(o.props) > 2 and o.props[2] == "Mesh":
            geoms[oid] = o
        elif o.name == "Model" and len(o.props) > 2 and o.props[2] == "Mesh":
            models[oid] = o
    conns = top.get("Connections")
    out = []
    for c in (conns.all("C") if conns is not None else []):
        if len(c.props) >= 3 and c.props[0] == "OO" and c.props[1] in geoms and c.props[2] in models:
            g, m = geoms[c.props[1]], models[c.props[2]]
            vn, pn = g.child("Vertices"), g.child("PolygonVertexIndex")
            if vn is None or pn is None:
                continue
            scale, shift = _model_transform(m)
            v = array_values(vn.props[0]).astype(np.float64).reshape(-1, 3) * scale + shift
            out.append((_object_name(m.props[1]), v * unit, _fans(array_values(pn.props[0]).astype(np.int64))))
    return out


def _fans(pvi: np.ndarray) -> np.ndarray:
    """Triangles (m, 3) from FBX polygon vertex indices (a polygon's last index is stored as ``-index - 1``)."""
    pvi = np.asarray(pvi, np.int64)
    ends = np.flatnonzero(pvi < 0)
    idx = np.where(pvi < 0, -pvi - 1, pvi)
    starts = np.r_[0, ends[:-1] + 1][:len(ends)].astype(np.int64)
    ntri = np.maximum(ends - starts - 1, 0)  # a polygon of L corners gives L - 2 triangles (fan from its first)
    first = np.repeat(starts, ntri)
    k = np.arange(int(ntri.sum())) - np.repeat(np.cumsum(ntri) - ntri, ntri) + 1
    return np.c_[idx[first], idx[first + k], idx[first + k + 1]].reshape(-1, 3)

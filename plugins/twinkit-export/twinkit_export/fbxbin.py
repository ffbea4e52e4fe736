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


def mesh_geometry(path: Path, names: tuple[str, ...] | None = None) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{model name: (vertices (n, 3) float64 as stored (no node transform applied), triangles (m, 3) int64)}
    of the mesh models of a binary FBX (``names``: only these). Polygons are fanned into triangles."""
    _, nodes = read_tree(path)
    top = {n.name: n for n in nodes}
    objects, conns = top.get("Objects"), top.get("Connections")
    if objects is None:
        raise FbxReadError(f"{path}: no Objects section")
    geoms, models = {}, {}
    for o in objects.children:
        if o.name == "Geometry" and len(o.props) > 2 and o.props[2] == "Mesh":
            geoms[o.props[0]] = o
        elif o.name == "Model" and len(o.props) > 2 and o.props[2] == "Mesh":
            models[o.props[0]] = _object_name(o.props[1])
    out = {}
    for c in (conns.all("C") if conns is not None else []):
        if len(c.props) < 3 or c.props[0] != "OO" or c.props[1] not in geoms or c.props[2] not in models:
            continue
        name = models[c.props[2]]
        if names is not None and name not in names:
            continue
        g = geoms[c.props[1]]
        vn, pn = g.child("Vertices"), g.child("PolygonVertexIndex")
        if vn is None or pn is None:
            continue
        v = array_values(vn.props[0]).astype(np.float64).reshape(-1, 3)
        pvi = array_values(pn.props[0]).astype(np.int64)
        ends = np.flatnonzero(pvi < 0)
        idx = np.where(pvi < 0, ~pvi, pvi)
        tris = []
        start = 0
        for e in ends.tolist():
            poly = idx[start:e + 1]
            tris.extend((poly[0], poly[k], poly[k + 1]) for k in range(1, len(poly) - 1))
            start = e + 1
        out[name] = (v, np.asarray(tris, np.int64).reshape(-1, 3))
    return out

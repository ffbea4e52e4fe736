"""glTF 2.0 binary (GLB) writer for viewing in a browser (three.js, model-viewer, Blender).

- one node + mesh per class, named like the FBX objects; node extras: class_id, cityscapes_class,
  carla_tag; asset extras: the site georeference;
- axes: glTF is y up; vertices are converted from the site frame (x east, y north, z up) to
  glTF (x, z, -y), a rotation, so viewers need no node transform; metres stay metres;
- attributes: POSITION, NORMAL, TEXCOORD_0 (v flipped: glTF UV origin is top left), COLOR_0 (the
  CityScapes palette converted from sRGB to linear, float RGB, as glTF defines vertex colours) and _CLASS_ID (unsigned byte, each vertex's
  own label); vertices are split where UV charts meet (glTF has one UV per vertex);
- one material with the texture as baseColorTexture (embedded, PNG or JPEG) and
  KHR_materials_unlit (the texture already holds the captured light). Note: per the glTF spec
  COLOR_0 multiplies the base colour; a viewer toggles between texture (ignore vertex colours)
  and segmentation (no texture, vertex colours) — see docs/export.md for the three.js lines.
"""
from __future__ import annotations

import io
import json
import struct
from pathlib import Path

import numpy as np

from .classes import info

_ARRAY_BUFFER = 34962
_ELEMENT_ARRAY_BUFFER = 34963
_FLOAT, _UBYTE, _UINT = 5126, 5121, 5125


class _Builder:
    def __init__(self):
        self.bin = io.BytesIO()
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def _view(self, data: bytes, target: int | None) -> int:
        pad = (-self.bin.tell()) % 4
        self.bin.write(b"\0" * pad)
        off = self.bin.tell()
        self.bin.write(data)
        v = {"buffer": 0, "byteOffset": off, "byteLength": len(data)}
        if target:
            v["target"] = target
        self.views.append(v)
        return len(self.views) - 1

    def accessor(self, arr: np.ndarray, ctype: int, typ: str, target: int | None = _ARRAY_BUFFER,
                 normalized: bool = False, minmax: bool = False) -> int:
        arr = np.ascontiguousarray(arr)
        ncomp = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[typ]
        data = arr.tobytes()
        if ctype == _UBYTE and ncomp in (1, 3) and target == _ARRAY_BUFFER:
            # vertex attribute elements must be 4-byte aligned: pad each element
            stride_el = ncomp
            padded = np.zeros((len(arr), 4), np.uint8)
            padded[:, :stride_el] = arr.reshape(len(arr), stride_el)
            vi = self._view(padded.tobytes(), target)
            self.views[vi]["byteStride"] = 4
        else:
            vi = self._view(data, target)
        acc = {"bufferView": vi, "componentType": ctype, "count": int(len(arr)), "type": typ}
        if normalized:
            acc["normalized"] = True
        if minmax:
            a2 = arr.reshape(len(arr), -1)
            acc["min"] = [float(x) for x in a2.min(0)]
            acc["max"] = [float(x) for x in a2.max(0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1



def srgb_to_linear(rgb8) -> "np.ndarray":
    """(n, 3) uint8 sRGB -> (n, 3) float32 linear RGB in [0, 1] (the IEC 61966-2-1 transfer curve)."""
    import numpy as np

    c = np.asarray(rgb8, dtype=np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)

def site_to_gltf(p: np.ndarray) -> np.ndarray:
    """(n, 3) site frame (x east, y north, z up) -> glTF (x, y up, z = -north)."""
    return np.column_stack([p[:, 0], p[:, 2], -p[:, 1]])


def write_glb(meshes, texture: Path | None, out: Path, georef: dict, *, texture_format: str = "jpeg",
              jpeg_quality: int = 90, unlit: bool = True) -> dict:
    """Write ``out`` (.glb). Returns per-class vertex counts after the UV split."""
    b = _Builder()
    nodes, gl_meshes, stats = [], [], {}
    for cm in meshes:
        if cm.n_faces == 0:
            continue
        # one glTF vertex per distinct (vertex, uv) corner
        corner_v = cm.faces.reshape(-1).astype(np.int64)
        corner_uv = cm.corner_uv.reshape(-1, 2)
        key = np.column_stack([corner_v.astype(np.float64), corner_uv.astype(np.float64)])
        uniq, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
        inv = inv.ravel()
        src_v = corner_v[first]
        pos = site_to_gltf(cm.vertices[src_v]).astype(np.float32)
        nrm = site_to_gltf(cm.normals[src_v].astype(np.float64)).astype(np.float32)
        ln = np.linalg.norm(nrm, axis=1, keepdims=True)
        nrm = np.where(ln > 0, nrm / np.where(ln > 0, ln, 1), np.array([0, 1, 0], np.float32)).astype(np.float32)
        uv = corner_uv[first].astype(np.float32).copy()
        uv[:, 1] = 1.0 - uv[:, 1]
        col = srgb_to_linear(cm.colors[src_v])  # glTF vertex colours are linear; the palette is sRGB
        cls = cm.vertex_class[src_v].astype(np.uint8)
        idx = inv.astype(np.uint32)
        attrs = {
            "POSITION": b.accessor(pos, _FLOAT, "VEC3", minmax=True),
            "NORMAL": b.accessor(nrm, _FLOAT, "VEC3"),
            "TEXCOORD_0": b.accessor(uv, _FLOAT, "VEC2"),
            "COLOR_0": b.accessor(col, _FLOAT, "VEC3"),
            "_CLASS_ID": b.accessor(cls, _UBYTE, "SCALAR"),
        }
        ind = b.accessor(idx, _UINT, "SCALAR", target=_ELEMENT_ARRAY_BUFFER)
        ci = info(cm.class_id)
        gl_meshes.append({"name": cm.name, "primitives": [{"attributes": attrs, "indices": ind, "material": 0,
                                                           "mode": 4}]})
        nodes.append({"name": cm.name, "mesh": len(gl_meshes) - 1,
                      "extras": {"class_id": int(cm.class_id), "cityscapes_class": ci.name,
                                 "carla_tag": ci.carla_tag, "source_vertices_own": cm.own_vertices}})
        stats[cm.name] = {"vertices": int(len(pos)), "faces": cm.n_faces}
    material = {"name": "M_twinkit", "doubleSided": False,
                "pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 1.0}}
    ext_used = []
    if unlit:
        material["extensions"] = {"KHR_materials_unlit": {}}
        ext_used.append("KHR_materials_unlit")
    doc: dict = {
        "asset": {"version": "2.0", "generator": "twinkit-export",
                  "extras": {"twinkit:georeference": georef,
                             "axes": "glTF y up; glTF (x, y, z) = site (x east, z up, -y north)"}},
        "scene": 0,
        "scenes": [{"name": "Site", "nodes": list(range(len(nodes)))}],
        "nodes": nodes, "meshes": gl_meshes, "materials": [material],
    }
    if texture is not None:
        from PIL import Image

        img = Image.open(texture).convert("RGB")
        buf = io.BytesIO()
        if texture_format == "png":
            img.save(buf, format="PNG")
            mime = "image/png"
        else:
            img.save(buf, format="JPEG", quality=int(jpeg_quality))
            mime = "image/jpeg"
        iv = b._view(buf.getvalue(), None)
        doc["images"] = [{"bufferView": iv, "mimeType": mime, "name": "texture"}]
        doc["samplers"] = [{"magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 33071}]
        doc["textures"] = [{"source": 0, "sampler": 0}]
        material["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0, "texCoord": 0}
    if ext_used:
        doc["extensionsUsed"] = ext_used
    binary = b.bin.getvalue()
    binary += b"\0" * ((-len(binary)) % 4)
    doc["buffers"] = [{"byteLength": len(binary)}]
    doc["bufferViews"] = b.views
    doc["accessors"] = b.accessors
    js = json.dumps(doc, separators=(",", ":")).encode("utf-8")
    js += b" " * ((-len(js)) % 4)
    total = 12 + 8 + len(js) + 8 + len(binary)
    with open(out, "wb") as fh:
        fh.write(struct.pack("<III", 0x46546C67, 2, total))
        fh.write(struct.pack("<II", len(js), 0x4E4F534A))
        fh.write(js)
        fh.write(struct.pack("<II", len(binary), 0x004E4942))
        fh.write(binary)
    return stats

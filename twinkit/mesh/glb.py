"""The one glTF 2.0 binary (GLB) writer of twinkit.

- :class:`GlbBuilder` packs arrays into the binary chunk (4-byte aligned buffer views, accessors)
  and writes the container (``glTF`` header, JSON chunk, BIN chunk; atomically through a temporary file);
- :func:`write_textured_glb`: a scene of named, textured parts (the exporter's one node per class):
  POSITION, NORMAL, TEXCOORD_0, optionally COLOR_0 (appearance colours, linear float RGB),
  application colour attributes (``_CLASS_COLOR``: linear float RGB) and unsigned-byte attributes,
  vertices split where UV charts meet (glTF has one UV per vertex), one material with the texture
  embedded (JPEG or PNG) and optionally KHR_materials_unlit, and optionally KHR_materials_variants
  ("photo" = that material, "segmentation" = one flat, unlit material per part colour);
- :func:`write_colored_glb`: one light vertex-coloured mesh (the report's 3D view), colours as
  normalised uint16 RGBA, centred on the site (origin in the node's extras).

Colour convention of twinkit's GLBs: ``COLOR_0`` is appearance only (the texture colours, or absent),
because glTF multiplies the base colour by ``COLOR_0`` and every standard viewer draws it so; the
segmentation lives where it darkens nothing: the application attribute ``_CLASS_COLOR`` (the
CityScapes palette of each vertex's own label, linear), ``_CLASS_ID``, and, in the export, the
"segmentation" material variant.

Axes: glTF is y up; site-frame points (x east, y north, z up, metres) become glTF (x, z, -y)
(:func:`site_to_gltf`), a rotation, so viewers need no node transform; metres stay metres.
Vertex colours are linear in glTF; twinkit's colours are sRGB (:func:`srgb_to_linear`).
"""
from __future__ import annotations

import io
import json
import os
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ARRAY_BUFFER = 34962
ELEMENT_ARRAY_BUFFER = 34963
FLOAT, UBYTE, USHORT, UINT = 5126, 5121, 5123, 5125


def srgb_to_linear(rgb8) -> np.ndarray:
    """(n, 3) uint8 sRGB -> (n, 3) float32 linear RGB in [0, 1] (the IEC 61966-2-1 transfer curve)."""
    return _srgb_to_linear64(rgb8).astype(np.float32)


def _srgb_to_linear64(rgb8) -> np.ndarray:
    c = np.asarray(rgb8, dtype=np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def site_to_gltf(p: np.ndarray) -> np.ndarray:
    """(n, 3) site frame (x east, y north, z up) -> glTF (x, y up, z = -north)."""
    return np.column_stack([p[:, 0], p[:, 2], -p[:, 1]])


class GlbBuilder:
    """Binary chunk of a GLB under construction: ``accessor`` adds an array, ``write`` the file."""

    def __init__(self):
        self.bin = io.BytesIO()
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def view(self, data: bytes, target: int | None) -> int:
        """Append ``data`` as a buffer view (4-byte aligned); returns its index."""
        pad = (-self.bin.tell()) % 4
        self.bin.write(b"\0" * pad)
        off = self.bin.tell()
        self.bin.write(data)
        v = {"buffer": 0, "byteOffset": off, "byteLength": len(data)}
        if target:
            v["target"] = target
        self.views.append(v)
        return len(self.views) - 1

    def accessor(self, arr: np.ndarray, ctype: int, typ: str, target: int | None = ARRAY_BUFFER,
                 normalized: bool = False, minmax: bool = False) -> int:
        """Append ``arr`` ((count, ncomp) or (count,), already in the dtype of ``ctype``) as an accessor
        of glTF ``typ`` (SCALAR, VEC2, ...); returns its index. Unsigned-byte vertex attributes of 1 or 3
        components are padded to 4-byte elements (``byteStride`` 4), as glTF requires."""
        arr = np.ascontiguousarray(arr)
        ncomp = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[typ]
        if ctype == UBYTE and ncomp in (1, 3) and target == ARRAY_BUFFER:
            padded = np.zeros((len(arr), 4), np.uint8)
            padded[:, :ncomp] = arr.reshape(len(arr), ncomp)
            vi = self.view(padded.tobytes(), target)
            self.views[vi]["byteStride"] = 4
        else:
            vi = self.view(arr.tobytes(), target)
        acc = {"bufferView": vi, "componentType": ctype, "count": int(len(arr)), "type": typ}
        if normalized:
            acc["normalized"] = True
        if minmax:
            a2 = arr.reshape(len(arr), -1)
            acc["min"] = [float(x) for x in a2.min(0)]
            acc["max"] = [float(x) for x in a2.max(0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def write(self, path: Path, doc: dict) -> None:
        """Write the GLB: ``doc`` (the glTF JSON without buffers) gets ``buffers``, ``bufferViews`` and
        ``accessors`` appended. Written to a temporary file beside ``path``, then renamed."""
        path = Path(path)
        binary = self.bin.getvalue()
        binary += b"\0" * ((-len(binary)) % 4)
        doc["buffers"] = [{"byteLength": len(binary)}]
        doc["bufferViews"] = self.views
        doc["accessors"] = self.accessors
        js = json.dumps(doc, separators=(",", ":")).encode("utf-8")
        js += b" " * ((-len(js)) % 4)
        total = 12 + 8 + len(js) + 8 + len(binary)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
        with open(tmp, "wb") as fh:
            fh.write(struct.pack("<4sII", b"glTF", 2, total))
            fh.write(struct.pack("<I4s", len(js), b"JSON"))
            fh.write(js)
            fh.write(struct.pack("<I4s", len(binary), b"BIN\0"))
            fh.write(binary)
        tmp.replace(path)


@dataclass
class GlbPart:
    """One node + mesh of :func:`write_textured_glb`.

    vertices (n, 3) float64 site frame; faces (m, 3) int; normals (n, 3); corner_uv (m, 3, 2)
    (v up, OBJ convention); colors: (n, 3) uint8 sRGB appearance colours written as ``COLOR_0``
    (which multiplies the texture in every viewer), or None for none; color_attrs: (n, 3) uint8 sRGB
    colours by application attribute name (``_CLASS_COLOR``), written linear; ubyte_attrs: extra
    per-vertex (n,) uint8 attributes by glTF name (application names start with ``_``); extras: the
    node's ``extras``; variant_color: sRGB colour of this part's flat material in the
    "segmentation" variant (with ``write_textured_glb(..., variants=True)``)."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    corner_uv: np.ndarray
    colors: np.ndarray | None = None
    ubyte_attrs: dict[str, np.ndarray] = field(default_factory=dict)
    extras: dict = field(default_factory=dict)
    color_attrs: dict[str, np.ndarray] = field(default_factory=dict)
    variant_color: tuple[int, int, int] | None = None


VARIANTS = ("photo", "segmentation")


def write_textured_glb(out: Path, parts, texture: Path | None, *, generator: str, asset_extras: dict | None = None,
                       texture_format: str = "jpeg", jpeg_quality: int = 90, unlit: bool = True,
                       variants: bool = False) -> dict:
    """Write ``out`` (.glb): one node per :class:`GlbPart` with faces (parts without faces are skipped),
    all sharing one material whose base colour is ``texture`` (embedded as JPEG or PNG).
    With ``variants``, KHR_materials_variants offers "photo" (that material) and "segmentation"
    (per part, a flat material of its ``variant_color``, unlit when ``unlit``).
    Returns per-part ``{"vertices", "faces"}`` counts after the UV split."""
    b = GlbBuilder()
    nodes, gl_meshes, stats = [], [], {}
    seg_materials: dict[tuple, int] = {}  # variant colour -> material index (0 is the texture material)
    materials_extra: list[dict] = []
    for part in parts:
        n_faces = int(len(part.faces))
        if n_faces == 0:
            continue
        prim, n_vertices = _textured_primitive(b, part)
        if variants:
            _add_segmentation_variant(prim, part, seg_materials, materials_extra, unlit)
        gl_meshes.append({"name": part.name, "primitives": [prim]})
        nodes.append({"name": part.name, "mesh": len(gl_meshes) - 1, "extras": part.extras})
        stats[part.name] = {"vertices": n_vertices, "faces": n_faces}
    material: dict = {"name": "M_twinkit", "doubleSided": False,
                      "pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 1.0}}
    ext_used = []
    if unlit:
        material["extensions"] = {"KHR_materials_unlit": {}}
        ext_used.append("KHR_materials_unlit")
    asset: dict = {"version": "2.0", "generator": generator}
    if asset_extras is not None:
        asset["extras"] = asset_extras
    doc: dict = {
        "asset": asset,
        "scene": 0,
        "scenes": [{"name": "Site", "nodes": list(range(len(nodes)))}],
        "nodes": nodes, "meshes": gl_meshes, "materials": [material] + materials_extra,
    }
    if variants:
        ext_used.append("KHR_materials_variants")
        doc["extensions"] = {"KHR_materials_variants": {"variants": [{"name": v} for v in VARIANTS]}}
    if texture is not None:
        _embed_texture(b, doc, material, texture, texture_format, jpeg_quality)
    if ext_used:
        doc["extensionsUsed"] = ext_used
    b.write(Path(out), doc)
    return stats


def _textured_primitive(b: GlbBuilder, part) -> tuple[dict, int]:
    """A part's triangle primitive (material 0) with one glTF vertex per distinct (vertex, uv) corner: positions and
    unit normals in the glTF frame (float32), UVs flipped to glTF's top-left origin, linear colours and the part's
    extra attributes; returns it and its vertex count."""
    corner_v = part.faces.reshape(-1).astype(np.int64)
    corner_uv = part.corner_uv.reshape(-1, 2)
    corner = np.column_stack([corner_v.astype(np.float64), corner_uv.astype(np.float64)])
    _, first, inv = np.unique(corner, axis=0, return_index=True, return_inverse=True)
    inv = inv.ravel()
    src_v = corner_v[first]
    pos = site_to_gltf(part.vertices[src_v]).astype(np.float32)
    nrm = site_to_gltf(part.normals[src_v].astype(np.float64)).astype(np.float32)
    ln = np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = np.where(ln > 0, nrm / np.where(ln > 0, ln, 1), np.array([0, 1, 0], np.float32)).astype(np.float32)
    uv = corner_uv[first].astype(np.float32).copy()
    uv[:, 1] = 1.0 - uv[:, 1]
    attrs = {
        "POSITION": b.accessor(pos, FLOAT, "VEC3", minmax=True),
        "NORMAL": b.accessor(nrm, FLOAT, "VEC3"),
        "TEXCOORD_0": b.accessor(uv, FLOAT, "VEC2"),
    }
    if part.colors is not None:
        attrs["COLOR_0"] = b.accessor(srgb_to_linear(part.colors[src_v]), FLOAT, "VEC3")
    for name, a in part.color_attrs.items():
        attrs[name] = b.accessor(srgb_to_linear(np.asarray(a)[src_v]), FLOAT, "VEC3")
    for name, a in part.ubyte_attrs.items():
        attrs[name] = b.accessor(np.asarray(a)[src_v].astype(np.uint8), UBYTE, "SCALAR")
    ind = b.accessor(inv.astype(np.uint32), UINT, "SCALAR", target=ELEMENT_ARRAY_BUFFER)
    return {"attributes": attrs, "indices": ind, "material": 0, "mode": 4}, int(len(pos))


def _add_segmentation_variant(prim: dict, part, seg_materials: dict[tuple, int], materials_extra: list[dict],
                              unlit: bool) -> None:
    """Map ``prim`` to material 0 in the "photo" variant and to a flat material of the part's ``variant_color``
    (created once per colour in ``materials_extra``) in the "segmentation" variant."""
    key = tuple(int(c) for c in (part.variant_color or (128, 128, 128)))
    if key not in seg_materials:
        lin = [float(x) for x in _srgb_to_linear64(np.array([key]))[0]]
        m = {"name": "M_segmentation_%02x%02x%02x" % key,
             "pbrMetallicRoughness": {"baseColorFactor": lin + [1.0], "metallicFactor": 0.0,
                                      "roughnessFactor": 1.0}}
        if unlit:
            m["extensions"] = {"KHR_materials_unlit": {}}
        materials_extra.append(m)
        seg_materials[key] = len(materials_extra)  # index after M_twinkit
    prim["extensions"] = {"KHR_materials_variants": {"mappings": [
        {"material": 0, "variants": [VARIANTS.index("photo")]},
        {"material": seg_materials[key], "variants": [VARIANTS.index("segmentation")]}]}}


def _embed_texture(b: GlbBuilder, doc: dict, material: dict, texture: Path, texture_format: str,
                   jpeg_quality: int) -> None:
    """Embed ``texture`` (as PNG, or JPEG of ``jpeg_quality``) as the base colour of ``material``."""
    from PIL import Image

    img = Image.open(texture).convert("RGB")
    buf = io.BytesIO()
    if texture_format == "png":
        img.save(buf, format="PNG")
        mime = "image/png"
    else:
        img.save(buf, format="JPEG", quality=int(jpeg_quality))
        mime = "image/jpeg"
    iv = b.view(buf.getvalue(), None)
    doc["images"] = [{"bufferView": iv, "mimeType": mime, "name": "texture"}]
    doc["samplers"] = [{"magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 33071}]
    doc["textures"] = [{"source": 0, "sampler": 0}]
    material["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0, "texCoord": 0}


def write_colored_glb(path: Path, xyz: np.ndarray, faces: np.ndarray, colors: np.ndarray | None,
                      seg_colors: np.ndarray | None, generator: str = "twinkit.report") -> None:
    """A GLB of one triangle mesh (``xyz`` (n, 3) site frame, ``faces`` (m, 3)) in glTF's frame, moved so
    that the site point (centre of the box in x, y; lowest z) is the origin (kept in the node's
    ``extras.site_origin_m``).

    ``COLOR_0`` holds the texture colours ``colors`` ((n, 3) uint8 sRGB), what any viewer shows; the
    segmentation colours ``seg_colors`` go to the application attribute ``_CLASS_COLOR`` (the convention
    of twinkit's exported GLBs), which darkens nothing. Colours are stored linear (glTF), as normalised
    uint16 RGBA."""
    centre = (xyz.min(0) + xyz.max(0)) / 2
    centre[2] = xyz[:, 2].min()
    p = xyz - centre
    pos = np.column_stack([p[:, 0], p[:, 2], -p[:, 1]]).astype("<f4")

    def col(c):
        rgba = np.ones((len(c), 4))
        rgba[:, :3] = _srgb_to_linear64(c[:, :3])
        return np.round(rgba * 65535).astype("<u2")

    b = GlbBuilder()
    prim_attrs = {"POSITION": b.accessor(pos, FLOAT, "VEC3", minmax=True)}
    if colors is not None:
        prim_attrs["COLOR_0"] = b.accessor(col(colors), USHORT, "VEC4", normalized=True)
    if seg_colors is not None:
        prim_attrs["_CLASS_COLOR"] = b.accessor(col(seg_colors), USHORT, "VEC4", normalized=True)
    idx = np.ascontiguousarray(faces, dtype="<u4").ravel()
    ind = b.accessor(idx, UINT, "SCALAR", target=ELEMENT_ARRAY_BUFFER)
    doc = {
        "asset": {"version": "2.0", "generator": generator},
        "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "twin", "extras": {"site_origin_m": [float(x) for x in centre]}}],
        "meshes": [{"primitives": [{"attributes": prim_attrs, "indices": ind, "material": 0}]}],
        "materials": [{"name": "twin", "doubleSided": True,
                       "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0.0,
                                                "roughnessFactor": 1.0}}],
    }
    b.write(Path(path), doc)


def decimate(xyz: np.ndarray, faces: np.ndarray, max_faces: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """At most ``max_faces`` faces for a light view: (vertices, faces, index of the nearest original vertex
    of each new vertex). fast-simplification's quadric decimation; without it a random subset of faces."""
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

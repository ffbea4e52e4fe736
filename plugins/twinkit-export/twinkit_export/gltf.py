"""The export's GLB: the class meshes as one scene, written by the one GLB writer (twinkit.mesh.glb).

- one node + mesh per class, named like the FBX objects; node extras: class_id, cityscapes_class,
  carla_tag; asset extras: the site georeference;
- axes: glTF is y up; vertices are converted from the site frame (x east, y north, z up) to
  glTF (x, z, -y), a rotation, so viewers need no node transform; metres stay metres;
- attributes: POSITION, NORMAL, TEXCOORD_0 (v flipped: glTF UV origin is top left), _CLASS_COLOR
  (the CityScapes palette of each vertex's own label, converted from sRGB to linear, float RGB) and
  _CLASS_ID (unsigned byte, each vertex's own label); vertices are split where UV charts meet (glTF
  has one UV per vertex). No COLOR_0: glTF multiplies the base colour by COLOR_0, so a palette
  there darkened the photo texture in every standard viewer (rendered at 37 % of its brightness on the demo);
- one material with the texture as baseColorTexture (embedded, PNG or JPEG) and
  KHR_materials_unlit (the texture already holds the captured light);
- KHR_materials_variants: "photo" (the texture, also the default) and "segmentation" (per class a
  flat unlit material of its CityScapes colour), which variant-aware viewers list (Babylon.js,
  model-viewer, the Khronos sample viewer).
"""
from __future__ import annotations

from pathlib import Path

from twinkit.mesh.glb import GlbPart, write_textured_glb

from .classes import info


def write_glb(meshes, texture: Path | None, out: Path, georef: dict, *, texture_format: str = "jpeg",
              jpeg_quality: int = 90, unlit: bool = True, variants: bool = True) -> dict:
    """Write ``out`` (.glb) from the class meshes. Returns per-class vertex counts after the UV split."""
    parts = []
    for cm in meshes:
        ci = info(cm.class_id)
        parts.append(GlbPart(name=cm.name, vertices=cm.mesh.vertices, faces=cm.mesh.faces, normals=cm.mesh.normals,
                             corner_uv=cm.mesh.corner_uv, colors=None, color_attrs={"_CLASS_COLOR": cm.mesh.colors},
                             ubyte_attrs={"_CLASS_ID": cm.mesh.attrs["class_id"]}, variant_color=ci.color,
                             extras={"class_id": int(cm.class_id), "cityscapes_class": ci.name,
                                     "carla_tag": ci.carla_tag, "source_vertices_own": cm.own_vertices}))
    asset_extras = {"twinkit:georeference": georef,
                    "axes": "glTF y up; glTF (x, y, z) = site (x east, z up, -y north)"}
    return write_textured_glb(out, parts, texture, generator="twinkit-export", asset_extras=asset_extras,
                              texture_format=texture_format, jpeg_quality=jpeg_quality, unlit=unlit,
                              variants=variants)

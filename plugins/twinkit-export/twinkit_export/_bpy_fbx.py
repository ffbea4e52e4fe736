"""FBX writer run inside Blender-as-a-module (``python -m twinkit_export._bpy_fbx job.json``).

Runs in its own process: bpy keeps global state, prints a lot and holds memory; the step that
starts it only sees a log file and an exit code. The job file names the class PLYs, the texture
and the output; see ``fbx.write_fbx``.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np


def _material(bpy, name: str, texture: str | None):
    mat = bpy.data.materials.new(name)
    # Blender 5 always uses nodes; touching Material.use_nodes there only prints a DeprecationWarning
    if bpy.app.version < (5, 0, 0) and hasattr(mat, "use_nodes"):
        try:
            mat.use_nodes = True
        except Exception:
            pass
    nt = mat.node_tree
    bsdf = next((n for n in nt.nodes if n.type == "BSDF_PRINCIPLED"), None)
    if bsdf is None:
        bsdf = nt.nodes.new("ShaderNodeBsdfPrincipled")
        out = next((n for n in nt.nodes if n.type == "OUTPUT_MATERIAL"), None) or nt.nodes.new("ShaderNodeOutputMaterial")
        nt.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    bsdf.inputs["Roughness"].default_value = 1.0
    bsdf.inputs["Metallic"].default_value = 0.0
    if texture:
        img = bpy.data.images.load(texture, check_existing=True)
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = img
        nt.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    return mat


def _mesh_object(bpy, cm, mat, georef: dict):
    n, m = cm.mesh.n_vertices, cm.mesh.n_faces
    me = bpy.data.meshes.new(cm.name)
    me.vertices.add(n)
    me.vertices.foreach_set("co", cm.mesh.vertices.astype(np.float32).ravel())
    me.loops.add(3 * m)
    me.loops.foreach_set("vertex_index", cm.mesh.faces.astype(np.int32).ravel())
    me.polygons.add(m)
    me.polygons.foreach_set("loop_start", np.arange(0, 3 * m, 3, dtype=np.int32))
    me.update(calc_edges=True)
    uv = me.uv_layers.new(name="UVMap")
    uv.data.foreach_set("uv", cm.mesh.corner_uv.astype(np.float32).ravel())
    rgba = np.ones((n, 4), np.float32)
    rgba[:, :3] = cm.mesh.colors / 255.0
    seg = me.color_attributes.new("segmentation", "BYTE_COLOR", "POINT")
    seg.data.foreach_set("color_srgb", rgba.ravel())
    cid = np.ones((n, 4), np.float32)
    cid[:, :3] = (cm.mesh.attrs["class_id"].astype(np.float32) / 255.0)[:, None]
    cls = me.color_attributes.new("class_id", "BYTE_COLOR", "POINT")
    cls.data.foreach_set("color_srgb", cid.ravel())
    me.color_attributes.active_color = seg
    try:
        me.color_attributes.render_color_index = 0
    except Exception:
        pass
    ia = me.attributes.new("class_id_int", "INT", "POINT")
    ia.data.foreach_set("value", cm.mesh.attrs["class_id"].astype(np.int32))
    me.polygons.foreach_set("use_smooth", np.ones(m, bool))
    if cm.mesh.normals is not None and n:
        me.normals_split_custom_set_from_vertices(cm.mesh.normals.astype(np.float32).reshape(-1, 3))
    me.materials.append(mat)
    ob = bpy.data.objects.new(cm.name, me)
    ob["class_id"] = int(cm.class_id)
    ob["cityscapes_class"] = cm.cityscapes
    ob["carla_tag"] = cm.carla_tag
    for k, v in georef.items():
        ob[f"geo_{k}"] = v
    return ob


def _relative_texture_paths() -> None:
    """Make the FBX exporter write the texture's package-relative path into ``FileName`` too.

    Blender's exporter stores ``RelativeFilename`` (relative to the FBX) and ``FileName`` = that path
    made absolute against the output folder, which for a step is a temporary build folder that no
    longer exists afterwards. Unreal's importer tries ``FileName``, then ``<fbx folder>/RelativeFilename``,
    so the relative path in both fields loses nothing and leaks no build path.
    """
    import io_scene_fbx.export_fbx_bin as fbx_bin

    orig = fbx_bin._gen_vid_path

    def gen_vid_path(img, scene_data):
        _abs, rel = orig(img, scene_data)
        return rel, rel

    fbx_bin._gen_vid_path = gen_vid_path


def _export_one(bpy, job: dict, out: dict) -> None:
    from twinkit_export.classes import info
    from twinkit_export.classmesh import read_class_ply

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.unit_settings.system = "METRIC"
    scene.unit_settings.scale_length = 1.0
    mat = _material(bpy, job.get("material_name", "M_twinkit"), job.get("texture"))
    names = out.get("names") or {}
    for p in out["meshes"]:
        cm = read_class_ply(Path(p))
        ci = info(cm.class_id)
        cm.cityscapes = ci.name
        cm.carla_tag = ci.carla_tag
        cm.name = names.get(p, cm.name)
        if cm.mesh.n_faces == 0:
            continue
        ob = _mesh_object(bpy, cm, mat, job.get("georef", {}))
        scene.collection.objects.link(ob)
        if ob.name != cm.name:
            raise RuntimeError(f"Blender renamed object {cm.name!r} to {ob.name!r}")
    bpy.ops.export_scene.fbx(
        filepath=out["out"],
        use_selection=False,
        object_types={"MESH"},
        global_scale=1.0,
        apply_unit_scale=True,
        apply_scale_options=job.get("apply_scale_options", "FBX_SCALE_UNITS"),
        axis_forward=job.get("axis_forward", "Y"),
        axis_up=job.get("axis_up", "Z"),
        bake_space_transform=False,
        use_mesh_modifiers=False,
        mesh_smooth_type="OFF",
        use_custom_props=True,
        colors_type="SRGB",
        prioritize_active_color=True,
        add_leaf_bones=False,
        bake_anim=False,
        path_mode="COPY" if job.get("embed_texture") else "RELATIVE",
        embed_textures=bool(job.get("embed_texture")),
    )
    if out.get("blend"):
        bpy.ops.wm.save_as_mainfile(filepath=out["blend"], compress=True)


def main(job_path: str) -> int:
    """One FBX (``meshes``/``out``/``blend``) or several (``outputs``: [{meshes, out, names}]) per job."""
    job = json.loads(Path(job_path).read_text())
    import bpy  # heavy: only in this process

    _relative_texture_paths()
    outputs = job.get("outputs") or [{"meshes": job["meshes"], "out": job["out"], "blend": job.get("blend")}]
    for out in outputs:
        _export_one(bpy, job, out)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))

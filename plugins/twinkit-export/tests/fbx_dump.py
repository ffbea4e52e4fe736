"""Dump an FBX file as JSON with ufbx (run as a subprocess: the young ufbx bindings can crash)."""
import json
import sys

import numpy as np
import gc

import ufbx

gc.disable()  # ufbx 0.0.5 bindings: collecting wrapper objects mid-read can crash


def main(path: str, out: str) -> None:
    scene = ufbx.load_file(path)
    axes = scene.settings.axes
    materials = {}
    texture_files = []
    for mm in scene.materials:
        materials[mm.name] = []
        for t2 in mm.textures:
            tx = t2.texture
            materials[mm.name].append([t2.material_prop, tx.relative_filename])
            # the file names as stored in the file (FileName, RelativeFilename), not resolved by ufbx
            texture_files.append([bytes(tx.raw_absolute_filename).decode("utf-8", "replace"),
                                  bytes(tx.raw_relative_filename).decode("utf-8", "replace")])
    res = {"materials": materials, "texture_files": texture_files, "unit_meters": scene.settings.unit_meters,
           "axes": [int(axes.right), int(axes.up), int(axes.front)], "nodes": {}}
    for node in scene.nodes:
        me = node.mesh
        if me is None:
            continue
        t = node.local_transform
        pos = np.array([[p.x, p.y, p.z] for p in me.vertex_position.values])
        uvs = me.vertex_uv
        uv_vals = np.array([[p.x, p.y] for p in uvs.values])
        uv_idx = np.array(list(uvs.indices))
        vi = np.array(list(me.vertex_indices))
        colors = {}
        for cset in list(me.color_sets):
            vc = cset.vertex_color
            vals = np.array([[c.x, c.y, c.z] for c in vc.values])
            idx = np.array(list(vc.indices))
            per_vertex = np.zeros((me.num_vertices, 3))
            per_vertex[vi] = vals[idx]
            colors[cset.name] = np.round(per_vertex * 255).astype(int).tolist()
        mats = len(me.materials)  # (touching a shared material object twice crashes ufbx 0.0.5)
        res["nodes"][node.name] = {
            "num_vertices": me.num_vertices, "num_faces": me.num_faces,
            "scale": [t.scale.x, t.scale.y, t.scale.z],
            "positions": pos.tolist(), "corner_uv": uv_vals[uv_idx].tolist(),
            "uv_sets": [u.name for u in me.uv_sets], "colors": colors, "n_materials": mats,
        }
    with open(out, "w") as fh:
        json.dump(res, fh)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])

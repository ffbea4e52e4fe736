"""FBX export through Blender (bpy), in a subprocess.

Conventions (see docs/export.md):
- one object per class, named exactly as ``classes.CLASSES[...].carla_name``; one shared material
  ``M_twinkit`` whose Principled BSDF base colour is the texture atlas (FBX: DiffuseColor texture);
- metres: the Blender scene is metric with scale 1, exported with ``apply_unit_scale`` (the FBX
  header then states its unit, and Unreal's importer, run by CARLA with ``bConvertSceneUnit``,
  converts to centimetres itself);
- axes: Z up, front -Y (Blender ``axis_up='Z', axis_forward='Y'``), right-handed: the site frame
  unchanged (x east, y north, z up) and already Unreal's FBX target system, so Unreal's
  ``bConvertScene`` applies no rotation, only its right- to left-handed mirror of y — the same
  mirror CARLA applies to OpenDRIVE coordinates, so the mesh and the roads stay aligned.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path


class FbxExportError(RuntimeError):
    pass


def write_fbx(mesh_files: list[Path], texture: Path | None, out: Path, *, georef: dict | None = None,
              embed_texture: bool = False, python: str = "", log_path: Path | None = None,
              blend: Path | None = None, timeout_s: float = 3600) -> None:
    """Write ``out`` (FBX 7.4 binary) from class PLYs; Blender runs in ``python`` (default: this interpreter)."""
    out = Path(out)
    job = {
        "meshes": [str(Path(p).resolve()) for p in mesh_files],
        "texture": str(Path(texture).resolve()) if texture else None,
        "out": str(out.resolve()),
        "embed_texture": bool(embed_texture),
        "georef": {k: v for k, v in (georef or {}).items() if isinstance(v, (str, int, float))},
        "blend": str(Path(blend).resolve()) if blend else None,
    }
    job_path = out.with_suffix(".job.json")
    job_path.write_text(json.dumps(job, indent=1))
    log_path = Path(log_path) if log_path else out.with_suffix(".bpy.log")
    env = dict(os.environ)
    pkg_root = str(Path(__file__).resolve().parent.parent)
    env["PYTHONPATH"] = pkg_root + os.pathsep + env.get("PYTHONPATH", "")
    cmd = [python or sys.executable, "-m", "twinkit_export._bpy_fbx", str(job_path)]
    try:
        with open(log_path, "w") as log:
            proc = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, timeout=timeout_s)
    finally:
        job_path.unlink(missing_ok=True)
    if proc.returncode != 0 or not out.exists():
        tail = log_path.read_text(errors="replace")[-3000:] if log_path.exists() else ""
        if "No module named 'bpy'" in tail:
            raise FbxExportError(
                "the FBX exporter needs Blender as a Python module: pip install bpy==5.0.1 "
                "(see docs/export.md), or set the fbx exporter's python= to an interpreter that has it")
        raise FbxExportError(f"Blender FBX export failed (exit {proc.returncode}); log {log_path}:\n{tail}")

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
import re
import subprocess
import sys
from pathlib import Path


class FbxExportError(RuntimeError):
    pass


ENV_PYTHON = "TWINKIT_BPY_PYTHON"


def bpy_python() -> str:
    """The interpreter that runs Blender's bpy: ``$TWINKIT_BPY_PYTHON``, else the one running twinkit.

    An executable comes from the environment, never from a config file (a site or recipe is data).
    """
    exe = os.environ.get(ENV_PYTHON, "")
    if exe and not (Path(exe).is_file() and os.access(exe, os.X_OK)):
        raise FbxExportError(f"{ENV_PYTHON}={exe} is not an executable file; unset it or point it at a Python with bpy")
    return exe


def write_fbx(mesh_files: list[Path], texture: Path | None, out: Path, *, georef: dict | None = None,
              embed_texture: bool = False, python: str = "", log_path: Path | None = None,
              blend: Path | None = None, timeout_s: float = 3600) -> None:
    """Write ``out`` (FBX 7.4 binary) from class PLYs; Blender runs in ``python`` (default: this interpreter)."""
    out = Path(out)
    _run_job({"meshes": [str(Path(p).resolve()) for p in mesh_files], "out": str(out.resolve()),
              "blend": str(Path(blend).resolve()) if blend else None},
             texture, out, georef=georef, embed_texture=embed_texture, python=python, log_path=log_path,
             timeout_s=timeout_s, expect=[out])


def write_fbx_set(outputs: list[tuple[Path, list[Path], dict[Path, str]]], texture: Path | None, *,
                  georef: dict | None = None, python: str = "", log_path: Path | None = None,
                  timeout_s: float = 3600) -> None:
    """Several FBX files in one Blender run: ``(out, class PLYs, {PLY: object name})`` each.

    Every file gets the same material ``M_twinkit`` with ``texture`` (referenced by its path
    relative to the FBX); object names default to the class names of the PLYs.
    """
    if not outputs:
        return
    first = Path(outputs[0][0])
    job = {"outputs": [{"out": str(Path(o).resolve()), "meshes": [str(Path(p).resolve()) for p in files],
                        "names": {str(Path(p).resolve()): n for p, n in (names or {}).items()}}
                       for o, files, names in outputs]}
    _run_job(job, texture, first, georef=georef, embed_texture=False, python=python, log_path=log_path,
             timeout_s=timeout_s, expect=[Path(o) for o, _, _ in outputs])


#: What ``import bpy`` prints on every start with NumPy 2: the bpy wheel's built-in audio module
#: (audaspace's ``aud``) was compiled against NumPy 1.x, so NumPy 2's ABI guard prints its warning with
#: a traceback, the import of ``aud`` fails and Blender prints "Unable to initialise audio". Nothing
#: else in bpy uses NumPy's C API (the FBX add-on uses NumPy from Python, which works), and the
#: export needs no audio, so the cause cannot be fixed from here short of NumPy 1.x for the bpy
#: interpreter (``TWINKIT_BPY_PYTHON``). The block is replaced by one line in bpy.log; any other
#: output, another traceback included, is kept as it is.
_BPY_NUMPY_NOISE = re.compile(
    r"\n?A module that was compiled using NumPy 1\.x cannot be run in\n.*?"
    r"Unable to initialise audio\nImportError: numpy\.core\.multiarray failed to import\n", re.S)
BPY_NUMPY_NOTE = ("bpy: audio off (its audio module was built for NumPy 1.x; NumPy's ABI warning removed "
                  "by twinkit, see twinkit_export/fbx.py); the export does not use audio\n")


def clean_log(log_path: Path) -> None:
    """Replace the known, harmless NumPy-ABI block of ``import bpy`` in ``log_path`` by one line."""
    try:
        text = log_path.read_text(errors="replace")
    except OSError:
        return
    m = _BPY_NUMPY_NOISE.search(text)
    if m and "Traceback" in m.group(0) and m.group(0).count("Unable to initialise audio") == 1:
        log_path.write_text(text[:m.start()] + BPY_NUMPY_NOTE + text[m.end():])


def _run_job(job: dict, texture: Path | None, out: Path, *, georef: dict | None, embed_texture: bool, python: str,
             log_path: Path | None, timeout_s: float, expect: list[Path]) -> None:
    job = {**job,
           "texture": str(Path(texture).resolve()) if texture else None,
           "embed_texture": bool(embed_texture),
           "georef": {k: v for k, v in (georef or {}).items() if isinstance(v, (str, int, float))}}
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
    clean_log(log_path)
    if proc.returncode != 0 or not all(Path(p).exists() for p in expect):
        tail = log_path.read_text(errors="replace")[-3000:] if log_path.exists() else ""
        if "No module named 'bpy'" in tail:
            raise FbxExportError(
                "the FBX exporter needs Blender as a Python module: pip install bpy==5.0.1 "
                f"(see docs/export.md), or set {ENV_PYTHON}=<an interpreter that has it>")
        raise FbxExportError(f"Blender FBX export failed (exit {proc.returncode}); log {log_path}:\n{tail}")

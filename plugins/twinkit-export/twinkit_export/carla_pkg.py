"""CARLA 0.9.16 import package and spawn points from the OpenDRIVE driving lanes.

Package layout (what ``make import`` reads; ``Util/BuildTools/Import.py`` takes the package name
from the JSON file name, imports ``source`` relative to the JSON, copies ``xodr`` to
``Content/<Package>/Maps/<name>/OpenDrive/<name>.xodr``)::

    Import/<Package>/<Package>.json   {"maps": [{name, source, use_carla_materials, xodr}], "props": []}
    Import/<Package>/<Map>.fbx        the per-class FBX
    Import/<Package>/<texture>.png    the texture the FBX references (relative path)
    Import/<Package>/<Map>.xodr       the aligned OpenDRIVE (site frame)
    Import/<Package>/README.md
    spawn_points.json                 beside Import/, not in it: Import.py treats *every* .json file
                                      under Import/ as a package description
"""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

from .classes import CARLA_NAME_KEYS


class PackageError(ValueError):
    pass


def check_names(package: str, map_name: str) -> None:
    for what, name in (("package", package), ("map", map_name)):
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", name or ""):
            raise PackageError(f"{what} name {name!r}: use letters, digits and '_' (starting with a letter)")
        for key in CARLA_NAME_KEYS:
            if key in name:
                raise PackageError(f"{what} name {name!r} contains {key!r}, which CARLA's import uses to tag meshes; "
                                   f"choose another name")


def load_map(xodr_text: str, name: str):
    """carla.Map parsed offline; raises PackageError when the file has no driving lane."""
    import carla

    if "<OpenDRIVE" not in xodr_text:
        raise PackageError("not an OpenDRIVE file (no <OpenDRIVE> element)")
    m = carla.Map(name, xodr_text)
    return m


def spawn_points(cmap, spacing_m: float = 20.0, height_m: float = 0.5, skip_junctions: bool = True) -> list[dict]:
    """Spawn points on driving lanes, every ``spacing_m`` along each lane, raised by ``height_m``.

    CARLA coordinates (``carla`` block) are what ``carla.Transform`` takes: metres, Unreal's
    left-handed frame (y = -north). ``site`` gives the same point in the site frame (y north) with
    the heading counter-clockwise from east.
    """
    import carla

    out = []
    seen = set()
    for w in cmap.generate_waypoints(float(spacing_m)):
        if w.lane_type != carla.LaneType.Driving:
            continue
        if skip_junctions and w.is_junction:
            continue
        t = w.transform
        key = (w.road_id, w.section_id, w.lane_id, round(w.s, 2))
        if key in seen:
            continue
        seen.add(key)
        x, y, z = t.location.x, t.location.y, t.location.z + height_m
        pitch, yaw, roll = (_wrap180(a) for a in (t.rotation.pitch, t.rotation.yaw, t.rotation.roll))
        out.append({
            "road_id": int(w.road_id), "section_id": int(w.section_id), "lane_id": int(w.lane_id),
            "s": round(float(w.s), 3),
            "carla": {"x": round(x, 3), "y": round(y, 3), "z": round(z, 3),
                      "pitch": round(pitch, 3), "yaw": round(yaw, 3), "roll": round(roll, 3)},
            "site": {"x": round(x, 3), "y": round(-y, 3), "z": round(z, 3),
                     "heading_deg": round(_wrap180(-yaw), 3)},
        })
    return out


def _wrap180(a: float) -> float:
    """Angle in degrees folded into (-180, 180]."""
    a = math.fmod(float(a), 360.0)
    if a > 180.0:
        a -= 360.0
    elif a <= -180.0:
        a += 360.0
    return 0.0 if abs(a) < 1e-9 else a


def xodr_georeference(xodr_text: str) -> str | None:
    m = re.search(r"<geoReference>\s*(?:<!\[CDATA\[)?(.*?)(?:\]\]>)?\s*</geoReference>", xodr_text, re.S)
    return m.group(1).strip() if m else None


README = """# CARLA import package `{package}`

Made by twinkit (`carla_package` exporter) for CARLA {carla_version} built from source.

Files: `{package}.json` (the package description `make import` reads), `{map}.fbx` (the site
mesh, one object per semantic class, metres, Z up), `{texture}` (its texture, referenced by the
FBX by relative path), `{map}.xodr` (the road network, same local frame as the mesh).
`../../spawn_points.json` (beside `Import/`, since `make import` reads every `.json` under
`Import/` as a package description) holds {n_spawn} spawn points on driving lanes for scripts;
CARLA also makes its own spawners from the OpenDRIVE during import.

## Import

1. Copy this folder into `<carla>/Import/` so that it reads `<carla>/Import/{package}/{package}.json`.
2. From the CARLA root: `make import`. The package name comes from `{package}.json` (a
   package JSON overrides `--package=` arguments): map `{map}`, source `./{map}.fbx`, OpenDRIVE `./{map}.xodr`,
   `use_carla_materials: {use_carla_materials}` (false keeps the captured texture instead of
   replacing road, sidewalk and terrain materials by CARLA's).
3. `make launch`, open `Content/{package}/Maps/{map}`, or package it with
   `make package ARGS="--packages={package}"`.

## Semantic tags

The import moves each mesh by name: `Road_Road` -> Road (Roads), `Road_Sidewalk` -> SideWalk
(Sidewalks), `Terrain` -> Terrain; every other mesh lands in `Static/Terrain` too and is tagged
Terrain. To give a class its own tag, move its mesh in the editor to
`Content/{package}/Static/<Folder>/{map}/`:

{table}

## Frames

{frames}
"""


def _site_frames(georef: str) -> str:
    return (f"Mesh and OpenDRIVE share the site frame (x east, y north, z up, metres, origin at the base\n"
            f"point {georef}). Unreal mirrors y on import of both, so they stay aligned.")


def write_package(folder: Path, *, package: str, map_name: str, fbx: Path, texture: Path | None, xodr_text: str,
                  spawn: list[dict], use_carla_materials: bool, georef: dict, classes_present: list,
                  carla_version: str = "0.9.16", frames=None) -> Path:
    """Write ``folder/Import/<package>/...``; returns the package folder.

    ``frames(georef_text) -> str``: the README's frame section (default: the site frame).
    """
    import shutil

    from .classes import info

    pkg = Path(folder) / "Import" / package
    pkg.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(fbx, pkg / f"{map_name}.fbx")
    tex_name = None
    if texture is not None and Path(texture).exists():
        tex_name = Path(texture).name
        shutil.copyfile(texture, pkg / tex_name)
    (pkg / f"{map_name}.xodr").write_text(xodr_text)
    desc = {"maps": [{"name": map_name, "source": f"./{map_name}.fbx",
                      "use_carla_materials": bool(use_carla_materials), "xodr": f"./{map_name}.xodr"}],
            "props": []}
    (pkg / f"{package}.json").write_text(json.dumps(desc, indent=2) + "\n")
    (Path(folder) / "spawn_points.json").write_text(json.dumps(
        {"map": map_name, "count": len(spawn),
         "frames": {"carla": "carla.Transform arguments: metres, degrees, Unreal left-handed (y = -north)",
                    "site": "site frame: x east, y north, z up; heading counter-clockwise from east"},
         "spawn_points": spawn}, indent=1) + "\n")
    rows = ["| mesh | CityScapes class | tag after `make import` | move to `Static/` | intended tag |",
            "|---|---|---|---|---|"]
    for cid in classes_present:
        ci = info(cid)
        rows.append(f"| `{ci.carla_name}` | {ci.name} | {ci.auto_tag} | `{ci.carla_folder}` | {ci.carla_tag} |")
    geo = ", ".join(f"{k} {v}" for k, v in georef.items() if k in ("crs", "lat", "lon", "alt"))
    (pkg / "README.md").write_text(README.format(
        package=package, map=map_name, texture=tex_name or "(no texture)", n_spawn=len(spawn),
        use_carla_materials=str(bool(use_carla_materials)).lower(), table="\n".join(rows),
        frames=(frames or _site_frames)(f"({geo})" if geo else ""), carla_version=carla_version))
    return pkg


"""The CARLA package in the CARLA frame: OpenDRIVE, FBX and spawn points moved by one similarity.

CARLA 0.9.16 geolocates from ``+lat_0``/``+lon_0`` alone, assuming x = true east and y = true north
in metres at that point (``GeoReferenceParser.cpp``, ``GeoLocation.cpp``; see
:mod:`twinkit.geo.carla`). The package is therefore written in :func:`twinkit.geo.carla.carla_frame`'s
frame: ``package = scale * Rz(rotation) * site`` for x, y and z.

- OpenDRIVE: :func:`twinkit.geo.xodr.transform_xodr`; its geoReference becomes the frame's
  exact PROJ string (the site-frame string is kept in a header ``userData``).
- FBX: re-exported through the fbx exporter with the vertices moved (normals turned). The transform
  is baked into the vertices, not put on a root node: CARLA's pedestrian navmesh tool reads raw
  vertex values without the FBX's node transforms (``Util/DockerUtils/fbx/src/FBX2OBJ.cpp``, run
  with ``IMP_FBX_GLOBAL_SETTINGS`` off), so only baked vertices stay aligned with the roads in both
  Unreal and the navmesh.
- Spawn points are made from the moved OpenDRIVE by the package step itself.

The USD, GLB and the twin's own FBX keep the site frame and the site CRS.
"""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

FRAME_MODES = ("carla", "site")


def package_frame(site, mode: str, scale: str, radius_m: float, tolerance_m: float, log=None, points=None):
    """The :class:`twinkit.geo.carla.CarlaFrame` of the package, or None for ``mode == "site"``. ``points``
    (site-frame x, y of the twin: :func:`twin_points`): where CARLA's geolocation is balanced and measured (else
    within ``radius_m`` of the base point)."""
    from twinkit import InputError
    from twinkit.geo import SiteFrame

    if mode not in FRAME_MODES:
        raise InputError(f"carla_package: frame={mode!r}; use 'carla' (CARLA's geolocation works) or 'site'")
    if mode == "site":
        return None
    try:
        sf = SiteFrame.from_site(site)
    except InputError as exc:
        raise InputError(f"carla_package: {exc} (or set the exporter's frame=site to write the package in the "
                         f"site frame, with CARLA's geolocation wrong)") from None
    points = points if points is not None and len(points) else None
    f = sf.carla_frame(radius_m=radius_m, tolerance_m=tolerance_m, scale=scale, points=points)
    if log is not None:
        log.info("CARLA frame: rotation %+.4f deg, scale %.6f, k %.6f; CARLA's geolocation within %.3f m "
                 "(mean %.3f m) %s", math.degrees(f.rotation_rad), f.scale, f.k,
                 f.carla_error_max_m, f.carla_error_mean_m, f.measured)
        if f.carla_error_max_m > tolerance_m:
            log.warning("CARLA's spherical geolocation cannot meet %.2f m %s (best %.3f m, frame_scale=%s); see "
                        "docs/georeferencing.md", tolerance_m, f.measured, f.carla_error_max_m, scale)
    return f


def twin_points(class_set, xodr_text: str | None = None, most: int = 20000) -> np.ndarray:
    """(n, 2) site-frame x, y where the twin is: the vertices of its class meshes (evenly thinned to at most
    ``most``) and the plan-view geometry starts of its OpenDRIVE."""
    import re

    parts = [np.asarray(cm.mesh.vertices, float)[:, :2] for cm in class_set.meshes if len(cm.mesh.vertices)]
    if xodr_text:
        parts.append(np.array([(float(a), float(b)) for a, b in re.findall(
            r'<geometry [^>]*?x="([-0-9.eE+]+)" y="([-0-9.eE+]+)"', xodr_text)], float).reshape(-1, 2))
    pts = np.concatenate(parts) if parts else np.zeros((0, 2))
    if len(pts) > most:
        pts = pts[np.linspace(0, len(pts) - 1, most).astype(int)]
    return pts


def package_xodr(text: str, frame, name: str) -> str:
    """The OpenDRIVE of the package (``text`` unchanged when ``frame`` is None)."""
    from twinkit.geo.carla import carla_xodr

    return text if frame is None else carla_xodr(text, frame, name)


def package_class_dir(frame, class_set, texture: Path | None, work: Path) -> Path:
    """The folder of class meshes the package's FBX files are made from: ``class_set.folder`` unchanged when
    ``frame`` is None, else the class meshes moved into the frame (vertices by the similarity, normals by
    its rotation), written to ``work`` under the manifest's file names."""
    from .classmesh import write_class_ply

    if frame is None:
        return Path(class_set.folder)
    work = Path(work)
    work.mkdir(parents=True, exist_ok=True)
    rot = frame.matrix / frame.scale
    for c, cm in zip(class_set.manifest["classes"], class_set.meshes):
        if c["faces"] <= 0:
            continue
        moved = dataclasses.replace(cm, mesh=dataclasses.replace(
                                    cm.mesh, vertices=frame.site_to_package(cm.mesh.vertices),
                                    attrs={**cm.mesh.attrs, "normals": (np.asarray(cm.mesh.normals, np.float64) @ rot.T).astype(np.float32)}))
        write_class_ply(work / c["file"], moved, texture.name if texture else None)
    return work


def site_spawn(spawn: list[dict], frame) -> list[dict]:
    """Spawn points made on the package's map, with their ``site`` block taken back into the site frame
    and a ``wgs84`` block (exact, through the geoReference). Unchanged when ``frame`` is None."""
    if frame is None or not spawn:
        return spawn
    from twinkit.street.lanes import from_carla

    pkg = from_carla([[p["carla"]["x"], p["carla"]["y"], p["carla"]["z"]] for p in spawn])
    site = frame.package_to_site(pkg)
    ll = frame.package_to_lonlat(pkg[:, :2])
    rot = math.degrees(frame.rotation_rad)
    out = []
    for p, q, g in zip(spawn, site, ll):
        h = round(math.fmod(p["site"]["heading_deg"] - rot, 360.0), 3)
        h = h + 360.0 if h <= -180.0 else h - 360.0 if h > 180.0 else h  # (-180, 180]
        out.append({**p, "site": {"x": round(float(q[0]), 3), "y": round(float(q[1]), 3), "z": round(float(q[2]), 3),
                                  "heading_deg": round(h, 3)},
                    "wgs84": {"lat": round(float(g[1]), 9), "lon": round(float(g[0]), 9)}})
    return out


def frame_json(frame, site_georeference: str | None) -> dict:
    """The ``carla_frame.json`` record: the similarity and what CARLA's formula gives."""
    if frame is None:
        return {"frame": "site", "geo_reference": site_georeference,
                "note": "package in the site frame; CARLA 0.9.16 reads only +lat_0/+lon_0 of this string"}
    return {**frame.to_json(), "site_geo_reference": site_georeference,
            "matrix_site_to_package": [[round(float(v), 15) for v in row] for row in frame.matrix]}


def readme_frames(frame, georef_text: str) -> str:
    """The README's frame section."""
    if frame is None:
        return (f"Mesh and OpenDRIVE share the site frame (x east, y north, z up, metres, origin at the base "
                f"point {georef_text}). Unreal mirrors y on import of both, so they stay aligned. CARLA 0.9.16 "
                f"reads only `+lat_0`/`+lon_0` of the geoReference, so its geolocation of this package is wrong "
                f"(twinkit's `frame=carla`, the default, fixes that).")
    return (
        f"Mesh and OpenDRIVE share the **CARLA frame**: x true east, y true north, z up, origin at the base "
        f"point {georef_text}, {frame.k:.9g} package metres per true metre there. It is the site frame "
        f"turned by {math.degrees(frame.rotation_rad):+.6f} deg (the meridian convergence) and scaled by "
        f"{frame.scale:.9g}: `package = scale * Rz(rotation) * site` (x, y, z; `carla_frame.json` has the "
        f"matrix). The twin's USD, GLB and own FBX stay in the site frame and the site CRS.\n\n"
        f"The OpenDRIVE geoReference is the exact PROJ string of this frame, "
        f"`{frame.geo_reference()}` (pyproj and other tools read it as it is); its `+lat_0`/`+lon_0` are what "
        f"CARLA 0.9.16 reads. CARLA's spherical formula is within {frame.carla_error_max_m:.2f} m "
        f"(mean {frame.carla_error_mean_m:.2f} m) of the exact position {frame.measured}, on north-positive y. CARLA 0.9.16 itself feeds Unreal's y (= -north) to it, so its "
        f"GNSS latitudes move south as you drive north; `twinkit.geo.carla.CarlaFrame.gnss_to_lonlat` (or: "
        f"negate y of `geolocation_to_transform`, then apply the geoReference) gives the exact position. "
        f"Unreal mirrors y on import of mesh and roads alike, so they stay aligned.")


def write_frame_json(path: Path, frame, site_georeference: str | None) -> None:
    Path(path).write_text(json.dumps(frame_json(frame, site_georeference), indent=1) + "\n")

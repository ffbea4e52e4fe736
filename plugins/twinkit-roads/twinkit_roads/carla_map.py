"""``roads_carla.xodr``: the roads-only recipe's map in the CARLA frame, the one CARLA geolocates.

``roads.xodr`` is in the site frame; its geoReference is the site frame's exact PROJ string, of which CARLA
0.9.16 reads only ``+lat_0``/``+lon_0`` (:mod:`twinkit.geo.carla`). The CARLA-frame copy is made by the
same code as the CARLA package's map (:func:`twinkit.geo.carla.carla_frame`, :func:`twinkit.geo.carla.carla_xodr`),
balanced over the map's own lane centres, and CARLA's geolocation is then measured with the ``carla`` wheel at
those lane centres against their exact position (:func:`twinkit.geo.carla.wheel_error`).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np


def carla_map(text: str, site, params, name: str, log) -> tuple[str, dict]:
    """(the CARLA-frame OpenDRIVE of the site-frame map ``text``, the geolocation record)."""
    from twinkit.geo import SiteFrame
    from twinkit.geo.carla import carla_xodr, wheel_error

    from .convert import check_xodr

    sf = SiteFrame.from_site(site)
    pts = _lane_centres(text, params.step_m, check_xodr)
    frame = sf.carla_frame(tolerance_m=params.tolerance_m, scale=params.frame_scale, points=pts)
    out = carla_xodr(text, frame, name)
    wheel = wheel_error(out, frame, sf, pts)
    doc = {"frame": {**frame.to_json(), "matrix_site_to_package": [[round(float(v), 15) for v in row]
                                                                    for row in frame.matrix]},
           "site_geo_reference": sf.proj_string(), "wheel": wheel, "tolerance_m": params.tolerance_m,
           "ok": wheel["carla_error_max_m"] <= params.tolerance_m,
           "note": "roads.xodr is in the site frame: CARLA 0.9.16 reads only +lat_0/+lon_0 of its geoReference and "
                   "misplaces it; roads_carla.xodr is the map to load in CARLA (package = scale * Rz(rotation) * "
                   "site; errors on north-positive y, docs/georeferencing.md)"}
    log.info("roads_carla.xodr (CARLA frame: rotation %+.4f deg, scale %.6f): CARLA's geolocation within %.3f m "
             "(mean %.3f m) %s (%s)", math.degrees(frame.rotation_rad), frame.scale, wheel["carla_error_max_m"],
             wheel["carla_error_mean_m"], wheel["measured"], wheel["tool"])
    if not doc["ok"]:
        log.warning("CARLA's spherical geolocation of roads_carla.xodr is off by up to %.2f m (more than %.2f m) %s; "
                    "see docs/georeferencing.md", wheel["carla_error_max_m"], params.tolerance_m, wheel["measured"])
    return out, doc


def _lane_centres(text: str, step_m: float, check_xodr) -> np.ndarray:
    """(n, 2) site-frame lane centres of the map (carla.Map waypoints, in a child process)."""
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        src, npy = Path(d) / "roads.xodr", Path(d) / "samples.npy"
        src.write_text(text, encoding="utf-8")
        check_xodr(src, (0.0, 0.0, 0.0, 0.0), step_m, samples=npy)
        pts = np.load(npy)[:, :2]
    if len(pts) > 5000:
        pts = pts[np.linspace(0, len(pts) - 1, 5000).astype(int)]
    return pts


def write_doc(doc: dict, path: Path) -> None:
    path.write_text(json.dumps(doc, indent=1) + "\n")

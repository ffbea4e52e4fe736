"""An existing OpenDRIVE map as the road source: moved from its own ``<geoReference>`` into the site frame.

A projection change is not a rigid motion, but over a street-sized map it is very nearly a
similarity: ``site_xy = k * Rz(theta) @ map_xy + t`` (k: the ratio of the two projections' scale
factors, theta: the difference of their grid convergences, t: the base point). A similarity maps
every OpenDRIVE geometry onto the same kind of geometry, exactly (:mod:`twinkit.geo.xodr`, shared with
the CARLA package):

- plan view: x, y by the similarity, hdg + theta, lengths * k; arc and spiral curvatures / k;
  poly3 and paramPoly3 (pRange arcLength) coefficients a * k, b, c / k, d / k^2 (normalized: all * k);
- road coordinates scale with the map: every s and t (lane sections, widths, offsets, road marks,
  signals, objects) * k; lateral polynomials (width, border, laneOffset) a * k, b, c / k, d / k^2;
- heights do not scale (a projection's scale factor is horizontal): elevation and shape keep their
  values, superelevation and crossfall their angles; their polynomials in s (or t) become
  a, b / k, c / k^2, d / k^3; elevation gets the vertical offset.

Lanes, junctions, signals and objects are in road coordinates and follow. The similarity is fitted
to the lane centres of the map (carla.Map waypoints) sent through pyproj's full transform; its
largest residual at those lane centres is measured and the map is refused when it exceeds
``max_residual_m`` (the map is then too large, or too far from where its projection is true, for
one similarity).
"""
from __future__ import annotations

import json
import math
import re
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from twinkit import InputError
from twinkit.geo.similarity import closed_form_similarity

from .sources import OpenDriveSourceParams  # noqa: F401 (the source's parameters live with the sources)

@dataclass
class Similarity2D:
    k: float
    theta: float
    t: np.ndarray

    def apply(self, xy) -> np.ndarray:
        xy = np.asarray(xy, float).reshape(-1, 2)
        c, s = math.cos(self.theta), math.sin(self.theta)
        return self.k * (xy @ np.array([[c, s], [-s, c]])) + self.t

    def is_identity(self, extent_m: float) -> bool:
        return abs(self.k - 1) * max(extent_m, 1.0) < 1e-9 and abs(self.theta) * max(extent_m, 1.0) < 1e-9 \
            and float(np.abs(self.t).max()) < 1e-9


# --------------------------------------------------------------------------- reading

def read_xodr(path: Path) -> tuple[str, ET.Element]:
    """The text and the parsed tree of an OpenDRIVE file; InputError naming the file otherwise."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"{path}: no such OpenDRIVE file; check road_source.path / site.inputs.xodr") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read it as an OpenDRIVE (.xodr) text file ({exc})") from None
    try:
        root = ET.fromstring(text.encode("utf-8"), parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    except ET.ParseError as exc:
        raise InputError(f"{path}: not valid XML ({exc}); the OpenDRIVE file is corrupt or truncated: "
                         "export it again") from None
    if root.tag != "OpenDRIVE":
        raise InputError(f"{path}: the root element is <{root.tag}>, not <OpenDRIVE>; give an OpenDRIVE (.xodr) map")
    if not root.findall("road"):
        raise InputError(f"{path}: an OpenDRIVE file without any <road>; nothing to use as the road network")
    return text, root


def _clean_proj(s: str) -> str:
    """Horizontal part of a PROJ string: vertical grids and units dropped (they need files and do not move x, y)."""
    s = " ".join(s.split())
    if s.startswith("+"):
        s = " ".join(tok for tok in s.split() if not re.match(r"\+(geoidgrids|vunits|vto_meter|type)=", tok))
    return s


def map_crs(root: ET.Element, override: str, path: Path):
    """The map's horizontal CRS (pyproj) from ``override`` or its <geoReference>; ``None`` for "site"."""
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    head = root.find("header")
    geo = head.find("geoReference") if head is not None else None
    text = (geo.text or "").strip() if geo is not None else ""
    given = override.strip()
    if given.lower() == "site":
        return None, "site"
    src = given or text
    if not src:
        raise InputError(
            f"{path}: the map has no <geoReference>, so where its coordinates lie is unknown. Give the frame of its "
            "coordinates: road_source.georeference='<PROJ string or EPSG code>' (e.g. EPSG:32632), or "
            "road_source.georeference=site when they are already the site frame (metres about the base point)")
    off = head.find("offset") if head is not None else None
    if off is not None and any(abs(float(off.get(k, 0) or 0)) > 0 for k in ("x", "y", "z", "hdg")):
        raise InputError(f"{path}: the header has a non-zero <offset> ({dict(off.attrib)}); its convention varies "
                         "between tools. Apply it to the map in your editor, or give road_source.georeference with "
                         "the offset folded into +x_0/+y_0")
    try:
        crs = CRS.from_user_input(_clean_proj(src))
    except CRSError as exc:
        what = "road_source.georeference" if given else "its <geoReference>"
        raise InputError(f"{path}: {what} '{src[:200]}' is not a CRS pyproj knows ({str(exc).splitlines()[0]}); "
                         "set road_source.georeference='<PROJ string or EPSG code>'") from None
    if crs.is_compound:
        crs = crs.sub_crs_list[0]
    if crs.is_geographic:
        raise InputError(f"{path}: the map's CRS '{src[:120]}' is geographic (degrees); OpenDRIVE coordinates are "
                         "metres: give the projected CRS of the map in road_source.georeference")
    return crs, src


def lane_centres(path: Path, step_m: float) -> np.ndarray:
    """(n, 6) x, y, z, road, lane, s of the lane centres carla.Map finds in the file (child process)."""
    from .convert import check_xodr

    with tempfile.TemporaryDirectory() as d:
        npy = Path(d) / "samples.npy"
        check_xodr(path, (0.0, 0.0, 0.0, 0.0), step_m, samples=npy)
        return np.load(npy)


# --------------------------------------------------------------------------- the source

def to_site_frame(src: Path, frame, params: OpenDriveSourceParams, log=None) -> tuple[str, dict]:
    """Read ``src``, move it into the site frame, return the new OpenDRIVE text and the report."""
    from pyproj import Transformer

    text, root = read_xodr(src)
    crs, declared = map_crs(root, params.georeference, src)
    samples = lane_centres(src, params.sample_step_m)
    if len(samples) == 0:
        raise InputError(f"{src}: carla.Map finds no lanes in it; nothing to reproject (check the map in an editor)")
    p = samples[:, :2]
    extent = float(np.hypot(*(p.max(0) - p.min(0))))
    if crs is None:  # already the site frame
        sim, q, full = Similarity2D(1.0, 0.0, np.zeros(2)), p, "none (road_source.georeference=site)"
    else:
        from pyproj import CRS

        tr = Transformer.from_crs(crs, CRS.from_user_input(frame.projected), always_xy=True)
        e, n = tr.transform(p[:, 0], p[:, 1])
        q = frame.projected_to_local(np.stack([np.asarray(e, float), np.asarray(n, float)], 1))
        if not np.all(np.isfinite(q)):
            raise InputError(f"{src}: pyproj cannot move the map from '{declared[:120]}' into the site CRS "
                             f"{frame.crs} (points outside the CRS's area); check the geoReference and site.crs")
        fit = closed_form_similarity(p, q)
        sim = Similarity2D(fit.scale, fit.angle_rad, fit.t)
        # float noise of a pure translation (same projection, another base point): no scale, no turn
        if abs(sim.k - 1) * max(extent, 1.0) < 1e-9:
            sim.k = 1.0
        if abs(sim.theta) * max(extent, 1.0) < 1e-9:
            sim.theta = 0.0
        full = f"pyproj: {declared[:200]} -> {frame.projected[:200]}"
    res = np.hypot(*(sim.apply(p) - q).T)
    worst = float(res.max())
    if worst > params.max_residual_m:
        raise InputError(
            f"{src}: the map ({extent:.0f} m across) cannot be moved into the site frame exactly: the best similarity "
            f"(scale {sim.k:.9f}, rotation {math.degrees(sim.theta):.6f} deg) is up to {worst * 1000:.1f} mm away from "
            f"pyproj's transform at the lane centres (limit {params.max_residual_m * 1000:.1f} mm, "
            "road_source.max_residual_m). Use a site CRS closer to the map's projection (e.g. the map's own CRS), "
            "cut the map to the site, or raise max_residual_m to accept that error")
    heights = params.heights.strip().lower()
    if heights not in ("datum", "keep"):
        raise InputError(f"road_source.heights='{params.heights}': choose 'datum' (z - base point alt) or 'keep'")
    dz = -frame.alt if heights == "datum" else 0.0
    identity = sim.is_identity(extent)
    proj = frame.proj_string()
    if identity:
        sim = Similarity2D(1.0, 0.0, np.zeros(2))
    from twinkit.geo.xodr import XodrFrameError, transform_xodr

    try:
        out = transform_xodr(text, sim.theta, sim.k, proj, name=str(src), translation=(sim.t[0], sim.t[1]),
                             scale_heights=False, dz=dz, keep_georeference_as="twinkit_source_geoReference")
    except XodrFrameError as exc:
        raise InputError(f"{exc}; or give a site CRS equal to the map's (scale 1)") from None
    rep = {
        "source": str(src), "map_georeference": declared, "site_georeference": proj, "transform": full,
        "similarity": {"scale": sim.k, "rotation_deg": math.degrees(sim.theta), "tx_m": float(sim.t[0]),
                       "ty_m": float(sim.t[1]), "identity": identity},
        "dz_m": dz, "heights": heights, "lane_centres": int(len(p)), "extent_m": round(extent, 2),
        "residual_max_m": worst, "residual_rms_m": float(np.sqrt(np.mean(res ** 2))),
        "max_residual_m": params.max_residual_m,
        "definition": "site_xy = scale * Rz(rotation) @ map_xy + t, fitted to pyproj's transform of the map's lane "
                      "centres (carla.Map waypoints); residual = distance between the two at those lane centres",
    }
    if log is not None:
        log.info("%s: %d lane centres over %.0f m; similarity scale %.9f, rotation %.6f deg, t (%.3f, %.3f) m; "
                 "residual max %.2f mm", src.name, len(p), extent, sim.k, math.degrees(sim.theta), sim.t[0], sim.t[1],
                 worst * 1000)
    return out, rep


def write_report(rep: dict, path: Path) -> None:
    path.write_text(json.dumps(rep, indent=1))

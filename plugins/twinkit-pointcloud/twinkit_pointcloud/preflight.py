"""``read_cloud``'s preflight: the cloud's box from its header (no points read), its centre as lat/lon,
and the site's base point against it (twinkit/engine/preflight.py runs this before the first step).

Bounds: LAS/LAZ from the header (laspy), E57 from each scan's ``cartesianBounds`` moved by its pose,
binary PLY from the x, y, z columns mapped from disk (one pass over three columns, nothing parsed).
An ASCII PLY or a file without bounds is not checked here (``read_cloud`` still checks the frame).
"""
from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np

log = logging.getLogger("twinkit.preflight.read_cloud")

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def _las_bounds(path: Path):
    import laspy

    with laspy.open(str(path)) as f:
        h = f.header
        if not h.point_count:
            return None  # an empty file's header box is 0, 0, 0 (thousands of km off): read_cloud says it is empty
        crs = None
        try:
            c = h.parse_crs()
            crs = c.to_wkt() if c is not None else None
        except Exception:  # noqa: BLE001 -- an unparsable CRS VLR: read_cloud says so
            crs = None
        return np.asarray(h.mins, float), np.asarray(h.maxs, float), crs


def _ply_bounds(path: Path):
    with open(path, "rb") as fh:
        if fh.readline().strip() != b"ply":
            raise ValueError("no 'ply' magic line")
        fmt, elements, cur = None, [], None
        while True:
            line = fh.readline()
            if not line:
                raise ValueError("no end_header")
            w = line.decode("ascii", "replace").split()
            if not w:
                continue
            if w[0] == "format":
                fmt = w[1]
            elif w[0] == "element":
                cur = [w[1], int(w[2]), []]
                elements.append(cur)
            elif w[0] == "property" and cur is not None:
                if w[1] == "list":
                    cur[2].append((w[-1], None))
                else:
                    cur[2].append((w[-1], w[1]))
            elif w[0] == "end_header":
                offset = fh.tell()
                break
    if fmt not in ("binary_little_endian", "binary_big_endian") or not elements or elements[0][0] != "vertex":
        return None  # ASCII, or vertices not first: not worth parsing here
    name, n, props = elements[0]
    if any(t is None for _, t in props) or not {"x", "y", "z"} <= {p for p, _ in props}:
        return None
    end = "<" if fmt == "binary_little_endian" else ">"
    dt = np.dtype([(p, end + _PLY_TYPES[t]) for p, t in props])
    if n == 0 or path.stat().st_size - offset >= (n + 1) * dt.itemsize:
        return None  # empty, or more rows than declared: read_cloud's reader says so
    a = np.memmap(path, dtype=dt, mode="r", offset=offset, shape=(n,))
    xyz = [np.asarray(a[c], np.float64) for c in "xyz"]
    ok = np.isfinite(xyz[0]) & np.isfinite(xyz[1]) & np.isfinite(xyz[2])
    if not ok.any():
        return None
    return (np.array([v[ok].min() for v in xyz]), np.array([v[ok].max() for v in xyz]), None)


def _e57_bounds(path: Path):
    from pye57 import libe57

    from .readers import _child, _e57_crs, _node_value, _quat_to_matrix

    imf = libe57.ImageFile(str(path), "r")
    try:
        root = imf.root()
        crs = _e57_crs(root)
        if not root.isDefined("data3D"):
            return None
        data3d = libe57.VectorNode(root.get("data3D"))
        pts = []
        for i in range(data3d.childCount()):
            scan = libe57.StructureNode(data3d.get(i))
            cb = _child(scan, "cartesianBounds")
            if cb is None:
                return None  # a scan without bounds: the box is unknown
            bs = libe57.StructureNode(cb)
            lim = [float(_node_value(bs.get(f"{c}{m}"))) for c in "xyz" for m in ("Minimum", "Maximum")]
            corners = np.array([[x, y, z] for x in lim[0:2] for y in lim[2:4] for z in lim[4:6]])
            R, t = np.eye(3), np.zeros(3)
            pose = _child(scan, "pose")
            if pose is not None:
                ps = libe57.StructureNode(pose)
                rot, tr = _child(ps, "rotation"), _child(ps, "translation")
                if rot is not None:
                    rs = libe57.StructureNode(rot)
                    R = _quat_to_matrix(*(float(_node_value(rs.get(c))) for c in "wxyz"))
                if tr is not None:
                    ts = libe57.StructureNode(tr)
                    t = np.array([float(_node_value(ts.get(c))) for c in "xyz"])
            pts.append(corners @ R.T + t)
        if not pts:
            return None
        allp = np.concatenate(pts)
        return allp.min(0), allp.max(0), crs
    finally:
        imf.close()


def cloud_bounds(path: Path):
    """``(lo, hi, crs)`` of the cloud's points in the file's coordinates, from the header; None when the
    file does not give them cheaply. Raises on an unreadable file."""
    ext = Path(path).suffix.lower()
    if ext in (".las", ".laz"):
        return _las_bounds(path)
    if ext == ".ply":
        return _ply_bounds(path)
    if ext == ".e57":
        return _e57_bounds(path)
    return None


def _box_distance(lo, hi) -> float:
    """Distance in x, y from the site origin (the base point) to the box (0 inside)."""
    dx = max(lo[0], 0.0, -hi[0]) if not (lo[0] <= 0.0 <= hi[0]) else 0.0
    dy = max(lo[1], 0.0, -hi[1]) if not (lo[1] <= 0.0 <= hi[1]) else 0.0
    return math.hypot(dx, dy)


def read_cloud_preflight(site, params, inputs) -> list[str]:
    """The cloud (a site input) exists, its header is readable, and the base point lies near its box (the box
    of the central 99.8 % of the points when the header's box, outliers included, would refuse it)."""
    path = inputs.get("in_cloud")
    if path is None:
        return []  # written by an earlier step (the demo's generator): read_cloud checks it
    path = Path(path)
    try:
        b = cloud_bounds(path)
    except Exception as exc:  # noqa: BLE001 -- an empty, cut or corrupt file: read_cloud's reader names the fault
        log.debug("%s: no bounds from the header (%s: %s); read_cloud checks the file", path.name,
                  type(exc).__name__, str(exc).splitlines()[0][:200] if str(exc) else "")
        return []
    if b is None:
        log.info("%s: no bounds in the header; the base point is checked when read_cloud runs", path.name)
        return []
    problems = _box_problems(path, *b, site, params)
    if not problems:
        return []
    robust = _robust_bounds(path)  # a few far points (a junk point at 0, 0, 0) must not refuse the whole cloud
    if robust is None:
        return problems
    lo, hi, n_out, n = robust
    again = _box_problems(path, lo, hi, b[2], site, params)
    if not again:
        log.warning("%s: %d of %d points lie far outside the rest (the header's box spans %s .. %s, the central "
                    "99.8 %% of the points %s .. %s); read_cloud drops those far from the base point", path.name,
                    n_out, n, np.round(b[0], 1).tolist(), np.round(b[1], 1).tolist(), np.round(lo, 1).tolist(),
                    np.round(hi, 1).tolist())
    return again


def _robust_bounds(path: Path):
    """``(lo, hi, n_far, n)``: the box of the central 99.8 % of the points in each axis (file coordinates)
    and how many points lie far outside it (more than its size and 100 m); None when the points cannot be read."""
    ext = path.suffix.lower()
    try:
        if ext in (".las", ".laz"):
            import laspy

            las = laspy.read(str(path))
            xyz = np.c_[np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)]
        elif ext == ".ply":
            from twinkit.mesh import read_ply

            xyz = read_ply(path).vertices
        elif ext == ".e57":
            from .readers import read_e57

            xyz = read_e57(path).xyz
        else:
            return None
    except Exception:  # noqa: BLE001 -- read_cloud's reader names the fault
        return None
    xyz = xyz[np.isfinite(xyz).all(axis=1)]
    if len(xyz) < 10:
        return None
    lo, hi = np.percentile(xyz, 0.1, axis=0), np.percentile(xyz, 99.9, axis=0)
    wide = np.maximum(hi - lo, 100.0)  # "far": beyond the central box's own size (and 100 m) from it
    n_out = int((~np.all((xyz >= lo - wide) & (xyz <= hi + wide), axis=1)).sum())
    return lo, hi, n_out, len(xyz)


def _box_problems(path: Path, lo, hi, crs, site, params) -> list[str]:
    """The problems of the cloud's box ``lo``, ``hi`` (file coordinates, CRS ``crs``) for the site: wrong CRS,
    flat, not a street, base point far outside."""
    from twinkit import InputError
    from twinkit.geo import to_site_frame

    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    from .localframe import apply_points, cloud_frame_matrix

    try:
        m, _ = cloud_frame_matrix(site)  # site.cloud_frame: the box moves as read_cloud moves the points
    except InputError as exc:
        return [str(exc)]
    if m is not None:
        corners = apply_points(m, corners)
        crs = (site or {}).get("crs") or None
    try:
        local, info = to_site_frame(corners, crs, site, path.name,
                                    max_offset_m=float(getattr(params, "max_offset_km", 20.0)) * 1000.0,
                                    bounds_margin_m=float(getattr(params, "bounds_margin_m", 50.0)),
                                    min_inside_fraction=0.0)
    except InputError as exc:
        return [str(exc)]
    llo, lhi = local.min(0), local.max(0)
    centre = 0.5 * (llo + lhi)
    where = f"centre x {centre[0]:.1f} m, y {centre[1]:.1f} m in the site frame"
    fix = "at its centre"
    try:
        from twinkit.geo import SiteFrame

        lon, lat = SiteFrame.from_site(site).local_to_lonlat(centre[None, :2])[0]
        where = f"centre lat {lat:.6f}, lon {lon:.6f} ({where})"
        fix = f"at its centre: site.base_point.lat={lat:.6f} site.base_point.lon={lon:.6f}"
    except Exception:  # noqa: BLE001 -- a site without a georeference: local metres only
        pass
    size = lhi - llo
    log.info("%s: box %.0f x %.0f x %.0f m, %s", path.name, size[0], size[1], size[2], where)
    from .street import MIN_STREET_EXTENT_M, flat_capture, not_a_street

    refusal = flat_capture(path.name, size) or not_a_street(
        path.name, size, float(getattr(params, "min_street_extent_m", MIN_STREET_EXTENT_M)))
    if refusal:
        return [refusal]
    limit = float(getattr(params, "max_base_point_offset_m", 0.0) or 0.0)
    if not (info.projected and info.shift_source == "base_point") or limit <= 0:
        return []  # a local cloud (used as it is) or no base point: nothing to compare
    d = _box_distance(llo, lhi)
    if d > limit:
        bp = dict(site.get("base_point") or {})
        bp_text = ", ".join(f"{k} {v}" for k, v in bp.items())
        return [f"{path.name}: the site's base point ({bp_text}) is {d:.0f} m outside the cloud's box (cloud {where}; "
                f"{math.hypot(centre[0], centre[1]):.0f} m from the base point; more than "
                f"steps.read_cloud.max_base_point_offset_m={limit:g}). Put the base point in the capture, e.g. "
                f"{fix}, or check site.crs"]
    return []

"""Point cloud readers: E57 (libe57 through pye57, incl. the ``nor:`` normals extension and
several posed scans), LAS/LAZ (laspy + lazrs), PLY (:func:`twinkit.mesh.read_ply`).

Every reader returns a :class:`RawCloud` in the file's own coordinates (float64); call
:func:`load_cloud` to also validate it and bring it into the site frame
(:func:`twinkit.geo.to_site_frame`).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np


@dataclass
class RawCloud:
    """A cloud as read.

    xyz: (n, 3) float64, file units and CRS (after E57 poses are applied).
    normals: (n, 3) float32 unit vectors or None.  colors: (n, 3) uint8 or None.
    intensity: (n,) float32 in [0, 1] (E57, normalised by its limits) or raw LAS values; or None.
    classification: (n,) uint8 or None.  scanner: (n,) int32 scan index or None.
    scanner_positions: (k, 3) float64, same frame as xyz; a row of NaN where unknown.
    """

    path: Path
    format: str
    xyz: np.ndarray
    normals: np.ndarray | None = None
    colors: np.ndarray | None = None
    intensity: np.ndarray | None = None
    classification: np.ndarray | None = None
    scanner: np.ndarray | None = None
    scanner_positions: np.ndarray | None = None
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    crs: Any = None  # anything pyproj.CRS.from_user_input accepts
    source_fields: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def n(self) -> int:
        return int(len(self.xyz))

    def take(self, mask: np.ndarray) -> "RawCloud":
        def t(a):
            return None if a is None else a[mask]

        return RawCloud(self.path, self.format, self.xyz[mask], t(self.normals), t(self.colors), t(self.intensity),
                        t(self.classification), t(self.scanner), self.scanner_positions,
                        {k: v[mask] for k, v in self.extra.items()}, self.crs, self.source_fields, self.notes)


def _input_error(msg: str):
    from twinkit import InputError

    return InputError(msg)


# ----------------------------------------------------------------------------- E57

def _node_value(node) -> float | str | None:
    from pye57 import libe57

    t = node.type()
    if t == libe57.NodeType.E57_FLOAT:
        return libe57.FloatNode(node).value()
    if t == libe57.NodeType.E57_INTEGER:
        return libe57.IntegerNode(node).value()
    if t == libe57.NodeType.E57_SCALED_INTEGER:
        return libe57.ScaledIntegerNode(node).scaledValue()
    if t == libe57.NodeType.E57_STRING:
        return libe57.StringNode(node).value()
    return None


def _e57_crs(root) -> str | None:
    """The CRS an E57 file names in its ``coordinateMetadata`` (as WKT), or None."""
    cm = _child(root, "coordinateMetadata")
    if cm is None:
        return None
    s = _node_value(cm)
    if not (isinstance(s, str) and s.strip()):
        return None
    try:
        from pyproj import CRS

        return CRS.from_user_input(s.strip()).to_wkt()
    except Exception:  # noqa: BLE001 -- any unparsable text: no CRS, the site's is used
        return None


def _child(struct, name):
    if not struct.isDefined(name):
        return None
    return struct.get(name)


def _quat_to_matrix(w: float, x: float, y: float, z: float) -> np.ndarray:
    q = np.array([w, x, y, z], dtype=np.float64)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def _read_fields(imf, points, names: list[str], n: int, path: Path, i: int) -> dict[str, np.ndarray]:
    """Every field of a scan's ``points`` (n,) float64, read in blocks of at most 2 million points."""
    from pye57 import libe57

    out = {nm: np.empty(n, np.float64) for nm in names}
    cap = int(min(n, 2_000_000))
    bufs_np = {nm: np.empty(cap, np.float64) for nm in names}
    bufs = libe57.VectorSourceDestBuffer()
    for nm in names:
        bufs.append(libe57.SourceDestBuffer(imf, nm, bufs_np[nm], cap, True, True))
    reader = points.reader(bufs)
    got = 0
    try:
        while got < n:
            k = reader.read()
            if k == 0:
                break
            for nm in names:
                out[nm][got:got + k] = bufs_np[nm][:k]
            got += k
    finally:
        reader.close()
    if got < n:
        raise _input_error(f"{path.name}: scan {i} declares {n} points but only {got} could be read; "
                           f"the file is truncated - re-export it")
    return out


def _scan_xyz(out: dict[str, np.ndarray], path: Path, i: int) -> np.ndarray:
    """(n, 3) float64 points in the scan's own frame, from cartesian or else spherical fields."""
    if "cartesianX" in out:
        return np.stack([out["cartesianX"], out["cartesianY"], out["cartesianZ"]], axis=1)
    if "sphericalRange" in out:
        r, az, el = out["sphericalRange"], out["sphericalAzimuth"], out["sphericalElevation"]
        return np.stack([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)], axis=1)
    raise _input_error(f"{path.name}: scan {i} has neither cartesian nor spherical coordinates")


def _scan_colors(scan, out: dict[str, np.ndarray]) -> np.ndarray:
    """(n, 3) uint8 colours scaled by the scan's colorLimits (else 0..255, or 0..max when above 255)."""
    from pye57 import libe57

    lim = _child(scan, "colorLimits")
    cols = []
    for c in ("Red", "Green", "Blue"):
        lo, hi = 0.0, 255.0
        if lim is not None:
            ls = libe57.StructureNode(lim)
            lo_n, hi_n = _child(ls, f"color{c}Minimum"), _child(ls, f"color{c}Maximum")
            lo = float(_node_value(lo_n)) if lo_n is not None else 0.0
            hi = float(_node_value(hi_n)) if hi_n is not None else float(out[f"color{c}"].max())
        else:
            hi = 255.0 if out[f"color{c}"].max() <= 255 else float(out[f"color{c}"].max())
        cols.append((out[f"color{c}"] - lo) / max(hi - lo, 1e-12))
    return np.clip(np.rint(np.stack(cols, axis=1) * 255), 0, 255).astype(np.uint8)


def _scan_intensity(scan, v: np.ndarray) -> np.ndarray:
    """(n,) float32 intensity scaled to 0..1 by the scan's intensityLimits (else its own min..max)."""
    from pye57 import libe57

    lim = _child(scan, "intensityLimits")
    lo, hi = float(v.min()), float(v.max())
    if lim is not None:
        ls = libe57.StructureNode(lim)
        a, b = _child(ls, "intensityMinimum"), _child(ls, "intensityMaximum")
        lo = float(_node_value(a)) if a is not None else lo
        hi = float(_node_value(b)) if b is not None else hi
    return ((v - lo) / max(hi - lo, 1e-12)).astype(np.float32)


def _scan_pose(pose) -> tuple[np.ndarray, np.ndarray]:
    """The scan's pose node as (R (3, 3), t (3,)): scan frame -> file frame, p' = R p + t."""
    from pye57 import libe57

    ps = libe57.StructureNode(pose)
    R = np.eye(3)
    t = np.zeros(3)
    rot = _child(ps, "rotation")
    if rot is not None:
        rs = libe57.StructureNode(rot)
        R = _quat_to_matrix(*(float(_node_value(rs.get(c))) for c in "wxyz"))
    tr = _child(ps, "translation")
    if tr is not None:
        ts = libe57.StructureNode(tr)
        t = np.array([float(_node_value(ts.get(c))) for c in "xyz"])
    return R, t


def _scan_part(scan, out: dict[str, np.ndarray], names: list[str], path: Path, i: int, notes: list[str]
               ) -> tuple[dict[str, np.ndarray], list]:
    """One scan's valid points in the file frame (xyz, and normals, colors, intensity, classification,
    scanner index where present) and its scanner position ([nan] * 3 when unknown)."""
    valid = np.ones(len(next(iter(out.values()))), bool)
    for st in ("cartesianInvalidState", "sphericalInvalidState"):
        if st in out:
            valid &= out[st] == 0
    part: dict[str, np.ndarray] = {"xyz": _scan_xyz(out, path, i)}
    nor = [f"nor:normal{c}" for c in "XYZ"]
    if all(c in out for c in nor):
        part["normals"] = np.stack([out[c] for c in nor], axis=1)
    if all(f"color{c}" in out for c in ("Red", "Green", "Blue")):
        part["colors"] = _scan_colors(scan, out)
    if "intensity" in out:
        part["intensity"] = _scan_intensity(scan, out["intensity"])
    cls_field = _class_field(names)
    if cls_field is not None:  # an extension field of per-point classes (ASPRS codes)
        part["classification"] = np.clip(np.rint(out[cls_field]), 0, 255).astype(np.uint8)
    pose = _child(scan, "pose")
    scanner_pos = [np.nan] * 3
    if pose is not None:
        R, t = _scan_pose(pose)
        part["xyz"] = part["xyz"] @ R.T + t
        if "normals" in part:
            part["normals"] = part["normals"] @ R.T
        scanner_pos = t.tolist()
    elif "sphericalRange" in out or "rowIndex" in out:
        # a structured (gridded) scan without a pose is in its scanner's own frame
        scanner_pos = [0.0, 0.0, 0.0]
        notes.append(f"scan {i}: no pose, gridded scan -> scanner assumed at its origin")
    for k in list(part):
        part[k] = part[k][valid]
    part["scanner"] = np.full(int(valid.sum()), i, np.int32)
    return part, scanner_pos


def _merge_scans(path: Path, parts: list[dict], positions: list, fields_seen: set[str], notes: list[str],
                 crs: str | None) -> RawCloud:
    """The scans' parts concatenated into one RawCloud; a field only some scans have is dropped (noted)."""
    if not parts:
        return RawCloud(path, "e57", np.zeros((0, 3)), source_fields=sorted(fields_seen), crs=crs)

    def cat(key, dtype=None):
        if not all(key in p for p in parts):
            if any(key in p for p in parts):
                notes.append(f"'{key}' present in only some scans: dropped")
            return None
        a = np.concatenate([p[key] for p in parts])
        return a.astype(dtype) if dtype else a

    normals = cat("normals", np.float32)
    if normals is not None:
        ln = np.linalg.norm(normals, axis=1, keepdims=True)
        normals = (normals / np.maximum(ln, 1e-12)).astype(np.float32)
    return RawCloud(path=path, format="e57", xyz=cat("xyz"), normals=normals, colors=cat("colors"),
                    intensity=cat("intensity"), classification=cat("classification", np.uint8), scanner=cat("scanner"),
                    scanner_positions=np.asarray(positions, np.float64).reshape(-1, 3),
                    crs=crs, source_fields=sorted(fields_seen), notes=notes)


def read_e57(path: Path) -> RawCloud:
    """Read every scan of an E57 file, apply each scan's pose, and merge them."""
    from pye57 import libe57

    path = Path(path)
    try:
        imf = libe57.ImageFile(str(path), "r")
    except Exception as exc:  # libe57 raises E57Exception subclasses; message says what
        raise _input_error(f"{path.name}: not a readable E57 file ({_first_line(exc)}); the file is corrupt or truncated - "
                           f"re-export it from the scanner software") from exc
    try:
        root = imf.root()
        crs = _e57_crs(root)
        if not root.isDefined("data3D"):
            raise _input_error(f"{path.name}: the E57 file has no data3D section (no point scans); "
                               f"export the point cloud, not only images")
        data3d = libe57.VectorNode(root.get("data3D"))
        parts: list[dict[str, np.ndarray]] = []
        positions = []
        fields_seen: set[str] = set()
        notes: list[str] = []
        for i in range(data3d.childCount()):
            scan = libe57.StructureNode(data3d.get(i))
            points = libe57.CompressedVectorNode(scan.get("points"))
            proto = libe57.StructureNode(points.prototype())
            names = [proto.get(j).elementName() for j in range(proto.childCount())]
            fields_seen.update(names)
            n = points.childCount()
            if n == 0:
                positions.append([np.nan] * 3)
                continue
            out = _read_fields(imf, points, names, n, path, i)
            part, scanner_pos = _scan_part(scan, out, names, path, i, notes)
            positions.append(scanner_pos)
            parts.append(part)
    except Exception as exc:
        from twinkit import InputError

        if isinstance(exc, InputError):
            raise
        raise _input_error(f"{path.name}: the E57 file cannot be read ({_first_line(exc)}); the file is corrupt or "
                           f"truncated - re-export it from the scanner software") from None
    finally:
        try:
            imf.close()
        except Exception:
            pass
    return _merge_scans(path, parts, positions, fields_seen, notes, crs)


# ----------------------------------------------------------------------------- LAS / LAZ

def read_las(path: Path) -> RawCloud:
    """LAS/LAZ through laspy (LAZ decompressed by lazrs). RGB 8- or 16-bit -> uint8."""
    import laspy

    path = Path(path)
    try:
        las = laspy.read(str(path))
    except Exception as exc:
        raise _input_error(f"{path.name}: not a readable LAS/LAZ file ({type(exc).__name__}: {exc}); "
                           f"the file is corrupt or truncated - download or export it again") from exc
    hdr = las.header
    if hdr.point_count and len(las.points) < hdr.point_count:
        raise _input_error(f"{path.name}: header declares {hdr.point_count} points but only {len(las.points)} "
                           f"could be read; the file is truncated - download or export it again")
    xyz = np.stack([np.asarray(las.x, np.float64), np.asarray(las.y, np.float64), np.asarray(las.z, np.float64)], axis=1)
    dims = list(las.point_format.dimension_names)
    colors = None
    notes: list[str] = []
    if all(c in dims for c in ("red", "green", "blue")):
        rgb = np.stack([np.asarray(las.red), np.asarray(las.green), np.asarray(las.blue)], axis=1)
        if rgb.size and rgb.max() > 255:
            colors = np.clip(np.rint(rgb / 257.0), 0, 255).astype(np.uint8)
            notes.append("16-bit RGB scaled to 8 bits")
        elif rgb.size and rgb.max() > 0:
            colors = rgb.astype(np.uint8)
            notes.append("RGB stored as 8-bit values")
        else:
            notes.append("RGB fields present but all zero: treated as no colour")
    intensity = np.asarray(las.intensity, np.float32) if "intensity" in dims else None
    classification = np.asarray(las.classification, np.uint8) if "classification" in dims else None
    normals = None
    for trip in (("normal_x", "normal_y", "normal_z"), ("nx", "ny", "nz"), ("NormalX", "NormalY", "NormalZ")):
        if all(c in dims for c in trip):
            normals = np.stack([np.asarray(las[c], np.float32) for c in trip], axis=1)
    crs = None
    try:
        c = hdr.parse_crs()
        crs = c.to_wkt() if c is not None else None
    except Exception as exc:  # unparsable CRS VLR
        notes.append(f"CRS in the file could not be parsed ({exc}); treated as unknown")
    return RawCloud(path=path, format=path.suffix.lower().lstrip("."), xyz=xyz, normals=normals, colors=colors,
                    intensity=intensity, classification=classification, crs=crs, source_fields=dims, notes=notes)


# ----------------------------------------------------------------------------- PLY

def read_ply_cloud(path: Path) -> RawCloud:
    """A PLY cloud (any vertex properties); refused when its header declares fewer vertices than it holds."""
    from twinkit.mesh import read_ply
    from twinkit.mesh.ply import PlyExtraData

    path = Path(path)
    try:
        m = read_ply(path, exact=True)
    except PlyExtraData as exc:
        raise _input_error(f"{path.name}: the header declares {exc.declared} vertices, but the file holds more "
                           f"(about {exc.extra_rows} more after them), so part of the cloud would be left out; fix "
                           f"the count in the header's 'element vertex' line or export the file again") from None
    except Exception as exc:
        raise _input_error(f"{path.name}: not a readable PLY file ({type(exc).__name__}: {exc}); "
                           f"the file is corrupt or truncated - export it again") from exc
    a = dict(m.attrs)
    normals = a.pop("normals", None)
    colors = a.pop("colors", None)
    intensity = None
    for k in ("intensity", "scalar_intensity", "scalar_Intensity"):
        if k in a:
            intensity = np.asarray(a.pop(k), np.float32)
            break
    classification = None
    k = _class_field(list(a))
    if k is not None:
        classification = np.clip(np.rint(np.asarray(a.pop(k), np.float64)), 0, 255).astype(np.uint8)
    scanner = np.asarray(a.pop("scanner")).astype(np.int32) if "scanner" in a else None
    fields = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals is not None else []) + \
             (["red", "green", "blue"] if colors is not None else []) + \
             [k for k in m.attrs if k not in ("normals", "colors")]  # the file's order
    if normals is not None:
        ln = np.linalg.norm(normals, axis=1, keepdims=True)
        ok = ln[:, 0] > 1e-12
        normals = np.where(ok[:, None], normals / np.maximum(ln, 1e-12), 0).astype(np.float32)
    return RawCloud(path=path, format="ply", xyz=m.vertices, normals=normals, colors=colors, intensity=intensity,
                    classification=classification, scanner=scanner, extra=a, source_fields=fields)


#: per-point class fields read as ASPRS codes (any case; CloudCompare's ``scalar_`` prefix, an E57
#: extension's ``prefix:``). A ``label`` field declares no scheme, so it stays an extra field, unused.
CLASS_FIELDS = ("classification", "class")


def _class_field(names) -> str | None:
    for nm in names:
        base = str(nm).split(":")[-1].lower()
        if base.startswith("scalar_"):
            base = base[len("scalar_"):]
        if base in CLASS_FIELDS:
            return nm
    return None


READERS = {".e57": read_e57, ".las": read_las, ".laz": read_las, ".ply": read_ply_cloud}


def _first_line(exc: BaseException) -> str:
    """libE57's messages carry a debug dump (context, source file and line) after the first line."""
    return (str(exc).strip().splitlines() or [type(exc).__name__])[0].strip()


def read_any(path: Path) -> RawCloud:
    path = Path(path)
    if path.is_symlink() and not path.exists():
        raise _input_error(f"{path}: a broken link (to {os.readlink(path)}, which does not exist); "
                           f"fix the link or the site's input path")
    if not path.exists():
        raise _input_error(f"{path}: file not found; check the site's input paths")
    if path.is_dir():
        raise _input_error(f"{path}: is a folder, not a point cloud file; give the E57, LAS, LAZ or PLY file "
                           f"inside it as the site's cloud input")
    try:
        with open(path, "rb") as f:
            f.read(1)
    except OSError as exc:
        raise _input_error(f"{path}: cannot read the file ({exc.strerror}); check its permissions") from None
    reader = READERS.get(path.suffix.lower())
    if reader is None:
        raise _input_error(f"{path.name}: unsupported point cloud format '{path.suffix}'; "
                           f"use E57, LAS, LAZ or PLY")
    if path.stat().st_size == 0:
        raise _input_error(f"{path.name}: the file is empty (0 bytes); export the cloud again")
    return reader(path)


# ----------------------------------------------------------------------------- validation + frame

@dataclass
class Cloud:
    """A validated cloud in the site frame. points: (n, 3) float64 metres (site frame)."""

    raw: RawCloud
    points: np.ndarray
    frame: Any
    dropped_invalid: int = 0
    dropped_duplicates: int = 0
    dropped_far: int = 0  # outliers more than max_offset_km from the base point
    dropped_platform: int = 0  # returns of the vehicle carrying a sweep's sensor (drop_platform)
    blind_circle: dict | None = None  # the sweep's blind circle (twinkit.surface.rings.blind_circle)


def validate_and_frame(raw: RawCloud, site: Mapping[str, Any], *, min_points: int = 10,
                       drop_invalid: bool = True, log=None, **frame_kw) -> Cloud:
    """Check the cloud (empty, NaN/inf, degenerate) and move it into the site frame."""
    from twinkit.geo import to_site_frame

    name = raw.path.name
    if raw.n == 0:
        raise _input_error(f"{name}: the cloud is empty (the file holds no points); check the export or the "
                           f"filter that produced it")
    finite = np.isfinite(raw.xyz).all(axis=1)
    n_bad = int((~finite).sum())
    if n_bad:
        if n_bad == raw.n:
            raise _input_error(f"{name}: all {raw.n} points have NaN or infinite coordinates, so none is left; "
                               f"the export is broken - export the cloud again")
        if not drop_invalid:
            raise _input_error(f"{name}: {n_bad} of {raw.n} points have NaN or infinite coordinates; "
                               f"remove them (or set drop_invalid_points=true to skip them)")
        if log is not None:
            log.warning("%s: dropped %d of %d points with NaN or infinite coordinates", name, n_bad, raw.n)
        raw = raw.take(finite)
    ext = raw.xyz.max(axis=0) - raw.xyz.min(axis=0)
    if raw.n >= 2 and float(ext.max()) <= 1e-9 * max(1.0, float(np.abs(raw.xyz).max())):
        raise _input_error(f"{name}: all {raw.n} points are identical ({raw.xyz[0].tolist()}); "
                           f"the capture is degenerate - check the export")
    dup = duplicate_rows(raw.xyz)
    n_dup = 0 if dup is None else int(dup.sum())
    if n_dup:
        if log is not None:
            log.warning("%s: removed %d duplicate points of %d (the same x, y, z as an earlier point; %.1f %%); "
                        "the point spacing is measured without them", name, n_dup, raw.n, 100.0 * n_dup / raw.n)
        raw = raw.take(~dup)
    if raw.n < min_points:
        raise _input_error(f"{name}: too few points ({raw.n}"
                           + (f" after removing {n_dup} duplicates" if n_dup else "")
                           + f"; at least {min_points} are needed for a surface); use a denser or larger capture")
    local, info = to_site_frame(raw.xyz, raw.crs, site, name, **frame_kw)
    far = _far_points(local, info, frame_kw.get("max_offset_m", 20000.0))
    if far is not None:
        i = int(np.flatnonzero(far)[np.argmax(np.hypot(*local[far, :2].T))])
        if log is not None:
            log.warning("%s: dropped %d of %d points more than %g km from the base point (outliers; the farthest "
                        "%.1f km away, at file coordinates %s); the rest of the cloud is around the base point",
                        name, int(far.sum()), raw.n, frame_kw.get("max_offset_m", 20000.0) / 1000.0,
                        float(np.hypot(*local[i, :2])) / 1000.0, np.round(raw.xyz[i], 2).tolist())
        raw, local = raw.take(~far), local[~far]
    n_far = 0 if far is None else int(far.sum())
    if raw.scanner_positions is not None and len(raw.scanner_positions):
        from twinkit.geo import apply_frame

        raw.scanner_positions = apply_frame(raw.scanner_positions, raw.crs, site, info)
    return Cloud(raw=raw, points=local, frame=info, dropped_invalid=n_bad, dropped_duplicates=n_dup,
                 dropped_far=n_far)


def drop_platform(cloud: Cloud, dens: dict, log=None) -> tuple[Cloud, dict]:
    """``cloud`` without the returns of the vehicle that carried a single sweep's sensor
    (:func:`twinkit.surface.rings.platform_returns`), and its density (``dens``: :func:`twinkit.surface.density
    .measure` of ``cloud``, measured again when points went); the same when it is not a sweep (by ``dens``'s
    ground: no sensor is looked for) or none is found."""
    import dataclasses

    from twinkit.surface import density
    from twinkit.surface.rings import platform_returns, ring_sensor

    share = dens.get("ground_two_way_share")
    if share is None or share >= density.RING_CAPTURE_SHARE:
        return cloud, dens
    sensor = ring_sensor(cloud.points)
    if sensor is None:
        return cloud, dens
    gone, circle = platform_returns(cloud.points, sensor)
    n = int(gone.sum())
    if log is not None and circle is not None:
        log.info("%s: a single sweep: %d points of the vehicle carrying the sensor left out (small clusters inside "
                 "the blind circle of %.1f m round the sensor at %.1f, %.1f; read_cloud.drop_platform)",
                 cloud.raw.path.name, n, circle["radius_m"], *circle["xy"])
    if not n:
        return dataclasses.replace(cloud, blind_circle=circle), dens
    kept = dataclasses.replace(cloud, raw=cloud.raw.take(~gone), points=cloud.points[~gone], dropped_platform=n,
                               blind_circle=circle)
    return kept, density.measure(kept.points, scanner_positions=kept.raw.scanner_positions)


def _far_points(local: np.ndarray, info, max_offset_m: float) -> np.ndarray | None:
    """A mask of the points more than ``max_offset_m`` from the base point when the cloud as a whole is near
    it (its median point passed :func:`twinkit.geo.to_site_frame`); None when there are none."""
    if info.shift_source != "base_point" or not max_offset_m or max_offset_m <= 0:
        return None
    far = np.hypot(local[:, 0], local[:, 1]) > max_offset_m
    return far if far.any() and not far.all() else None


def duplicate_rows(xyz: np.ndarray) -> np.ndarray | None:
    """A mask of the points that repeat an earlier point exactly (the same x, y, z), or None when no point
    does. One 64-bit hash per point sorted (about 1 s per 10 million points), equal hashes then compared
    value by value, so the first of each group of duplicates is kept."""
    a = np.ascontiguousarray(xyz, dtype=np.float64) + 0.0  # -0.0 -> 0.0: equal values, equal bits
    b = a.view(np.uint64).reshape(-1, 3)
    with np.errstate(over="ignore"):
        h = (b[:, 0] * np.uint64(0x9E3779B97F4A7C15)) ^ (b[:, 1] * np.uint64(0xC2B2AE3D27D4EB4F)) \
            ^ (b[:, 2] * np.uint64(0x165667B19E3779F9))
    hs = np.sort(h)
    if not (hs[1:] == hs[:-1]).any():
        return None
    order = np.argsort(h, kind="stable")
    ho = h[order]
    same = (ho[1:] == ho[:-1]) & (a[order[1:]] == a[order[:-1]]).all(axis=1)
    if not same.any():
        return None
    dup = np.zeros(len(a), bool)
    dup[order[1:][same]] = True
    return dup

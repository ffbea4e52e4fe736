"""What read_cloud writes: the points PLY's per-point attributes and comments, the meta record, the metrics."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def point_attrs(raw, normals: np.ndarray | None) -> dict[str, np.ndarray]:
    """The per-point attributes of ``points.ply``: normals (float32), colours, intensity (float32),
    classification, scanner index (int32), then the file's other 1-D fields, each (n,) or (n, 3)."""
    attrs: dict[str, np.ndarray] = {}
    if normals is not None:
        attrs["normals"] = normals.astype(np.float32)
    if raw.colors is not None:
        attrs["colors"] = raw.colors
    if raw.intensity is not None:
        attrs["intensity"] = raw.intensity.astype(np.float32)
    if raw.classification is not None:
        attrs["classification"] = raw.classification
    if raw.scanner is not None:
        attrs["scanner"] = raw.scanner.astype(np.int32)
    for k, v in raw.extra.items():
        if k not in attrs and v.ndim == 1:
            attrs[k] = v
    return attrs


def ply_comments(in_cloud: Path, shift) -> list[str]:
    """The PLY header's comments: the source file and the site frame's shift (m)."""
    return [f"twinkit-pointcloud read_cloud from {in_cloud.name}",
            f"site frame shift {shift[0]:.3f} {shift[1]:.3f} {shift[2]:.3f}"]


def cloud_meta(in_cloud: Path, raw, cloud, n_read: int, pts: np.ndarray, normals_info: tuple, cloud_frame,
               dens: dict) -> dict:
    """The ``points_meta.json`` record (without its time): source, counts, fields, frame, scanners, bounds,
    density, notes. ``pts``: (n, 3) float64 written points (site frame, m); ``normals_info``: (source,
    orientation, check) from :func:`~twinkit_pointcloud.normals.cloud_normals`."""
    normals_source, orientation, normals_check = normals_info
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    return {
        "source": {"file": in_cloud.name, "format": raw.format, "fields": raw.source_fields},
        "counts": {"read": n_read, "dropped_invalid": cloud.dropped_invalid,
                   "duplicates_removed": cloud.dropped_duplicates, "dropped_far": cloud.dropped_far,
                   "dropped_platform": cloud.dropped_platform,
                   "written": int(len(pts))},
        "fields": {"normals": normals_source, "normals_orientation": orientation, "normals_check": normals_check,
                   "colors": raw.colors is not None, "intensity": raw.intensity is not None,
                   "classification": raw.classification is not None, "scanner": raw.scanner is not None,
                   "extra": sorted(raw.extra)},
        "frame": dict(cloud.frame.as_dict(), cloud_frame=cloud_frame),
        "scanner_positions_m": (None if raw.scanner_positions is None else
                                [[None if not np.isfinite(c) else float(c) for c in row]
                                 for row in raw.scanner_positions]),
        "bounds_m": [lo.tolist(), hi.tolist()],
        "density": dens,
        "blind_circle": cloud.blind_circle,
        "notes": raw.notes,
    }


def read_metrics(pts: np.ndarray, raw, cloud, normals_source: str | None, normals_check: dict | None,
                 cloud_frame: dict | None, dens: dict, measured: dict) -> dict:
    """read_cloud's metrics: points, duplicates removed, normals' source, colours, shift (m), spacing (m)
    (measured without the duplicates), capture, the measure's figures, the file normals' check and the cloud frame (without its matrix) when there."""
    out = {"points": int(len(pts)), "duplicates_removed": cloud.dropped_duplicates, "normals": normals_source, "colors": raw.colors is not None,
           "shift_m": cloud.frame.shift, "spacing_m": dens["spacing_m"], "capture": dens["capture"], **measured}
    if normals_check is not None:
        out["normals_flipped"] = normals_check["flipped"]
        out["normals_disagreeing_share"] = normals_check["disagreeing_share"]
    if cloud_frame is not None:
        out["cloud_frame"] = {k: v for k, v in cloud_frame.items() if k != "transform"} or {"transform": True}
    return out

"""A cloud in its own local frame (a sensor sweep, an extract shifted to the origin) placed in the site's
CRS by the site config (docs/pointcloud.md "Local frames", docs/georeferencing.md)::

    cloud_frame:                 # the cloud's own coordinates -> the site CRS
      offset: [x, y, z]          # where the cloud's origin lies, in the site CRS's units
      heading_deg: 30.0          # direction of the cloud's +x axis, degrees counter-clockwise from grid east
    # or
    cloud_frame:
      transform: [[r, r, r, tx], [r, r, r, ty], [r, r, r, tz], [0, 0, 0, 1]]   # rigid, row-major 4x4

The matrix maps the file's coordinates (after its E57 poses) to coordinates in ``site.crs`` (its units:
US feet for a feet CRS). The cloud then counts as being in the site CRS, whatever the file declares, and
:func:`twinkit.geo.to_site_frame` converts units and subtracts the base point as for any georeferenced file.
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

KEYS = ("offset", "heading_deg", "transform")


def _err(msg: str):
    from twinkit import InputError

    return InputError(msg)


def cloud_frame_matrix(site: Mapping[str, Any] | None) -> tuple[np.ndarray | None, dict | None]:
    """(4x4 float64 matrix or None when the site gives no ``cloud_frame``, a description for the step's
    output). Raises InputError on a malformed entry, naming the key and the fix."""
    from twinkit.geo.crs import site_dict

    site = site_dict(site)
    cf = site.get("cloud_frame")
    if not cf:
        return None, None
    name = site.get("name", "?")
    try:
        cf = dict(cf)
    except (TypeError, ValueError):
        raise _err(f"site '{name}': cloud_frame must be a mapping with offset/heading_deg or transform, "
                   f"got {cf!r}") from None
    unknown = sorted(set(cf) - set(KEYS))
    if unknown:
        raise _err(f"site '{name}': unknown cloud_frame keys {unknown}; use offset: [x, y, z] with heading_deg, "
                   f"or transform: a 4x4 matrix")
    if "transform" in cf and ("offset" in cf or "heading_deg" in cf):
        raise _err(f"site '{name}': cloud_frame gives both transform and offset/heading_deg; give one of them")
    if "transform" in cf:
        try:
            m = np.asarray(cf["transform"], np.float64)
            if m.size == 16:
                m = m.reshape(4, 4)
        except (TypeError, ValueError):
            m = np.zeros(0)
        if m.shape != (4, 4) or not np.isfinite(m).all():
            raise _err(f"site '{name}': cloud_frame.transform must be 4x4 finite numbers (rows), got "
                       f"{cf['transform']!r}")
        if not np.allclose(m[3], [0, 0, 0, 1], atol=1e-9):
            raise _err(f"site '{name}': cloud_frame.transform's last row must be [0, 0, 0, 1], got {m[3].tolist()}")
        r = m[:3, :3]
        if not (np.allclose(r.T @ r, np.eye(3), atol=1e-4) and np.linalg.det(r) > 0):
            raise _err(f"site '{name}': cloud_frame.transform is not a rigid motion (its 3x3 part must be a rotation: "
                       f"orthonormal, determinant +1); scale the cloud in the file, or give offset and heading_deg")
        return m, {"transform": m.tolist()}
    try:
        off = np.asarray(cf.get("offset", [0.0, 0.0, 0.0]), np.float64).reshape(-1)
        heading = float(cf.get("heading_deg", 0.0) or 0.0)
    except (TypeError, ValueError):
        raise _err(f"site '{name}': cloud_frame.offset must be [x, y] or [x, y, z] and heading_deg a number, "
                   f"got {cf!r}") from None
    if off.size == 2:
        off = np.append(off, 0.0)
    if off.size != 3 or not np.isfinite(off).all() or not np.isfinite(heading):
        raise _err(f"site '{name}': cloud_frame.offset must be [x, y] or [x, y, z] (site CRS units), got "
                   f"{cf.get('offset')!r}")
    a = np.radians(heading)
    m = np.eye(4)
    m[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    m[:3, 3] = off
    return m, {"offset": off.tolist(), "heading_deg": heading, "transform": m.tolist()}


def apply_points(m: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    return np.asarray(xyz, np.float64) @ m[:3, :3].T + m[:3, 3]


def apply_cloud_frame(raw, site: Mapping[str, Any], log=None):
    """Move a :class:`~twinkit_pointcloud.readers.RawCloud` by the site's ``cloud_frame`` (points, normals,
    scanner positions) and mark it as being in the site CRS. Returns the description (None: no cloud_frame)."""
    m, desc = cloud_frame_matrix(site)
    if m is None:
        return None
    raw.xyz = apply_points(m, raw.xyz)
    if raw.normals is not None:
        raw.normals = (np.asarray(raw.normals, np.float64) @ m[:3, :3].T).astype(np.float32)
    if raw.scanner_positions is not None and len(raw.scanner_positions):
        raw.scanner_positions = apply_points(m, raw.scanner_positions)
    if raw.crs is not None:
        desc["file_crs_replaced"] = True
        raw.notes.append("the file declares a CRS, but site.cloud_frame places the cloud: the site CRS is used")
    raw.crs = site.get("crs") or None
    raw.notes.append(f"placed by site.cloud_frame into {site.get('crs') or 'the site frame'}")
    if log is not None:
        log.info("%s: placed by site.cloud_frame (%s) into %s", raw.path.name,
                 ", ".join(f"{k} {v}" for k, v in desc.items() if k != "transform") or "4x4 transform",
                 site.get("crs") or "the site frame")
    return desc

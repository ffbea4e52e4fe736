"""CRS rules: parsing, unit factors, the base point in a CRS, and file coordinates -> the site frame.

The one place that says how coordinates in some CRS become site-frame metres (x east, y north, z up,
origin at the site base point; see :mod:`twinkit.geo.frame` for the frame itself). All arithmetic
here is float64; callers convert to float32 only after :func:`to_site_frame`. pyproj is imported
inside the functions.

Rules for a file's coordinates (in this order):

1. The file has a CRS and the site names another one: reproject x, y (pyproj) into the site CRS;
   z is scaled to metres when the file's CRS has no vertical part.
2. The file has a CRS and the site names none (or the same one): horizontal (and vertical)
   units are converted to metres with the CRS's own unit factors (US-foot LAS files, ...).
3. The coordinates are projected (a projected CRS, or no CRS and values beyond
   ``LARGE_COORD_M``): shift by the site base point (:func:`base_point_in`: ``x, y`` in the CRS's
   units, or ``lat, lon`` projected into the target CRS, both converted to metres); without a
   base point, by the cloud centre rounded to 100 m (z: to 1 m), and say so.
4. Small coordinates with no CRS are taken as already in the site frame (shift 0).
5. The result is checked against ``site.bounds_m`` (or, without bounds, against a maximum
   distance from the base point): a cloud elsewhere is in the wrong CRS for the site.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

LARGE_COORD_M = 1.0e4


@dataclass
class FrameInfo:
    shift: list[float]  # subtracted from (converted) file coordinates, metres, target CRS
    source_crs: str | None  # WKT or user string of the file's CRS
    target_crs: str | None  # CRS of the shifted frame before the shift (site CRS, or the file's)
    reprojected: bool = False
    unit_factor_xy: float = 1.0
    unit_factor_z: float = 1.0
    projected: bool = False
    shift_source: str = "none"  # "base_point", "rounded_centre", "none"
    notes: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return {
            "shift_m": self.shift,
            "source_crs": short_crs(self.source_crs),
            "target_crs": short_crs(self.target_crs),
            "reprojected": self.reprojected,
            "unit_factor_xy": self.unit_factor_xy,
            "unit_factor_z": self.unit_factor_z,
            "projected_input": self.projected,
            "shift_source": self.shift_source,
            "notes": self.notes,
        }


def site_dict(site: Any) -> dict:
    """A site config (dict, mapping or OmegaConf node; None = empty) as a plain dict."""
    if site is None:
        return {}
    try:
        from omegaconf import OmegaConf

        if OmegaConf.is_config(site):
            return OmegaConf.to_container(site, resolve=True)  # type: ignore[return-value]
    except ImportError:  # pragma: no cover
        pass
    return dict(site)


def short_crs(crs: str | None) -> str | None:
    """``EPSG:<code>`` when the CRS has one, else its name (for messages and metadata)."""
    if crs is None:
        return None
    try:
        from pyproj import CRS

        c = CRS.from_user_input(crs)
        epsg = c.to_epsg(min_confidence=70)
        return f"EPSG:{epsg}" if epsg else c.name
    except Exception:
        return str(crs)[:200]


def parse_crs(crs):
    """``pyproj.CRS`` of anything ``CRS.from_user_input`` accepts; None for None or ""."""
    if crs is None or crs == "":
        return None
    from pyproj import CRS

    return CRS.from_user_input(crs)


def horizontal(crs):
    """The horizontal part of a compound CRS (the CRS itself otherwise)."""
    return crs.sub_crs_list[0] if crs.is_compound else crs


def unit_factors(crs) -> tuple[float, float]:
    """(horizontal, vertical) metres per unit of a projected or compound CRS (1.0 where not stated)."""
    fxy = 1.0
    fz = None
    try:
        for ax in horizontal(crs).axis_info:
            if ax.direction in ("east", "north", "west", "south") and ax.unit_conversion_factor:
                fxy = float(ax.unit_conversion_factor)
                break
        if crs.is_compound and len(crs.sub_crs_list) > 1:
            for ax in crs.sub_crs_list[1].axis_info:
                if ax.unit_conversion_factor:
                    fz = float(ax.unit_conversion_factor)
    except Exception:
        pass
    return fxy, (fz if fz is not None else fxy)


def z_unit(crs) -> float:
    """Metres per unit of a base point's ``z`` in ``crs``: the vertical axis of a compound CRS, else the
    horizontal unit of a projected one (feet in a feet CRS); 1 for a geographic 2D CRS or None."""
    if crs is None:
        return 1.0
    if not crs.is_compound and horizontal(crs).is_geographic:
        return 1.0
    return unit_factors(crs)[1]


def base_height(bp: Mapping[str, Any], z_unit_m: float = 1.0) -> float:
    """The base point's height in metres: ``alt`` (metres, as given), else ``z`` (the site CRS's own vertical
    unit, like ``x, y``: times ``z_unit_m``, 0.3048 in a feet CRS), else 0. Never a datum conversion."""
    if bp.get("alt") is not None:
        return float(bp["alt"] or 0.0)
    return float(bp.get("z", 0.0) or 0.0) * float(z_unit_m)


def utm_epsg(lat: float, lon: float) -> tuple[int, str]:
    """The WGS 84 / UTM zone of a place: (EPSG code, "zone 35N")."""
    zone = int((float(lon) + 180.0) // 6.0) % 60 + 1
    north = float(lat) >= 0
    return (32600 if north else 32700) + zone, f"zone {zone}{'N' if north else 'S'}"


def outside_area_of_use(crs, lat: float, lon: float, margin_deg: float = 2.0) -> str | None:
    """Why ``(lat, lon)`` lies outside ``crs``'s area of use (pyproj ``CRS.area_of_use``, widened by
    ``margin_deg`` on every side: a site just across a zone or national border is still fine), or None
    when it lies inside, or the CRS states no area."""
    try:
        area = crs.area_of_use
    except Exception:  # noqa: BLE001 - a CRS without the information
        area = None
    if area is None:
        return None
    w, s, e, n = float(area.west), float(area.south), float(area.east), float(area.north)
    lat, lon = float(lat), float(lon)
    in_lat = s - margin_deg <= lat <= n + margin_deg
    if w <= e:
        in_lon = w - margin_deg <= lon <= e + margin_deg
    else:  # the area crosses the antimeridian
        in_lon = lon >= w - margin_deg or lon <= e + margin_deg
    if in_lat and in_lon:
        return None
    return (f"lat {lat:.4f}, lon {lon:.4f} lies outside the area of use of {short_crs(crs.to_wkt())} "
            f"({crs.name}: {area.name}; lon {w:g}..{e:g}, lat {s:g}..{n:g})")


def base_point_lonlat(bp: Mapping[str, Any], horiz) -> tuple[float, float] | None:
    """(lon, lat) of a base point given as ``lat``/``lon`` or as ``x``/``y`` in the horizontal CRS ``horiz``;
    None when it has neither pair."""
    if "lat" in bp and "lon" in bp:
        return float(bp["lon"]), float(bp["lat"])
    if "x" in bp and "y" in bp:
        if horiz.is_geographic:
            return float(bp["x"]), float(bp["y"])
        from pyproj import Transformer

        t = Transformer.from_crs(horiz, "EPSG:4326", always_xy=True)
        lon, lat = t.transform(float(bp["x"]), float(bp["y"]))
        return float(lon), float(lat)
    return None


def check_base_point_area(site: Mapping[str, Any], where: str) -> None:
    """Refuse a site whose base point lies outside its CRS's area of use (a CRS of another country or UTM
    zone gives metres that are kilometres wrong, or nonsense). ``where`` names the site file in the message.
    Unknown CRSs and incomplete base points are left to :class:`twinkit.geo.SiteFrame`."""
    from twinkit.errors import InputError

    crs_in, bp = site.get("crs"), site.get("base_point")
    if not crs_in or not isinstance(bp, Mapping):
        return
    try:
        crs = parse_crs(str(crs_in))
    except Exception:  # noqa: BLE001 - an unknown CRS is SiteFrame's message
        return
    try:
        ll = base_point_lonlat(bp, horizontal(crs))
    except (TypeError, ValueError):
        return
    if ll is None:
        return
    lon, lat = ll
    import math

    if not (math.isfinite(lat) and math.isfinite(lon)):
        why: str | None = f"the base point {dict(bp)} has no position in {crs_in}"
    else:
        why = outside_area_of_use(crs, lat, lon)
    if why is None:
        return
    hint = ""
    if math.isfinite(lat) and math.isfinite(lon) and abs(lat) < 84:
        code, zone = utm_epsg(lat, lon)
        hint = f" (for this place e.g. EPSG:{code}, WGS 84 / UTM {zone}, or the national grid)"
    raise InputError(f"{where}: site.crs {crs_in} does not fit site.base_point: {why}. Set site.crs to a CRS "
                     f"made for the place{hint}, or fix site.base_point to the place the data shows")


def base_point_in(crs, site: Mapping[str, Any]) -> np.ndarray | None:
    """The site base point in ``crs`` as metres (x, y times the CRS's unit factor; z: :func:`base_height`),
    or None when the site has none (or gives lat/lon and ``crs`` is None or geographic).

    ``x, y`` are taken in ``crs``'s units, ``lat, lon`` are projected into ``crs`` -- the same rule as
    :class:`twinkit.geo.SiteFrame`, so ``base_point_in(site CRS, site)`` is the frame's
    ``(easting, northing) * unit_m``.
    """
    bp = site.get("base_point") or {}
    if not bp:
        return None
    fxy, fz = (unit_factors(crs)[0] if crs is not None else 1.0), z_unit(crs)
    if "x" in bp and "y" in bp:
        return np.array([float(bp["x"]) * fxy, float(bp["y"]) * fxy, base_height(bp, fz)])
    if "lat" in bp and "lon" in bp and crs is not None and not crs.is_geographic:
        from pyproj import Transformer

        t = Transformer.from_crs("EPSG:4326", crs, always_xy=True)
        x, y = t.transform(float(bp["lon"]), float(bp["lat"]))
        return np.array([x * fxy, y * fxy, base_height(bp, fz)])
    return None


def to_site_frame(xyz: np.ndarray, file_crs, site: Mapping[str, Any], name: str,
                  *, max_offset_m: float = 20000.0, bounds_margin_m: float = 50.0,
                  min_inside_fraction: float = 0.05) -> tuple[np.ndarray, FrameInfo]:
    """Return ``(local, info)``: ``local`` (n, 3) float64 metres in the site frame.

    Raises :class:`twinkit.InputError` when the cloud cannot belong to the site (wrong CRS).
    """
    xyz = np.array(xyz, dtype=np.float64, copy=True)
    src = parse_crs(file_crs)
    site_crs_s = site.get("crs")
    site_crs = parse_crs(site_crs_s) if site_crs_s else None
    info = FrameInfo(shift=[0.0, 0.0, 0.0], source_crs=src.to_wkt() if src is not None else None,
                     target_crs=None)
    if src is not None:
        target = _into_metres(xyz, src, site_crs, name, info)
        projected = True
    else:
        projected = bool(np.nanmax(np.abs(xyz[:, :2])) > LARGE_COORD_M) if len(xyz) else False
        target = site_crs
    info.projected = projected
    info.target_crs = target.to_wkt() if target is not None else (str(site_crs_s) if site_crs_s else None)
    if projected:
        _shift_to_origin(xyz, base_point_in(target, site), info)
    else:
        _refuse_degrees(xyz, site_crs, site, name)
        info.notes.append("local coordinates (no CRS, small values): used as they are")
    _check_on_site(xyz, site, info, name, max_offset_m=max_offset_m, bounds_margin_m=bounds_margin_m,
                   min_inside_fraction=min_inside_fraction)
    return xyz, info


def _refuse_degrees(xyz: np.ndarray, site_crs, site: Mapping[str, Any], name: str) -> None:
    """InputError when a cloud without a CRS of its own has x, y in degrees near the base point of a site whose
    CRS is geographic (EPSG:4326): read as metres such a street is a few millimetres wide ("not a street")."""
    from twinkit import InputError

    if site_crs is None or not horizontal(site_crs).is_geographic or not len(xyz):
        return
    mx, my = (float(v) for v in np.nanmedian(xyz[:, :2], axis=0))
    ll = base_point_lonlat(site.get("base_point") or {}, horizontal(site_crs))
    lon, lat = ll if ll is not None else (mx, my)
    span = float(np.nanmax(np.ptp(xyz[:, :2], axis=0)))
    if not (abs(mx - lon) < 1.0 and abs(my - lat) < 1.0 and abs(my) <= 90.0 and span < 1.0):
        return
    code, zone = utm_epsg(my, mx)
    raise InputError(f"{name}: site.crs {site.get('crs')} is geographic (degrees), and the cloud's x, y are degrees "
                     f"too (around lon {mx:.6f}, lat {my:.6f}); twinkit needs a projected CRS in metres: reproject "
                     f"the cloud into one (here e.g. EPSG:{code}, WGS 84 / UTM {zone}) and set site.crs to it")


def _into_metres(xyz: np.ndarray, src, site_crs, name: str, info: FrameInfo):
    """Reproject ``xyz`` (n, 3, in place) from ``src`` into the site's CRS, or, when the site has none or the same,
    convert the file's units to metres; returns the CRS the coordinates are now in. InputError for geographic
    coordinates with no projected site CRS."""
    from twinkit import InputError

    fxy, fz = unit_factors(src)
    vertical_in_src = bool(src.is_compound)
    if site_crs is not None and not src.equals(site_crs, ignore_axis_order=True):
        from pyproj import Transformer

        t = Transformer.from_crs(src, site_crs, always_xy=True)
        x, y = t.transform(xyz[:, 0], xyz[:, 1])
        sfxy, _ = unit_factors(site_crs)
        xyz[:, 0], xyz[:, 1] = np.asarray(x) * sfxy, np.asarray(y) * sfxy
        if not vertical_in_src:
            xyz[:, 2] *= fz
        info.reprojected = True
        info.unit_factor_z = fz if not vertical_in_src else 1.0
        info.notes.append(f"reprojected from {short_crs(src.to_wkt())} to {short_crs(site_crs.to_wkt())}")
        return site_crs
    if src.is_geographic:
        mx, my = (float(v) for v in np.nanmedian(xyz[:, :2], axis=0)) if len(xyz) else (0.0, 0.0)
        code, zone = utm_epsg(my, mx) if abs(my) <= 90 else (32631, "zone 31N")
        raise InputError(
            f"{name}: coordinates are geographic (degrees, {src.name}) and site.crs "
            f"({site_crs.name if site_crs is not None else 'not set'}) is not a projected CRS in metres; set "
            f"site.crs to one (here e.g. EPSG:{code}, WGS 84 / UTM {zone}): the cloud is reprojected into it")
    xyz[:, :2] *= fxy
    xyz[:, 2] *= fz
    info.unit_factor_xy, info.unit_factor_z = fxy, fz
    if fxy != 1.0 or fz != 1.0:
        info.notes.append(f"converted file units to metres (x, y x{fxy:g}, z x{fz:g})")
    return src


def _shift_to_origin(xyz: np.ndarray, base, info: FrameInfo) -> None:
    """Subtract the site base point ``base`` (projected metres) from ``xyz`` (in place), or without one the cloud's
    rounded centre (100 m in x, y; 1 m in z); noted in ``info``."""
    if base is not None:
        shift = base
        info.shift_source = "base_point"
    else:
        lo, hi = np.nanmin(xyz, axis=0), np.nanmax(xyz, axis=0)
        c = 0.5 * (lo + hi)
        shift = np.array([np.round(c[0] / 100.0) * 100.0, np.round(c[1] / 100.0) * 100.0, np.round(c[2])])
        info.shift_source = "rounded_centre"
        info.notes.append(
            f"projected coordinates and no site base point: shifted by the rounded cloud centre "
            f"{shift.tolist()} (record it; set site.base_point to use a fixed origin)")
    xyz -= shift
    info.shift = [float(v) for v in shift]


def _check_on_site(xyz: np.ndarray, site: Mapping[str, Any], info: FrameInfo, name: str, *, max_offset_m: float,
                   bounds_margin_m: float, min_inside_fraction: float) -> None:
    """InputError when the site-frame cloud cannot belong to the site: too few points inside the site's
    ``bounds_m`` (+ margin), or, without bounds, its centre (the median point) too far from the base point
    (a wrong CRS)."""
    from twinkit import InputError

    site_crs_s = site.get("crs")
    bounds = site.get("bounds_m")
    finite = np.isfinite(xyz).all(axis=1)
    pts = xyz[finite]
    if len(pts) and bounds is not None:
        b = np.asarray(bounds, dtype=np.float64)
        lo, hi = b[0] - bounds_margin_m, b[1] + bounds_margin_m
        inside = np.all((pts >= lo) & (pts <= hi), axis=1).mean()
        if inside < min_inside_fraction:
            clo, chi = pts.min(axis=0), pts.max(axis=0)
            raise InputError(
                f"{name}: only {inside:.1%} of the points lie within the site bounds {b.tolist()} (+{bounds_margin_m:g} m); "
                f"the cloud spans {np.round(clo, 1).tolist()} .. {np.round(chi, 1).tolist()} in the site frame, "
                f"so it is probably in the wrong CRS for this site (file CRS: {short_crs(info.source_crs)}, "
                f"site CRS: {site_crs_s}); reproject it or fix site.crs / site.base_point")
    elif len(pts) and info.shift_source == "base_point":
        sample = pts[:: max(1, len(pts) // 1_000_000)]
        centre = np.median(sample, axis=0)  # a few far points (a junk 0, 0, 0) do not move it; read_cloud drops them
        d = float(np.linalg.norm(centre[:2]))
        if d > max_offset_m:
            raise InputError(
                f"{name}: the cloud centre is {d / 1000:.1f} km from the site base point (limit {max_offset_m / 1000:g} km); "
                f"it is probably in the wrong CRS for this site (file CRS: {short_crs(info.source_crs)}, "
                f"site CRS: {site_crs_s}); reproject it or fix site.crs / site.base_point")


def apply_frame(xyz: np.ndarray, file_crs, site: Mapping[str, Any], info: FrameInfo) -> np.ndarray:
    """Apply the transform that :func:`to_site_frame` chose (``info``) to other points of the same file
    (scanner positions). NaN rows stay NaN."""
    xyz = np.array(xyz, dtype=np.float64, copy=True)
    if info.reprojected:
        from pyproj import Transformer

        src = parse_crs(file_crs)
        dst = parse_crs(site.get("crs"))
        t = Transformer.from_crs(src, dst, always_xy=True)
        x, y = t.transform(xyz[:, 0], xyz[:, 1])
        sfxy, _ = unit_factors(dst)
        xyz[:, 0], xyz[:, 1] = np.asarray(x) * sfxy, np.asarray(y) * sfxy
    else:
        xyz[:, :2] *= info.unit_factor_xy
    xyz[:, 2] *= info.unit_factor_z
    return xyz - np.asarray(info.shift)

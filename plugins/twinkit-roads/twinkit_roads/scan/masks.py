"""Top-view masks of the scan: the carriageway (labels and curbs, or grey measured ground without curbs) and
the carriageway level's height raster."""
from __future__ import annotations

import numpy as np

from twinkit.cityscapes import ROAD, SIDEWALK

from ..mesh2d import level_faces
from .model import ScanSourceParams


def rasterize_faces(v, f, fidx, grid) -> np.ndarray:
    """Faces seen from above (``mesh2d.rasterize``, scanline edge rule): the mask is centred on the surface and
    on average half a pixel wider on each side (the widths take it off)."""
    from ..mesh2d import rasterize

    return rasterize(v, f, grid, fidx) > 0


def grey_ground(v, f, labels, rgb, p: ScanSourceParams) -> tuple[np.ndarray, str]:
    """Faces of the carriageway where the scan shows no curbs: paved-labelled (road or sidewalk: without a
    kerb the two are one surface, and a 2D model looking down at a street calls much of it sidewalk), facing
    up, grey."""
    from ..mesh2d import face_normals_z

    sel = np.flatnonzero(np.isin(labels[f], (ROAD, SIDEWALK)).sum(1) >= 2)
    sel = sel[face_normals_z(v, f, sel) > 0.9]
    how = "road or sidewalk labels, facing up"
    if rgb is not None and p.grey_max_saturation < 1:
        c = rgb[f[sel]].astype(np.float64).mean(1)
        sat = (c.max(1) - c.min(1)) / np.maximum(c.max(1), 1.0)
        sel = sel[sat <= p.grey_max_saturation]
        how += f", grey (saturation <= {p.grey_max_saturation:g})"
    return sel, how


def measured(points_xy: np.ndarray, grid, share: float) -> tuple[np.ndarray, float]:
    """Pixels whose 2 m neighbourhood holds at least ``share`` of the cloud's median point density (points
    per m^2 over the pixels with any point near), and that median."""
    from scipy import ndimage

    px = np.floor(grid.to_px(points_xy)).astype(int)
    ok = (px[:, 0] >= 0) & (px[:, 0] < grid.w) & (px[:, 1] >= 0) & (px[:, 1] < grid.h)
    cnt = np.zeros((grid.h, grid.w), np.float32)
    np.add.at(cnt, (px[ok, 1], px[ok, 0]), 1.0)
    k = max(3, int(round(2.0 / grid.res)) | 1)
    dens = ndimage.uniform_filter(cnt, size=k, mode="constant") / grid.res ** 2
    typical = float(np.median(dens[dens > 0])) if (dens > 0).any() else 0.0
    return dens >= share * typical, typical


def carriageway_mask(v, f, labels, grid, p: ScanSourceParams, level=None, *, curbs: bool = True,
                     rgb=None, points_xy: np.ndarray | None = None) -> tuple[np.ndarray, str]:
    """Top-view mask of the carriageway. ``curbs`` false (a scan too sparse to show them; labels needed):
    the paved-labelled, up-facing, grey surface (``grey_ground``) instead of the level below the curbs, where
    the cloud (``points_xy``, when given) was measured at its usual density."""
    from scipy import ndimage

    parts = []
    lab_mask = None
    if not curbs and labels is not None:
        sel, how = grey_ground(v, f, labels, rgb, p)
        m = rasterize_faces(v, f, sel, grid)
        if points_xy is not None and len(points_xy) and p.min_point_density > 0:
            ok, typical = measured(points_xy, grid, p.min_point_density)
            m &= ok
            how += (f", measured (>= {p.min_point_density:g} x the cloud's median {typical:.1f} points/m^2 "
                    "within 2 m)")
        if p.majority_m > 0:
            # seen from above, grey paved-looking specks lie everywhere (shadows, gravel, a garden's path
            # stones): a carriageway pixel has most of its neighbourhood paved-looking
            k = max(3, int(round(p.majority_m / grid.res)) | 1)
            m = ndimage.uniform_filter(m.astype(np.float32), size=k, mode="constant") > 0.5
            how += f", the majority of {k * grid.res:.2f} m around"
        return clean_mask(m, grid, p, None, v, f, False), how + " (no curbs at this point spacing)"
    if labels is not None:
        lv = labels[f]
        road_f = np.flatnonzero((lv == ROAD).sum(1) >= 2)
        if len(road_f):
            lab_mask = rasterize_faces(v, f, road_f, grid)
            parts.append("road labels")
    if p.use_curbs or lab_mask is None:
        low = rasterize_faces(v, f, level_faces(v, f, p.curb_tol_m) if level is None else level, grid)
        parts.append("curbs (carriageway level)")
        if lab_mask is not None:
            r = max(1, int(round(p.label_margin_m / grid.res)))
            near = ndimage.binary_dilation(ndimage.binary_closing(lab_mask, np.ones((5, 5), bool)),
                                           np.ones((2 * r + 1, 2 * r + 1), bool))
            m = low & near
        else:
            m = low
    else:
        m = lab_mask
    return clean_mask(m, grid, p, level, v, f, p.use_curbs or lab_mask is None), " + ".join(parts)


def clean_mask(m, grid, p: ScanSourceParams, level, v, f, by_level: bool) -> np.ndarray:
    """Gaps closed, holes filled, slivers opened away; components of a road's worth of surface kept, and
    with ``by_level`` only those on the lowest level (a yard or park is a curb above the carriageway)."""
    from scipy import ndimage

    r = max(1, int(round(0.75 / grid.res)))
    m = ndimage.binary_closing(m, np.ones((2 * r + 1, 2 * r + 1), bool), border_value=0)
    m = ndimage.binary_fill_holes(m)
    # away with slivers narrower than a lane half: what remains is carriageway
    k = max(1, int(round(0.5 * p.min_road_width_m / grid.res / 2)))
    m = ndimage.binary_opening(m, np.ones((2 * k + 1, 2 * k + 1), bool))
    lab, n = ndimage.label(m)
    if n > 1:  # keep components of at least a road's worth of surface...
        sizes = ndimage.sum(m, lab, range(1, n + 1)) * grid.res ** 2
        keep = np.flatnonzero(sizes >= p.min_road_width_m * p.min_road_length_m * 2) + 1
        if len(keep) > 1 and by_level:
            # ...on the lowest level: far from any road (a yard, a park) the raised ground is the local
            # lowest too, but it lies a curb above the carriageway's
            tri = v[f[level]] if level is not None else v[f]
            comp = grid.sample(lab, tri[:, :, :2].mean(1))
            cz = tri[:, :, 2].mean(1)
            med = {c: float(np.median(cz[comp == c])) for c in keep if (comp == c).any()}
            if med:
                low = min(med.values())
                keep = np.array([c for c in keep if med.get(c, low) <= low + 0.06])
        m = np.isin(lab, keep)
    return m


def _face_heights(v, f, fidx, grid) -> np.ndarray:
    """(h, w) float: the height of a face of ``fidx`` whose centre lies in each pixel; nan where none."""
    c = v[f[fidx]].mean(1)
    px = np.floor(grid.to_px(c[:, :2])).astype(int)
    ok = (px[:, 0] >= 0) & (px[:, 0] < grid.w) & (px[:, 1] >= 0) & (px[:, 1] < grid.h)
    z = np.full((grid.h, grid.w), np.nan)
    z[px[ok, 1], px[ok, 0]] = c[ok, 2]
    return z


def level_raster(v, f, fidx, grid, mask: np.ndarray | None = None, reach_m: float = 1.0) -> np.ndarray:
    """Height of the carriageway level per pixel, from the level faces ``fidx``; nearest filled. With the
    carriageway ``mask`` (grid pixels), a pixel of it farther than ``reach_m`` from every level face takes the
    height of the up-facing faces there instead: the carriageway's own surface, where the level test found
    lower ground nearby and none on the road (a sweep's far street beside a lower verge: nearest-filled from the
    verge, the road's height came out half a metre under its surface)."""
    from scipy import ndimage

    z = _face_heights(v, f, fidx, grid)
    if mask is not None and mask.any() and not np.isnan(z).all():
        from ..mesh2d import face_normals_z

        far = ndimage.distance_transform_edt(np.isnan(z)) * grid.res > reach_m
        own = _face_heights(v, f, np.flatnonzero(face_normals_z(v, f) > 0.9), grid)
        take = far & mask.astype(bool) & ~np.isnan(own)
        z[take] = own[take]
    if np.isnan(z).all():
        return np.zeros_like(z)
    idx = ndimage.distance_transform_edt(np.isnan(z), return_distances=False, return_indices=True)
    return z[idx[0], idx[1]]

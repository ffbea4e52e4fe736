"""Reconstruction diagnostics: distances between cloud, mesh and (optional) ground truth,
and a top-down distance colour map (PNG)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from twinkit import cityscapes


def stats(d: np.ndarray) -> dict:
    d = np.asarray(d, np.float64)
    if len(d) == 0:
        return {"mean": None, "median": None, "p95": None, "max": None}
    return {"mean": float(d.mean()), "median": float(np.median(d)), "p95": float(np.quantile(d, 0.95)),
            "max": float(d.max())}


def sample_surface(vertices: np.ndarray, faces: np.ndarray, n: int, seed: int = 0) -> np.ndarray:
    """Area-weighted uniform samples on a triangle mesh, (n, 3) float64."""
    from twinkit.mesh import face_areas

    rng = np.random.default_rng(seed)
    a = face_areas(vertices, faces)
    f = rng.choice(len(faces), size=n, p=a / a.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    w = np.stack([1 - s, s * (1 - r2), s * r2], axis=1)
    tri = vertices[faces[f]]
    return np.einsum("ij,ijk->ik", w, tri)


def colormap(values: np.ndarray, vmax: float) -> np.ndarray:
    """Blue (0) -> green -> yellow -> red (>= vmax), (n, 3) uint8."""
    anchors = np.array([[48, 18, 160], [30, 150, 230], [60, 200, 90], [250, 220, 40], [220, 30, 30]], np.float64)
    t = np.clip(np.asarray(values, np.float64) / max(vmax, 1e-12), 0, 1) * (len(anchors) - 1)
    i = np.minimum(np.floor(t).astype(int), len(anchors) - 2)
    f = (t - i)[:, None]
    return np.rint(anchors[i] * (1 - f) + anchors[i + 1] * f).astype(np.uint8)


def topdown_map(points: np.ndarray, values: np.ndarray, path: Path, vmax: float, size_px: int = 1024,
                title: str = "") -> None:
    """Orthographic top view: each pixel shows the largest value of the points in it."""
    from PIL import Image, ImageDraw

    lo, hi = points[:, :2].min(axis=0), points[:, :2].max(axis=0)
    ext = max(float((hi - lo).max()), 1e-9)
    W = size_px
    H = max(1, int(round(size_px * (hi[1] - lo[1]) / ext))) if (hi[1] - lo[1]) < ext else size_px
    W = max(1, int(round(size_px * (hi[0] - lo[0]) / ext)))
    col = np.clip(((points[:, 0] - lo[0]) / ext * (size_px - 1)).astype(int), 0, W - 1)
    row = np.clip(((hi[1] - points[:, 1]) / ext * (size_px - 1)).astype(int), 0, H - 1)
    best = np.full(H * W, -1.0)
    np.maximum.at(best, row * W + col, np.asarray(values, np.float64))
    # close the gaps between points: empty pixels take the max of their 3 x 3 neighbourhood
    from scipy.ndimage import maximum_filter

    grid = best.reshape(H, W)
    grown = maximum_filter(grid, size=3)
    best = np.where(grid >= 0, grid, grown).ravel()
    img = np.full((H * W, 3), 255, np.uint8)
    has = best >= 0
    img[has] = colormap(best[has], vmax)
    img = img.reshape(H, W, 3)
    # legend bar
    bar_h = 24
    legend = np.full((bar_h + 16, W, 3), 255, np.uint8)
    ramp = colormap(np.linspace(0, vmax, W), vmax)
    legend[4:4 + bar_h] = ramp[None]
    im = Image.fromarray(np.vstack([img, legend]))
    d = ImageDraw.Draw(im)
    d.text((4, H + 6), "0 m", fill=(0, 0, 0))
    d.text((max(0, W - 90), H + 6), f">= {vmax:.3f} m", fill=(0, 0, 0))
    if title:
        d.text((4, 4), title, fill=(0, 0, 0))
    im.save(str(path))


def mesh_with_distance_colors(vertices: np.ndarray, faces: np.ndarray, dist: np.ndarray, vmax: float):
    from twinkit.mesh import Mesh

    return Mesh(vertices=vertices, faces=faces, attrs={"colors": colormap(dist, vmax), "dist_to_cloud_m": dist})


def sample_surface_by_label(vertices: np.ndarray, faces: np.ndarray, face_labels: np.ndarray, n_total: int,
                            min_per_label: int = 20_000, seed: int = 0):
    """Area-weighted samples per face label: each label gets its share of ``n_total`` by area, at
    least ``min_per_label``. Returns (samples (q, 3), label per sample (q,), area m^2 per label dict)."""
    from twinkit.mesh import face_areas

    a = face_areas(vertices, faces)
    total = float(a.sum()) or 1.0
    pts, labs, areas = [], [], {}
    for c in np.unique(face_labels):
        idx = np.flatnonzero(face_labels == c)
        ac = float(a[idx].sum())
        if ac <= 0:
            continue
        n = max(int(min_per_label), int(round(n_total * ac / total)))
        pts.append(sample_surface(vertices, faces[idx], n, seed=seed + int(c)))
        labs.append(np.full(n, int(c), np.int32))
        areas[int(c)] = ac
    if not pts:
        return np.zeros((0, 3)), np.zeros(0, np.int32), {}
    return np.vstack(pts), np.concatenate(labs), areas


def coverage_by_label(dist_to_mesh: np.ndarray, labels: np.ndarray, areas: dict, *, within_m: float = 0.05,
                      dist_to_cloud: np.ndarray | None = None, observed_m: float = 0.10,
                      names: dict | None = None) -> dict:
    """Per label: share of the ground-truth area that has reconstructed surface within ``within_m``
    (``covered``); with ``dist_to_cloud`` (GT sample -> nearest input point) also the share of the
    area the scan saw (a point within ``observed_m``: ``observed``) and the coverage of that seen
    area (``covered_observed``). Also ``mean_dist_m`` (GT -> mesh, capped at 1 m, so holes count but
    unseen roofs do not dominate)."""
    names = dict(enumerate(cityscapes.NAMES)) if names is None else names
    out = {}
    for c, area in sorted(areas.items()):
        sel = labels == c
        d = dist_to_mesh[sel]
        row = {"id": int(c), "area_m2": round(float(area), 3), "covered": float((d <= within_m).mean()),
               "mean_dist_capped_m": float(np.minimum(d, 1.0).mean())}
        if dist_to_cloud is not None:
            seen = dist_to_cloud[sel] <= observed_m
            row["observed"] = float(seen.mean())
            row["covered_observed"] = float((d[seen] <= within_m).mean()) if seen.any() else None
        out[names.get(int(c), str(int(c)))] = row
    return out


def vertex_tree(vertices: np.ndarray):
    """A k-d tree of mesh vertices for nearest-vertex queries from far off the surface: split at sliding
    midpoints rather than medians (``balanced_tree=False``), which answers the metres-away queries of unseen
    roofs 5x faster on a 250k-vertex mesh (0.9 against 4.1 s for 370k of them), with the same distances."""
    from scipy.spatial import cKDTree

    return cKDTree(vertices, balanced_tree=False, compact_nodes=False)


def distance_near_exact(surface, vertices: np.ndarray, query: np.ndarray, near_m: float = 0.5, threads: int = -1,
                        tree=None) -> np.ndarray:
    """Distance (q,) float32 from points to a mesh surface, exact where the nearest mesh vertex is
    within ``near_m`` and the nearest-vertex distance (an upper bound, off by at most an edge)
    beyond. A closest-point query far from the surface costs 20-50x one near it, and most of the
    ground-truth samples of unseen roofs are metres away; this keeps those cheap. ``tree``: a k-d tree of
    ``vertices`` (:func:`vertex_tree`)."""
    tree = tree if tree is not None else vertex_tree(vertices)
    dv, _ = tree.query(query, workers=threads, distance_upper_bound=near_m)  # the near ones first: cheap
    near = np.isfinite(dv)
    if not near.all():
        dv[~near] = tree.query(query[~near], workers=threads)[0]
    out = dv.astype(np.float32)
    near &= dv <= near_m
    if near.any():
        out[near] = surface.distance(query[near])
    return out


#: the distance beyond which a point counts as lost by the mesh (its label cannot reach the twin: labels are
#: carried by the nearest vertex, and 0.5 m is past the size of a pole or a trunk)
FAR_M = 0.5
#: share of the cloud farther than FAR_M above which the run is degraded (docs/pointcloud.md "Coverage of sparse
#: scans": after the clean-up rules of issue 44 the real scans lose under 1 %, before them 6-10 %; 25 % means a
#: quarter of what was scanned has no surface, e.g. a far too sparse cloud or a trim far below its spacing)
FAR_MAX_SHARE = 0.25


def far_from_mesh(c2m: np.ndarray, classification: np.ndarray | None = None, far_m: float = FAR_M) -> dict:
    """The share of the cloud's points farther than ``far_m`` (m) from the mesh surface, overall and, when the
    file has classes (``classification``: (n,) ASPRS codes), per class by name with its point count.
    ``c2m``: (n,) cloud -> mesh distances (m)."""
    from twinkit.cityscapes import ASPRS_NAMES

    far = np.asarray(c2m) > far_m
    out: dict = {"far_m": far_m, "share": round(float(far.mean()), 5) if len(far) else 0.0,
                 "points": int(far.sum())}
    if classification is not None and len(classification) == len(far):
        cls = np.asarray(classification).astype(np.int64)
        per = {}
        for c in np.unique(cls):
            m = cls == c
            per[ASPRS_NAMES.get(int(c), f"class {int(c)}")] = {"points": int(m.sum()),
                                                                "share": round(float(far[m].mean()), 5)}
        out["per_class"] = per
    return out

"""Normal estimation (PCA on k nearest neighbours, open3d) and consistent orientation.

Orientation methods:

- ``scanner``: each normal points towards the position of the scanner that saw the point
  (E57 poses, gridded scans); the most reliable when known.
- ``mst``: consistent propagation over a minimum spanning tree of the k-nearest-neighbour
  graph weighted by 1 - |n_i . n_j| (Hoppe 1992; our own, open3d's version needs a Delaunay
  triangulation that fails on planar scenes), then one sign per connected part so that its
  near-horizontal surfaces face up (or, with none, its vertical ones face the street viewpoint);
  near-horizontal surfaces less than 1.5 m above the local ground face up whatever their part
  (:func:`face_up_near_ground`: seen from above by any street capture).
- ``up``: z-up for surfaces that are not vertical; vertical ones face a viewpoint at the
  cloud's centre 1.8 m above its lowest decile (a street's axis), as a scanner driving the
  street would see them. Cheap, for huge clouds.
- ``auto``: ``scanner`` when every point has a known scanner position, else ``mst`` up to
  ``mst_max_points``, else ``up``.
"""
from __future__ import annotations

import numpy as np


def estimate_normals(points: np.ndarray, k: int = 24, radius_m: float = 0.0) -> np.ndarray:
    """Unoriented unit normals, (n, 3) float32, from PCA of the k nearest neighbours
    (optionally limited to ``radius_m``)."""
    import open3d as o3d

    from twinkit.mesh import to_o3d_cloud

    pcd = to_o3d_cloud(points)
    param = (o3d.geometry.KDTreeSearchParamHybrid(radius=radius_m, max_nn=k) if radius_m > 0
             else o3d.geometry.KDTreeSearchParamKNN(knn=k))
    pcd.estimate_normals(param)
    return np.asarray(pcd.normals, dtype=np.float32)


def orient_normals(points: np.ndarray, normals: np.ndarray, method: str = "auto", *,
                   scanner_index: np.ndarray | None = None, scanner_positions: np.ndarray | None = None,
                   k: int = 16, mst_max_points: int = 1_500_000) -> tuple[np.ndarray, str]:
    """Return ``(oriented normals (n, 3) float32, method used)``."""
    normals = np.asarray(normals, dtype=np.float32).copy()
    have_scanner = (scanner_index is not None and scanner_positions is not None and len(scanner_positions) > 0
                    and np.isfinite(scanner_positions[np.clip(scanner_index, 0, len(scanner_positions) - 1)]).all())
    if method == "auto":
        method = "scanner" if have_scanner else ("mst" if len(points) <= mst_max_points else "up")
    if method == "scanner":
        if not have_scanner:
            raise ValueError("orientation 'scanner' needs a known scanner position for every point")
        to_scanner = scanner_positions[scanner_index] - points
        flip = np.einsum("ij,ij->i", to_scanner, normals) < 0
        normals[flip] *= -1
        return normals, method
    if method == "mst":
        return face_up_near_ground(points, _orient_mst(points, normals, k)), method
    if method == "up":
        z = points[:, 2]
        view = np.array([points[:, 0].mean(), points[:, 1].mean(), np.quantile(z, 0.1) + 1.8])
        vertical = np.abs(normals[:, 2]) < 0.3
        flip = np.where(vertical, np.einsum("ij,ij->i", view - points, normals) < 0, normals[:, 2] < 0)
        normals[flip] *= -1
        return normals, method
    raise ValueError(f"unknown normal orientation '{method}' (use auto, scanner, mst or up)")


def _orient_mst(points: np.ndarray, normals: np.ndarray, k: int = 12) -> np.ndarray:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree
    from scipy.spatial import cKDTree

    n = len(points)
    k = int(min(k, n - 1))
    _, nb = cKDTree(points).query(points, k=k + 1, workers=-1)
    i = np.repeat(np.arange(n), k)
    j = nb[:, 1:].ravel()
    ok = j < n
    i, j = i[ok], j[ok]
    w = 1.0 - np.abs(np.einsum("ij,ij->i", normals[i], normals[j])) + 1e-6
    g = coo_matrix((w, (i, j)), shape=(n, n)).tocsr()
    mst = minimum_spanning_tree(g)
    mst = mst + mst.T
    ncomp, comp = connected_components(mst, directed=False)
    parity = np.zeros(n, bool)
    seen = np.zeros(n, bool)
    for root in range(n):
        if seen[root]:
            continue
        order, pred = breadth_first_order(mst, root, directed=False, return_predecessors=True)
        seen[order] = True
        ch = order[1:]
        par = pred[ch]
        rel = np.einsum("ij,ij->i", normals[ch], normals[par]) < 0
        pl = parity.tolist()
        for c, p_, r in zip(ch.tolist(), par.tolist(), rel.tolist()):
            pl[c] = pl[p_] ^ r
        parity = np.asarray(pl, bool)
    out = normals.copy()
    out[parity] *= -1
    # one sign per connected part
    z = points[:, 2]
    view = np.array([points[:, 0].mean(), points[:, 1].mean(), np.quantile(z, 0.1) + 1.8])
    horiz = np.abs(out[:, 2]) > 0.7
    up_score = np.bincount(comp, weights=np.where(horiz, np.sign(out[:, 2]), 0.0), minlength=ncomp)
    view_score = np.bincount(comp, weights=np.where(horiz, 0.0, np.sign(np.einsum("ij,ij->i", view - points, out))),
                             minlength=ncomp)
    has_h = np.bincount(comp, weights=horiz.astype(float), minlength=ncomp) > 0
    flip_c = np.where(has_h, up_score < 0, view_score < 0)
    out[flip_c[comp]] *= -1
    return out.astype(np.float32)


def face_up_near_ground(points: np.ndarray, normals: np.ndarray, *, horizontal_z: float = 0.85,
                        seen_from_above_m: float = 1.5) -> np.ndarray:
    """``normals`` (n, 3) with every near-horizontal one (|z| >= ``horizontal_z``) on a point less than
    ``seen_from_above_m`` above the local ground turned to face up; a copy, float32.

    A street is captured from the ground, a car's roof or the air: a road, a pavement, a car's bonnet or a
    table below a scanner's height is seen from above. The propagation over the neighbour graph carries one
    sign along each connected part, and on a sparse capture (a lidar sweep's rings, one line of points
    each, whose normals are ill-posed) it turns whole ring segments of road upside down inside a part
    that faces up overall: the ground cells that the ground fill and Poisson need. The local ground is the
    lowest near-horizontal point within 4 m (:class:`twinkit.street.ground.LocalGround`'s window minimum),
    whatever its sign."""
    from twinkit.street.ground import LocalGround

    out = np.asarray(normals, np.float32).copy()
    horiz = np.abs(out[:, 2]) >= horizontal_z
    if not horiz.any():
        return out
    g = LocalGround(points[horiz], cell_m=0.5, window="min", window_m=4.0, min_window_cells=3)
    above = g.height(points[horiz])
    flip = np.zeros(len(out), bool)
    flip[np.flatnonzero(horiz)] = (out[horiz, 2] < 0) & (above < seen_from_above_m)
    out[flip] *= -1
    return out


def check_file_normals(points: np.ndarray, normals: np.ndarray, method: str = "auto", *,
                       scanner_index: np.ndarray | None = None, scanner_positions: np.ndarray | None = None,
                       min_share: float = 0.01) -> tuple[np.ndarray, dict]:
    """Normals from the file checked against a consistent orientation of the same lines (:func:`orient_normals`:
    towards the scanner where it is known, else propagated over the neighbour graph with each connected part's
    near-horizontal surfaces facing up). A normal that disagrees points into the surface. When more than
    ``min_share`` of them disagree, they are flipped (fewer: the file is kept as it is, the disagreement being
    the orientation's own noise on thin parts) -- unless flipping would leave more near-horizontal normals
    pointing down than the file has (then the reference is wrong: scanner positions that are not where the
    points were seen from). Returns (normals, metrics)."""
    n = np.asarray(normals, np.float32)
    oriented, used = orient_normals(points, n, method, scanner_index=scanner_index,
                                    scanner_positions=scanner_positions)
    disagree = np.einsum("ij,ij->i", n, oriented) < 0
    horiz = np.abs(n[:, 2]) > 0.7

    def down_share(a):
        return float((a[horiz, 2] < 0).mean()) if horiz.any() else 0.0

    share = float(disagree.mean()) if len(n) else 0.0
    flip = share > min_share
    out = np.where(disagree[:, None], -n, n).astype(np.float32) if flip else n
    kept_why = None
    if flip and down_share(out) > down_share(n) + 0.01:
        # the orientation would turn floors and roads upside down: its reference (scanner positions that are
        # not where the points were seen from, a part joined the wrong way) is the wrong one, not the file
        kept_why = (f"flipping would turn {100 * down_share(out):.1f} % of the near-horizontal normals down "
                    f"(now {100 * down_share(n):.1f} %)")
        out, flip = n, False
    return out, {"method": used, "disagreeing_share": round(share, 4), "flipped": int(disagree.sum()) if flip else 0,
                 "near_horizontal_down_before": round(down_share(n), 4),
                 "near_horizontal_down_after": round(down_share(out), 4), "min_share": min_share,
                 "kept_because": kept_why}


def cloud_normals(pts: np.ndarray, raw, params, name: str, log) -> tuple[np.ndarray | None, str | None,
                                                                          dict | None, dict | None]:
    """The normals read_cloud writes: the file's (re-oriented or checked), else estimated ones, else none.

    ``pts``: (n, 3) float64 points (site frame, m); ``raw``: the read cloud (its ``normals``, ``scanner``,
    ``scanner_positions``); ``params``: :class:`~twinkit_pointcloud.params.ReadCloudParams`. Returns
    (normals (n, 3) or None, their source "file" / "estimated" / None, the orientation record or None,
    the file normals' check record or None); logs what it did under ``name``.
    """
    normals = raw.normals
    normals_source = "file" if normals is not None else None
    orientation = None
    normals_check = None
    if normals is not None and params.reorient_existing_normals:
        normals, orientation = orient_normals(pts, normals, params.normals_orientation,
                                              scanner_index=raw.scanner, scanner_positions=raw.scanner_positions)
    elif normals is not None and params.file_normals_flip_share < 1:
        normals, normals_check = check_file_normals(pts, normals, params.normals_orientation,
                                                    scanner_index=raw.scanner,
                                                    scanner_positions=raw.scanner_positions,
                                                    min_share=params.file_normals_flip_share)
        say = log.warning if normals_check["flipped"] else log.info
        say("%s: normals from the file: %.1f %% point into the surface against a consistent orientation (%s)%s; "
            "near-horizontal normals pointing down %.1f %% -> %.1f %%", name,
            100 * normals_check["disagreeing_share"], normals_check["method"],
            f", {normals_check['flipped']} flipped" if normals_check["flipped"] else
            f", kept as they are ({normals_check['kept_because']})" if normals_check["kept_because"] else
            ", kept as they are",
            100 * normals_check["near_horizontal_down_before"], 100 * normals_check["near_horizontal_down_after"])
    if normals is None and params.estimate_normals:
        log.info("%s: no normals in the file: estimating them (k=%d)", name, params.normals_k)
        normals = estimate_normals(pts, k=params.normals_k)
        normals, orientation = orient_normals(pts, normals, params.normals_orientation,
                                              scanner_index=raw.scanner, scanner_positions=raw.scanner_positions)
        normals_source = "estimated"
    return normals, normals_source, orientation, normals_check

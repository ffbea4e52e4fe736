"""Post-processing of a Poisson mesh (thesis 3.4.2 / 4.3.1), in this order:

1. density trimming: drop vertices whose Poisson density is below a quantile (optional);
2. distance trimming ("bubbles"): drop vertices farther than ``max_dist_m`` from every input point,
   except (``gap_dist_m`` > 0) vertices that lie on the tangent plane of the nearby points
   (within ``gap_plane_m`` of it), no farther than ``gap_dist_m`` from them and with points on both
   sides (``two_sided``, so nothing grows past the edge of the scan): the surface that
   Poisson interpolates across the gaps between far-range scan lines on the ground (sparse,
   anisotropic sampling) is kept, bubbles (off the local plane) still go;
3. keep the large connected components;
4. repair non-manifold edges (drop the smallest faces around an edge shared by > 2 faces);
5. close holes whose boundary loop has at most ``max_hole_edges`` edges (fan around the loop's centroid);
6. (``fill_ground_cell_m`` > 0, needs the points' normals) fill the ground's occlusion shadows
   (behind parked cars, bicycles, ...) with grid patches, see :mod:`twinkit.surface.groundfill`;
7. per-vertex distance to the cloud (``dist_to_cloud_m``).

The module-level defaults keep the thesis's plain clean-up (no gap rule, no ground fill); the
``clean_mesh`` step of the pointcloud plugin turns both on (``CleanParams``); the tiles plugin
runs the same clean-up per tile. The topology helpers it uses (components, boundary loops, fan
fill) live in :mod:`twinkit.mesh.topology`.

Units: metres, site frame; ``points`` (p, 3) float64 and their ``normals`` (p, 3); the mesh is a
:class:`twinkit.mesh.Mesh`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twinkit.mesh import Mesh, compact, face_areas, vertex_normals
from twinkit.mesh.topology import boundary_loops, components, edge_face_incidence, remove_vertices
from twinkit.street.holes import fan_fill


@dataclass
class CleanOptions:
    max_dist_m: float = 0.10
    gap_dist_m: float = 0.0
    gap_plane_m: float = 0.02
    gap_k: int = 8
    gap_min_normal_z: float = 0.0
    density_quantile: float = 0.0
    min_component_faces: int = 200
    min_component_ratio: float = 0.0
    min_component_points: int = 0  # > 0: a component below min_component_faces stays when this many points lie on it
    local_trim_factor: float = 0.0  # > 0: the distance trim per vertex is at least this x the local point spacing
    local_trim_max_m: float = 0.5  # ... never more than this (m)
    repair_non_manifold: bool = True
    max_hole_edges: int = 60
    fill_ground_cell_m: float = 0.0
    fill_ground_max_gap_m: float = 8.0
    fill_ground_stitch: bool = True
    fill_ground_smooth_cells: int = 0  # the shadows' heights smoothed by a median this many cells square (groundfill)
    fill_ground_sliver_max_m: float = 0.10  # thin closed shells on the filled ground taken out first (groundfill)
    fill_ground_diagonal_gap_m: float = 3.0  # a last round of shadows along the diagonals, this short (groundfill)
    threads: int = -1
    loose_dist_m: float = 0.0  # vertices flagged by clean_mesh's ``loose`` mask are trimmed at this distance instead


def vertex_cloud_distance(vertices: np.ndarray, points: np.ndarray, threads: int = -1, tree=None) -> np.ndarray:
    """Distance (m) from every vertex to its nearest input point, (n,) float32."""
    from scipy.spatial import cKDTree

    tree = tree if tree is not None else cKDTree(points)
    d, _ = tree.query(vertices, k=1, workers=threads)
    return d.astype(np.float32)


def vertex_plane_distance(vertices: np.ndarray, points: np.ndarray, normals: np.ndarray, *, k: int = 8,
                          max_dist_m: float = 1.0, tree=None, threads: int = -1, min_normal_z: float = 0.0,
                          chunk: int = 500_000) -> np.ndarray:
    """Per vertex, the median distance to the tangent planes (point + normal) of its ``k`` nearest
    input points within ``max_dist_m`` (inf where none is that near; points whose normal has
    |z| < ``min_normal_z`` are ignored), (n,) float32."""
    from scipy.spatial import cKDTree

    tree = tree if tree is not None else cKDTree(points)
    out = np.full(len(vertices), np.inf, np.float32)
    nrm = np.asarray(normals, np.float32)
    for s in range(0, len(vertices), chunk):
        v = vertices[s:s + chunk]
        d, idx = tree.query(v, k=k, distance_upper_bound=max_dist_m, workers=threads)
        if k == 1:
            d, idx = d[:, None], idx[:, None]
        ok = np.isfinite(d)
        idx = np.where(ok, idx, 0)
        n = nrm[idx]
        pd = np.abs(np.einsum("ijk,ijk->ij", (v[:, None, :] - points[idx]).astype(np.float32), n))
        if min_normal_z > 0:
            ok &= np.abs(n[..., 2]) >= min_normal_z
        pd[~ok] = np.inf
        out[s:s + chunk] = np.median(pd, axis=1)  # inf when more than half are missing
    return out


def two_sided(vertices: np.ndarray, points: np.ndarray, normals: np.ndarray, reach_m: float, tree=None,
              threads: int = -1) -> np.ndarray:
    """True where a vertex has input points on both sides along its tangent plane: the nearest
    point is on one side; looking ``reach_m`` the other way, the point nearest there must lie
    within 60 degrees of that opposite direction and within ``2 * reach_m``. Separates the gap between two scan lines (kept)
    from the surface Poisson extends past the last scan line (not kept)."""
    from scipy.spatial import cKDTree

    tree = tree if tree is not None else cKDTree(points)
    if len(vertices) == 0:
        return np.zeros(0, bool)
    _, i1 = tree.query(vertices, workers=threads)
    u = points[i1] - vertices
    n = np.asarray(normals, np.float64)[i1]
    u -= np.sum(u * n, axis=1, keepdims=True) * n
    ln = np.linalg.norm(u, axis=1, keepdims=True)
    u = u / np.maximum(ln, 1e-12)
    _, i2 = tree.query(vertices - u * reach_m, workers=threads)
    w = points[i2] - vertices
    lw = np.linalg.norm(w, axis=1)
    # opposite: within 60 degrees of the direction away from the nearest point
    return (np.sum(w * u, axis=1) < -0.5 * lw) & (lw <= 2 * reach_m) & (ln[:, 0] > 1e-9)


def component_support(mesh: Mesh, face_label: np.ndarray, n: int, points: np.ndarray, within_m: float,
                      threads: int = -1) -> np.ndarray:
    """Per component (``face_label``: per-face component ids 0..n-1), how many input ``points`` (p, 3) have
    their nearest mesh vertex in it, at most ``within_m`` metres away: the samples the piece of surface
    stands on. (n,) int64."""
    from scipy.spatial import cKDTree

    assert mesh.faces is not None  # a mesh, not a cloud
    vlab = np.full(mesh.n_vertices, -1, np.int64)
    for k in range(3):
        vlab[mesh.faces[:, k]] = face_label
    used = np.flatnonzero(vlab >= 0)
    if len(used) == 0 or len(points) == 0:
        return np.zeros(n, np.int64)
    d, i = cKDTree(mesh.vertices[used]).query(points, workers=threads, distance_upper_bound=within_m)
    ok = np.isfinite(d)
    return np.bincount(vlab[used[i[ok]]], minlength=n)


def keep_large_components(mesh: Mesh, min_faces: int, min_ratio: float = 0.0, *, points: np.ndarray | None = None,
                          min_points: int = 0, within_m: float = 0.1, threads: int = -1) -> tuple[Mesh, int, int]:
    """Drop components with fewer faces than ``max(min_faces, min_ratio * largest)``, except (``min_points`` > 0
    and ``points`` given) those that at least ``min_points`` input points stand on (nearest vertex within
    ``within_m``, :func:`component_support`): a thin or far object scanned by a few points (a pole, a trunk,
    foliage at 30 m) makes a small piece of surface that is real; a stray point makes one alone.
    Returns (mesh, components before, components kept)."""
    assert mesh.faces is not None  # a mesh, not a cloud
    n, lab = components(mesh.n_vertices, mesh.faces)
    if n == 0:
        return mesh, 0, 0
    sizes = np.bincount(lab, minlength=n)
    thr = max(int(min_faces), int(min_ratio * sizes.max()))
    keep_c = sizes >= thr
    if min_points > 0 and points is not None and not keep_c.all():
        keep_c |= component_support(mesh, lab, n, points, within_m, threads) >= min_points
    if not keep_c.any():  # never empty the mesh by this rule: keep the largest
        keep_c[np.argmax(sizes)] = True
    return compact(mesh, keep_c[lab]), int(n), int(keep_c.sum())


def repair_non_manifold_edges(mesh: Mesh) -> tuple[Mesh, int]:
    """Remove the smallest faces at every edge shared by more than two faces, until all edges
    have at most two. Returns (mesh, faces removed)."""
    assert mesh.faces is not None  # a mesh, not a cloud
    removed = 0
    for _ in range(10):
        if mesh.n_faces == 0:
            break
        _, fe, counts = edge_face_incidence(mesh.faces)
        bad_e = counts > 2
        if not bad_e.any():
            break
        area = face_areas(mesh.vertices, mesh.faces)
        drop = np.zeros(mesh.n_faces, bool)
        fid = np.repeat(np.arange(mesh.n_faces), 3)
        eid = fe.ravel()
        sel = bad_e[eid]
        fid, eid = fid[sel], eid[sel]
        order = np.lexsort((-area[fid], eid))  # per edge, largest first
        fid, eid = fid[order], eid[order]
        first = np.r_[0, np.flatnonzero(np.diff(eid)) + 1]
        rank = np.arange(len(eid)) - np.repeat(first, np.diff(np.r_[first, len(eid)]))
        drop[fid[rank >= 2]] = True
        removed += int(drop.sum())
        mesh = compact(mesh, ~drop)
    return mesh, removed


def close_small_holes(mesh: Mesh, max_edges: int) -> tuple[Mesh, int]:
    """Fill every boundary loop of 3..``max_edges`` edges with a fan around a new centroid
    vertex (attributes: mean of the loop). Returns (mesh, holes closed)."""
    assert mesh.faces is not None  # a mesh, not a cloud
    if max_edges < 3 or mesh.n_faces == 0:
        return mesh, 0
    loops = [lp for lp in boundary_loops(mesh.faces) if len(lp) <= max_edges]
    return fan_fill(mesh, loops), len(loops)


def local_spacing(points: np.ndarray, k: int = 8, tree=None, threads: int = -1) -> np.ndarray:
    """Per input point, the point spacing around it on the same scale as the cloud's median nearest-neighbour
    distance (:mod:`twinkit.surface.density`), (p,) float32 metres: the local density
    ``rho = k / (pi r_k**2)`` from the radius ``r_k`` holding its ``k`` nearest neighbours, turned into the
    nearest-neighbour distance a uniform sampling of that density has (``0.5 / sqrt(rho)``). A single sweep's
    density falls with the square of the range; on scan lines ``r_k`` reaches the next line, so the gap
    between lines counts, not only the spacing along them."""
    from scipy.spatial import cKDTree

    tree = tree if tree is not None else cKDTree(points)
    k = int(min(k, len(points) - 1))
    if k < 1:
        return np.zeros(len(points), np.float32)
    d, _ = tree.query(points, k=k + 1, workers=threads)
    return (0.5 * d[:, -1] * np.sqrt(np.pi / k)).astype(np.float32)


def max_dist_per_vertex(vertices: np.ndarray, points: np.ndarray, opt: CleanOptions, tree) -> np.ndarray | float:
    """The distance trim's threshold: ``opt.max_dist_m``, or (``opt.local_trim_factor`` > 0) per vertex the
    larger of it and ``local_trim_factor`` x the :func:`local_spacing` of the vertex's nearest point, at
    most ``opt.local_trim_max_m``: where the samples are sparse (far range) the surface between them lies
    farther from the nearest one, and the same rule as the global trim (a factor of the spacing) keeps it."""
    if not (opt.local_trim_factor > 0) or len(vertices) == 0:
        return opt.max_dist_m
    sp = local_spacing(points, tree=tree, threads=opt.threads)
    _, i = tree.query(vertices, workers=opt.threads)
    cap = max(opt.max_dist_m, opt.local_trim_max_m)
    return np.clip(opt.local_trim_factor * sp[i], opt.max_dist_m, cap)


def trim_mask(vertices: np.ndarray, d: np.ndarray, points: np.ndarray, normals, opt: CleanOptions,
              tree) -> tuple[np.ndarray, int]:
    """The distance trim's decision: which vertices go (``d``: their distance to the points, ``tree``
    a cKDTree of ``points``). Farther than ``max_dist_m`` goes, unless the gap rule keeps it (up to
    ``gap_dist_m`` away, on the points' tangent plane, with points on both sides). Returns the mask
    and how many vertices the gap rule kept."""
    drop = d > max_dist_per_vertex(vertices, points, opt, tree)
    if not (opt.gap_dist_m > opt.max_dist_m and normals is not None and drop.any()):
        return drop, 0
    cand = np.flatnonzero(drop & (d <= opt.gap_dist_m))
    pd = vertex_plane_distance(vertices[cand], points, normals, k=opt.gap_k, max_dist_m=opt.gap_dist_m,
                               tree=tree, threads=opt.threads, min_normal_z=opt.gap_min_normal_z)
    on_plane = cand[pd <= opt.gap_plane_m]
    on_plane = on_plane[two_sided(vertices[on_plane], points, normals, opt.gap_dist_m, tree, opt.threads)]
    drop[on_plane] = False
    return drop, int(len(on_plane))


def _nothing_left(points: np.ndarray, max_dist_m: float) -> str:
    """Why the distance trim left no face: a cloud too small or too sparse for a surface, else a frame mismatch."""
    n = len(points)
    spacing = float("nan")
    if n >= 2:
        from scipy.spatial import cKDTree

        spacing = float(np.median(cKDTree(points).query(points, k=2)[0][:, 1]))
    if n < 1000 or spacing > max_dist_m:
        return (f"no face is within {max_dist_m} m of the cloud after trimming: the cloud has only {n} points "
                f"(median spacing {spacing:.3g} m), too few or too sparse for a surface; use a denser or larger capture")
    return (f"no face is within {max_dist_m} m of the cloud ({n} points, median spacing {spacing:.3g} m) after "
            f"trimming; check that the mesh and the cloud share a frame")


def clean_mesh(mesh: Mesh, points: np.ndarray, opt: CleanOptions, log=None,
               normals: np.ndarray | None = None, colors: np.ndarray | None = None,
               loose=None) -> tuple[Mesh, dict]:
    """Run the whole clean-up; returns (clean mesh with ``dist_to_cloud_m``, report dict).
    ``normals`` (of the points) enable the gap rule of the distance trim (``opt.gap_dist_m``) and
    the ground fill (``opt.fill_ground_cell_m``); ``colors`` colour the ground patches.
    ``loose`` (a function of the vertices giving a bool mask, with ``opt.loose_dist_m`` > 0): the
    vertices it flags are only trimmed beyond ``loose_dist_m`` (tiles keep the surface near their
    seams loosely trimmed; the exact trim is done once on the merged mesh, so both sides of a
    seam get the same decision). The report then has ``loose_samples``: the flagged vertices, their
    normals, and whether the exact rule would have kept them."""
    from scipy.spatial import cKDTree

    rep: dict = {"input": {"vertices": mesh.n_vertices, "faces": mesh.n_faces}}
    tree = cKDTree(points)
    if opt.density_quantile > 0 and "density" in mesh.attrs:
        thr = float(np.quantile(mesh.attrs["density"], opt.density_quantile))
        mesh = remove_vertices(mesh, mesh.attrs["density"] < thr)
        rep["density_trim"] = {"threshold": thr, "vertices": mesh.n_vertices, "faces": mesh.n_faces}
    d = vertex_cloud_distance(mesh.vertices, points, opt.threads, tree)
    rep["before_distance_trim"] = _dist_stats(d)
    if opt.max_dist_m > 0:
        drop, kept_gap = trim_mask(mesh.vertices, d, points, normals, opt, tree)
        if loose is not None and opt.loose_dist_m > 0:
            lm = np.asarray(loose(mesh.vertices), bool)
            # what the exact rule said there, for the caller (tiles pass it on to the merge)
            if "normals" in mesh.attrs and len(mesh.attrs["normals"]) == mesh.n_vertices:
                nrm = mesh.attrs["normals"][lm]
            else:
                assert mesh.faces is not None  # a mesh, not a cloud
                nrm = vertex_normals(mesh.vertices, mesh.faces[lm[mesh.faces].any(axis=1)])[lm]  # faces there only
            rep["loose_samples"] = {"points": mesh.vertices[lm].copy(), "normals": np.asarray(nrm, np.float32),
                                    "keep": ~drop[lm]}
            drop[lm] = d[lm] > opt.loose_dist_m
        mesh = remove_vertices(mesh, drop)
        rep["distance_trim"] = {"max_dist_m": opt.max_dist_m, "local_trim_factor": opt.local_trim_factor,
                                "local_trim_max_m": opt.local_trim_max_m, "gap_dist_m": opt.gap_dist_m,
                                "gap_plane_m": opt.gap_plane_m, "kept_on_plane": kept_gap,
                                "vertices": mesh.n_vertices, "faces": mesh.n_faces}
    if mesh.n_faces == 0:
        from twinkit import InputError

        raise InputError(_nothing_left(points, opt.max_dist_m))
    mesh, n_before, n_kept = keep_large_components(mesh, opt.min_component_faces, opt.min_component_ratio,
                                                   points=points, min_points=opt.min_component_points,
                                                   within_m=max(opt.max_dist_m, 1e-6), threads=opt.threads)
    rep["components"] = {"before": n_before, "kept": n_kept, "vertices": mesh.n_vertices, "faces": mesh.n_faces,
                         "min_points": opt.min_component_points}
    if opt.repair_non_manifold:
        mesh, removed = repair_non_manifold_edges(mesh)
        rep["non_manifold"] = {"faces_removed": removed, "faces": mesh.n_faces}
    if opt.max_hole_edges >= 3:
        mesh, closed = close_small_holes(mesh, opt.max_hole_edges)
        rep["holes"] = {"closed": closed, "max_hole_edges": opt.max_hole_edges,
                        "vertices": mesh.n_vertices, "faces": mesh.n_faces}
    if opt.fill_ground_cell_m > 0 and normals is not None:
        from .groundfill import GroundFillOptions, fill_ground_holes

        mesh, frep = fill_ground_holes(mesh, points, normals, colors,
                                       GroundFillOptions(cell_m=opt.fill_ground_cell_m,
                                                         max_gap_m=opt.fill_ground_max_gap_m, threads=opt.threads,
                                                         stitch=opt.fill_ground_stitch,
                                                         smooth_cells=opt.fill_ground_smooth_cells,
                                                         sliver_max_m=opt.fill_ground_sliver_max_m,
                                                         diagonal_gap_m=opt.fill_ground_diagonal_gap_m),
                                       tree=tree)
        frep.update(vertices=mesh.n_vertices, faces=mesh.n_faces)
        rep["ground_fill"] = frep
        if log is not None:
            sl = (frep.get("slivers_removed") or {}).get("components", 0)
            dg = frep.get("diagonal_cells", 0)
            log.info("ground fill: %d cells (%.1f m^2) of occlusion shadow filled%s%s", frep.get("filled_cells", 0),
                     frep.get("area_m2", 0.0),
                     f", over {sl} thin shells around lone scan lines taken out first" if sl else "",
                     f"; {dg} cells found along the diagonals (the notches of a staircase edge)" if dg else "")
    d = vertex_cloud_distance(mesh.vertices, points, opt.threads, tree)
    mesh.attrs["dist_to_cloud_m"] = d
    rep["output"] = {"vertices": mesh.n_vertices, "faces": mesh.n_faces, "dist_to_cloud_m": _dist_stats(d)}
    return mesh, rep


def _dist_stats(d: np.ndarray) -> dict:
    if len(d) == 0:
        return {"mean": None, "p95": None, "max": None}
    return {"mean": float(np.mean(d)), "p95": float(np.quantile(d, 0.95)), "max": float(np.max(d))}

"""The parts of ``merge_tiles``: the tile meshes read, the seams' state before and after stitching, the
seam bands trimmed, the ground filled, and the ``tile_seams.json`` report with its metrics."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from twinkit import InputError


def read_tile_meshes(paths: list, tiles: list[dict]) -> tuple[list[int], list[dict], list]:
    """(indices of the tiles with faces, their plan items, their meshes) from the tile meshes ``paths``
    (one per plan item; a mesh without faces gets an empty (0, 3) int64 face array). InputError when
    every tile is empty."""
    from twinkit.mesh import read_ply

    meshes = [read_ply(p) for p in paths]
    for m in meshes:
        if m.faces is None:
            m.faces = np.zeros((0, 3), np.int64)
    keep = [k for k, m in enumerate(meshes) if m.n_faces]
    if not keep:
        raise InputError("merge_tiles: every tile is empty; check the cloud and max_dist_m")
    return keep, [tiles[k] for k in keep], [meshes[k] for k in keep]


def seams_before(meshes: list, planes: list, tol_m: float) -> tuple[int, float, dict]:
    """The tiles' seams before stitching: (open edges on the seam planes, seam length (m, each tile
    brings one border so half the border length), the concatenated tiles' edge counts)."""
    from .edges import edge_counts
    from .seam_stats import seam_border_length, seam_boundary_edges
    from .stitch import _concat

    cat = meshes[0]
    for m in meshes[1:]:
        cat = _concat(cat, m)
    before = seam_boundary_edges(cat, planes, tol_m)
    seam_len = seam_border_length(cat, planes, tol_m) / 2  # each tile brings one border
    return before, seam_len, edge_counts(cat.faces)


def read_votes(paths):
    """The tiles' votes near the seams (a tile's own full-resolution surface and its verdict under the
    exact trim), all tiles together, as rows (x, y, z, nx, ny, nz, keep, tile); None when no tile list
    is given."""
    if not paths:
        return None
    out = []
    for t, p in enumerate(paths if isinstance(paths, list) else [paths]):
        try:
            with np.load(p) as z:
                k = np.asarray(z["keep"], np.float64)
                P = np.asarray(z["points"], np.float64)
                out.append(np.hstack([P, np.asarray(z["normals"], np.float64), k[:, None], np.full((len(P), 1), t)]))
        except Exception as exc:
            raise InputError(f"{p}: cannot read the tile's seam votes ({exc}); re-run reconstruct_tiles "
                             f"(twinkit ... 'rerun=[reconstruct_tiles]')") from exc
    return np.vstack(out) if out else None


def tile_trim(comments: list) -> dict:
    """The trim parameters a tile mesh was made with (its ``twinkit-tiles trim ...`` comment); {} if absent."""
    for c in comments or []:
        if c.startswith("twinkit-tiles trim "):
            w = c.split()[2:]
            try:
                return {w[i]: float(w[i + 1]) for i in range(0, len(w) - 1, 2)}
            except ValueError:
                return {}
    return {}


def trim_bands(merged, planes: list, trim: dict, cloud, params, threads: int, vote_paths, log):
    """The seam bands of the stitched mesh trimmed to the points as the tiles were (``trim``: the tiles'
    trim parameters), then the seam holes closed again. Returns (mesh, holes closed, the trim's record)."""
    from .seam_trim import trim_seam_bands
    from .stitch import close_seam_holes

    votes = read_votes(vote_paths) if params.vote_radius_m > 0 or params.vote_reach_m > 0 else None
    merged, band_rep = trim_seam_bands(
        merged, planes, cloud.vertices, cloud.normals, trim["seam_band_m"], trim["max_dist_m"],
        trim.get("gap_dist_m", 0.0), trim.get("gap_plane_m", 0.02), int(trim.get("min_component_faces", 200)),
        int(trim.get("max_hole_edges", 60)), threads, votes=votes, vote_radius_m=params.vote_radius_m,
        vote_plane_m=params.vote_plane_m, vote_reach_m=params.vote_reach_m,
        hanging_tol_m=params.seam_tol_m if params.drop_hanging_faces else 0.0)
    del votes
    merged, holes = close_seam_holes(merged, planes, params.max_hole_edges, params.seam_tol_m)
    log.info("seam bands (%.2f m): %d of %d vertices trimmed (the tiles' votes kept %d and dropped %d), "
             "%d small components removed, %d faces left hanging on a seam removed, %d holes closed",
             band_rep["band_m"], band_rep["vertices_trimmed"], band_rep["vertices_in_band"],
             band_rep["vertices_kept_by_votes"], band_rep["vertices_dropped_by_votes"],
             band_rep["components_removed"], band_rep.get("hanging_faces_removed", 0),
             band_rep["holes_closed"])
    return merged, holes, band_rep


def open_seams(runs: list[dict]) -> tuple[int, dict, int, dict]:
    """The open edges on the seams from their runs: (cracks: open edges of tile faces, the cracks by what
    lies across the plane {facing_surface, surface_ends}, border crossings: the strip edges (the mesh's
    own border crossing a seam), their lengths in m {facing_surface, surface_ends, strip_edges})."""
    cracks = sum(r["tile_edges"] for r in runs)
    kinds = {"facing_surface": sum(r["facing_edges"] for r in runs)}
    kinds["surface_ends"] = cracks - kinds["facing_surface"]
    ends = sum(r["edges"] for r in runs) - cracks
    facing_len = sum(r["facing_length_m"] for r in runs)
    open_len = {"facing_surface": round(facing_len, 3),
                "surface_ends": round(sum(r["tile_edges_length_m"] for r in runs) - facing_len, 3),
                "strip_edges": round(sum(r["length_m"] - r["tile_edges_length_m"] for r in runs), 3)}
    return cracks, kinds, ends, open_len


def fill_ground(merged, cloud, params, threads: int, log):
    """The ground's occlusion shadows filled (``params.fill_ground_*``): (mesh, the fill's record or None
    when the cloud has no normals)."""
    from twinkit.surface.groundfill import GroundFillOptions, fill_ground_holes

    if cloud.normals is None:
        return merged, None
    merged, ground = fill_ground_holes(merged, cloud.vertices, cloud.normals, cloud.colors,
                                       GroundFillOptions(cell_m=params.fill_ground_cell_m,
                                                         max_gap_m=params.fill_ground_max_gap_m, threads=threads))
    log.info("ground fill: %d cells (%.1f m^2) of occlusion shadow filled",
             ground.get("filled_cells", 0), ground.get("area_m2", 0.0))
    return merged, ground


def near_lines_report(merged, planes: list, band_m: float) -> dict:
    """Open border near the seams vs. near control lines half-way between them, per metre of surface cut
    (the seams add cracks where their figure is higher); with the control planes as [axis, value]."""
    from .seam_labels import control_planes
    from .seam_stats import open_near_line_sets

    controls = control_planes(planes, merged.vertices.min(axis=0), merged.vertices.max(axis=0))
    near_lines = open_near_line_sets(merged, {"seams": planes, "controls": controls}, band_m)
    near_lines["control_planes"] = [["xyz"[a], round(v, 4)] for a, v in controls]
    return near_lines


def merge_report(tiles: list, keep: list, planes: list, merged, tile_attr: np.ndarray, seams: list,
                 before_total: dict, *, before: int, after_zipper: int, holes: int, cracks: int, kinds: dict,
                 ends: int, seam_len: float, open_len: dict, runs: list, png: Path, outside: int, ground: dict | None,
                 ground_border: dict | None, band_rep: dict | None, near_lines: dict) -> dict:
    """The ``tile_seams.json`` record: the tiles, the planes ([axis, value]), the seams' open edges
    before, after the zipper and after (by kind, with their lengths in m and their runs), the edge counts
    of the tiles and of the merged mesh, its stitch faces (``tile_attr`` < 0), the ground fill, the open
    border, the band trim, the open border near lines, and each seam's gaps (mean, max in mm)."""
    from .edges import edge_counts

    after_total = edge_counts(merged.faces)
    report = {
        "tiles": len(tiles), "tiles_with_faces": len(keep), "planes": [["xyz"[a], v] for a, v in planes],
        "seam_boundary_edges_before": before, "seam_boundary_edges_after_zipper": after_zipper,
        "seam_holes_closed": holes, "seam_boundary_edges_after": cracks,
        "seam_open_facing_surface": kinds["facing_surface"], "seam_open_surface_ends": kinds["surface_ends"],
        "seam_border_crossings": ends, "seam_length_m": round(seam_len, 3), "seam_open_length_m": open_len,
        "seam_open_runs": [r for r in runs if r["kind"] != "border_crossing"], "seam_map_png": png.name,
        "faces_outside_core": outside,
        "non_manifold_edges": after_total["non_manifold_edges"],
        "non_manifold_edges_in_tiles": before_total["non_manifold_edges"],
        "boundary_edges_before": before_total["boundary_edges"], "boundary_edges_after": after_total["boundary_edges"],
        "stitched_faces": int((tile_attr < 0).sum()), "vertices": merged.n_vertices, "faces": merged.n_faces,
        "ground_fill": ground, "open_border": ground_border, "seam_band_trim": band_rep,
        "open_near_lines": near_lines, "seams": seams,
    }
    gaps = [s["gap_mean_mm"] for s in seams if s["gap_mean_mm"] is not None]
    report["gap_mean_mm"] = round(float(np.mean(gaps)), 3) if gaps else None
    report["gap_max_mm"] = max((s["gap_max_mm"] for s in seams if s["gap_max_mm"] is not None), default=None)
    return report


def merge_metrics(report: dict, near_lines: dict, ground_border: dict | None, measured: dict) -> dict:
    """merge_tiles' metrics: the report's counts, the open border near seams and controls, the measure's."""
    return {k: report[k] for k in ("tiles", "faces", "vertices", "seam_boundary_edges_before",
                                   "seam_boundary_edges_after", "seam_open_facing_surface", "seam_open_surface_ends",
                                   "seam_holes_closed", "seam_border_crossings", "seam_length_m", "faces_outside_core",
                                   "non_manifold_edges", "non_manifold_edges_in_tiles", "boundary_edges_before",
                                   "boundary_edges_after", "stitched_faces", "gap_mean_mm", "gap_max_mm")} | {
        "open_near_seams_per_m": near_lines["seams"]["open_per_section"],
        "open_border_inside_m": (ground_border or {}).get("inside_m"),
        "open_border_inside_m_per_m2": (ground_border or {}).get("inside_m_per_m2"),
        "open_near_controls_per_m": near_lines["controls"]["open_per_section"]} | measured


def log_merge(log, n_tiles: int, report: dict, seam_len: float, near_lines: dict, line_band_m: float,
              png_name: str) -> None:
    """Log the merge: faces, seam edges before and after, open seam length, stitch faces; near-line figures."""
    log.info("merged %d tiles: %d faces; seam boundary edges %d -> %d (%.2f m of %.1f m of seam open), "
             "%d stitch faces; seam map %s", n_tiles, report["faces"], report["seam_boundary_edges_before"],
             report["seam_boundary_edges_after"], report["seam_open_length_m"]["facing_surface"]
             + report["seam_open_length_m"]["surface_ends"], seam_len, report["stitched_faces"], png_name)
    ns, nc = near_lines["seams"], near_lines["controls"]
    if ns["open_per_section"] is not None and nc["open_per_section"] is not None:
        log.info("open border within %.2f m of a line, per m of surface it cuts: seams %.3f, control lines %.3f",
                 line_band_m, ns["open_per_section"], nc["open_per_section"])

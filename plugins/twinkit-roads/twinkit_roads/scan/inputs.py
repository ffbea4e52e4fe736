"""The scan road source's inputs: which labels, the cloud's sampling (curbs or not), the cloud's points,
the true lane centre lines."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from twinkit import InputError
from twinkit import artefacts as A
from twinkit.cityscapes import ROAD

from .model import ScanSourceParams


def read_labels(which: str, n_vertices: int, mesh_name: str, in_labels_npy: Path | None,
                in_gt_labels_npy: Path | None, log) -> tuple[str, Path | None, np.ndarray | None]:
    """The label source ``which`` resolved (auto: predicted when labels.npy exists, else none), its file and
    the per-vertex labels ((n_vertices,) int64 CityScapes ids; None for none). Raises InputError when the
    chosen file is missing, unreadable or of another length."""
    if which == "auto":
        which = "predicted" if in_labels_npy is not None else "none"
        if in_labels_npy is None:
            log.info("road_source=scan: no labels.npy before this step; the curbs alone draw the roads")
    src = {"predicted": in_labels_npy, "gt": in_gt_labels_npy, "none": None}[which]
    if which == "none":
        return which, src, None
    if src is None:
        what = ("the segmentation's labels.npy (the steps before fetch_roads)" if which == "predicted"
                else "gt_labels.npy (a site with ground truth: the demo)")
        raise InputError(f"road_source=scan with labels={which} needs {what}; none was written before this "
                         "step. Use road_source.labels=none for the curbs alone")
    return which, src, A.read_labels(src, n_vertices, mesh_name).astype(np.int64)


def cloud_sampling(in_points_meta_json: Path | None, in_points_ply: Path | None = None) -> tuple[float | None,
                                                                                              float | None]:
    """(the cloud's median point spacing (m), the share of its ground sampled in patches rather than single scan
    lines (:func:`twinkit.surface.density.measure` ``ground_two_way_share``)) from points_meta.json's density
    block, one read; what an older file lacks is measured from points.ply when given
    (:func:`twinkit.artefacts.read_points_meta`). (None, None) without points_meta.json."""
    if in_points_meta_json is None:
        return None, None
    ply = in_points_ply if in_points_ply is not None and Path(in_points_ply).is_file() else None
    meta = A.read_points_meta(in_points_meta_json, points=ply)
    return meta.spacing_m, meta.ground_two_way_share


def level_params(p: ScanSourceParams, labels_for_mask: np.ndarray | None, curbs: bool, two_way: float | None,
                 log) -> ScanSourceParams:
    """``p``, with ``use_curbs`` off where the capture cannot show a kerb step (its ground mostly single scan
    lines: ``two_way`` under ``level_min_two_way_share``) and road labels can draw the carriageway instead."""
    import dataclasses

    if (labels_for_mask is None or not curbs or not p.use_curbs or two_way is None
            or two_way >= p.level_min_two_way_share):
        return p
    log.info("road_source=scan: %.0f %% of the cloud's ground is sampled in patches (the rest single scan lines, "
             "under level_min_two_way_share=%g): no kerb step to measure; the road labels alone draw the "
             "carriageway (as use_curbs=false)", 100 * two_way, p.level_min_two_way_share)
    return dataclasses.replace(p, use_curbs=False)


def choose_curbs(labels: np.ndarray | None, spacing: float | None, p: ScanSourceParams, src: Path | None,
                 log) -> tuple[np.ndarray | None, bool]:
    """The labels the carriageway mask uses and whether the curbs draw it. A cloud coarser than
    ``curb_max_spacing_m`` shows no curbs: with labels, the paved-labelled grey ground is the carriageway (no
    road or sidewalk label at all: no carriageway, no roads)."""
    coarse = spacing is not None and p.curb_max_spacing_m > 0 and float(spacing) > p.curb_max_spacing_m
    labels_for_mask = None
    if labels is not None:
        if coarse:
            labels_for_mask = labels
        elif not (labels == ROAD).any():
            log.warning("road_source=scan: no vertex is labelled road in %s; the curbs alone draw the roads",
                        src.name)
        else:
            labels_for_mask = labels
    curbs = not (labels_for_mask is not None and coarse)
    if not curbs:
        log.info("road_source=scan: point spacing %.3f m is coarser than curb_max_spacing_m=%g: no curbs to "
                 "see; the carriageway is the paved-labelled grey ground the scanner measured, and no sidewalk "
                 "lanes are made",
                 float(spacing), p.curb_max_spacing_m)
    return labels_for_mask, curbs


def cloud_xy(in_points_ply: Path) -> np.ndarray:
    """(n, 2) float64 x, y of the cloud's points (site frame)."""
    return np.asarray(A.read_points(in_points_ply).vertices, np.float64)[:, :2]


def read_truth(in_roads_truth_json: Path | None) -> list[np.ndarray] | None:
    """The true lane centre lines ((k, 2) site-frame x, y each) of roads_truth.json; None when not given."""
    if in_roads_truth_json is None:
        return None
    return [np.asarray(ln["points"], float)[:, :2] for ln in A.read_roads_truth(in_roads_truth_json).lanes] or None

"""The scan file's own classes (ASPRS codes of a LAS/LAZ, or an E57/PLY ``classification`` field) as a
prior of the label fusion (docs/segmentation.md "File classes").

``read_cloud`` keeps the field in points.ply (``classification``, uint8). Each mesh vertex takes the class
of its nearest point when that point lies within ``spacings`` times the cloud's median point spacing
(farther: the vertex is a surface the scan did not sample there, and the file says nothing about it).
:data:`twinkit.cityscapes.ASPRS_TO_TRAINIDS` says which CityScapes classes each code allows; the prior is
1 for those and ``factor`` for the others, 1 everywhere for a silent code (0, 1, noise, water, ...).
The fusion multiplies it into the 3D-context prior, so a vertex whose views voted only for classes the
file rules out (a car on ASPRS ground) has its votes explained away and takes an allowed label from its
neighbours, exactly as a geometric cue does.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np


def point_spacing(points: np.ndarray, sample: int = 20000, seed: int = 0) -> float:
    """Median distance from a point to its nearest other point (a random sample of at most ``sample``)."""
    from scipy.spatial import cKDTree

    pts = np.asarray(points, np.float64)
    if len(pts) < 2:
        return 0.0
    tree = cKDTree(pts)
    idx = np.random.default_rng(seed).choice(len(pts), min(sample, len(pts)), replace=False)
    d, _ = tree.query(pts[idx], k=2)
    d = d[:, 1]
    d = d[d > 0]
    return float(np.median(d)) if len(d) else 0.0


def classes_on_vertices(points: np.ndarray, codes: np.ndarray, vertices: np.ndarray, spacings: float = 3.0,
                        threads: int = 1) -> tuple[np.ndarray, float, float]:
    """(per-vertex code (0 = nothing within reach), point spacing, the reach in metres)."""
    from scipy.spatial import cKDTree

    spacing = point_spacing(points)
    reach = float(spacings) * spacing if spacing > 0 else 0.0
    out = np.zeros(len(vertices), np.uint8)
    if reach <= 0 or not len(points):
        return out, spacing, reach
    d, i = cKDTree(np.asarray(points, np.float64)).query(np.asarray(vertices, np.float64),
                                                          distance_upper_bound=reach, workers=max(1, threads))
    hit = np.isfinite(d)
    out[hit] = np.asarray(codes, np.uint8)[i[hit]]
    return out, spacing, reach


def file_class_prior(vertex_codes: np.ndarray, factor: float) -> tuple[np.ndarray, np.ndarray]:
    """(prior (n, 19): 1 for the classes the vertex's file class allows, ``factor`` for the others, 1 on
    silent vertices; ``voting`` (n,) bool: the vertex's class says something)."""
    from twinkit.cityscapes import asprs_allowed

    allowed = asprs_allowed()[np.asarray(vertex_codes, np.uint8)]
    voting = allowed.any(axis=1)
    prior = np.where(allowed, 1.0, float(factor))
    prior[~voting] = 1.0
    return prior, voting


def read_point_classes(points_ply: Path):
    """(points (n, 3), codes (n,) uint8) of a points.ply whose vertices carry ``classification``; None
    when the file has no such field (the header is read first, so a cloud without classes costs nothing)."""
    from twinkit.artefacts import read_points
    from twinkit.artefacts.files import ply_header

    try:
        if "classification" not in ply_header(points_ply).get("vertex", (0, []))[1]:
            return None
    except ValueError:  # not a PLY: no classes to read
        return None
    m = read_points(points_ply)
    codes = m.attrs.get("classification")
    if codes is None:
        return None
    return np.asarray(m.vertices, np.float64), np.asarray(codes).astype(np.uint8)


def summary(vertex_codes: np.ndarray, voting: np.ndarray, allowed_prior: np.ndarray, before: np.ndarray,
            after: np.ndarray) -> dict:
    """What the file's classes did: vertices per code, and the share of the voting vertices whose label the
    file rules out, with the views' plain vote (``before``) and after the fusion (``after``)."""
    from twinkit.cityscapes import ASPRS_NAMES, N_CLASSES

    codes, counts = np.unique(vertex_codes, return_counts=True)
    ok = allowed_prior >= 1.0

    def against(lab):
        lab = np.asarray(lab)
        known = voting & (lab < N_CLASSES)
        bad = np.zeros(len(lab), bool)
        bad[known] = ~ok[np.nonzero(known)[0], lab[known].astype(np.int64)]
        return int(bad.sum()), int(known.sum())

    b, nb = against(before)
    a, na = against(after)
    return {"vertices_with_class": int(voting.sum()), "vertices": int(len(vertex_codes)),
            "per_code": {f"{int(c)} {ASPRS_NAMES.get(int(c), 'user/reserved')}": int(k) for c, k in zip(codes, counts)},
            "against_file_before": round(b / max(nb, 1), 4), "against_file_after": round(a / max(na, 1), 4)}


def vertex_file_classes(params, ctx, points_ply, vertices):
    """(prior (n, 19) or None, voting (n,), per-vertex codes, info) from the cloud's own classes: the
    classification of ``points_ply`` carried to the mesh's ``vertices`` (n, 3) (``params``: backproject's
    ``file_classes``, ``file_class_spacings``, ``file_class_factor``); None and why where it is not used."""
    if not params.file_classes:
        return None, None, None, {"used": False, "why": "file_classes: false"}
    if points_ply is None:
        return None, None, None, {"used": False, "why": "no points.ply"}
    got = read_point_classes(Path(points_ply))
    if got is None:
        return None, None, None, {"used": False, "why": "the cloud has no classification field"}
    pts, codes = got
    vcodes, spacing, reach = classes_on_vertices(pts, codes, vertices, params.file_class_spacings,
                                                 max(1, int(getattr(ctx, "threads", 1) or 1)))
    prior, voting = file_class_prior(vcodes, params.file_class_factor)
    info = {"used": bool(voting.any()), "point_spacing_m": round(spacing, 4), "reach_m": round(reach, 4),
            "factor": params.file_class_factor}
    if not voting.any():
        ctx.log.info("file classes: none of the cloud's classes (%s) says anything the labels use; not used",
                     ", ".join(str(int(c)) for c in np.unique(codes)[:12]))
        return None, None, None, dict(info, why="only silent codes (0 never classified, 1 unclassified, ...)")
    return prior, voting, vcodes, info

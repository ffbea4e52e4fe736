"""The ``classify_geometry`` step: the 3D classifier's class probabilities on the mesh's vertices.

Writes ``geometry_votes.npy`` (float32, vertices x 19: the probabilities carried to each vertex from the
classified cloud points near it; zero rows where none is near) and ``geometry_labels.ply`` (the mesh in
the palette colours of the most probable class, for a look).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from twinkit import StepContext
from twinkit import artefacts as A
from twinkit.ranges import param


@dataclass
class ClassifyGeometryParams:
    enabled: bool = param(True, help="Run the 3D classifier; false writes all-zero votes (no 3D source).")
    base_voxel_m: float = param(0.1, gt=0, le=1.0,
                                help="Side (m) of the voxels the cloud is thinned to, one point each, before the "
                                     "features (density normalisation; the shipped model was trained at 0.1).")
    ground_window_m: float = param(8.0, gt=0,
                                   help="Window (m) of the local ground's opening: wider than any vehicle roof, so "
                                        "roofs are not ground.")
    smooth_m: float = param(0.25, ge=0, le=2.0,
                            help="Side (m) of the voxels over whose 3 x 3 x 3 block each classified point's class "
                                 "probabilities are averaged (geometric mean) on a colourless capture, where the "
                                 "geometry leads; 0 = each point alone. Measured on the real labelled sweeps in "
                                 "docs/segmentation.md (\"3D classifier\").")
    smooth_coloured: bool = param(False,
                                  help="Smooth a coloured capture's probabilities too. Off: there the views and "
                                       "backproject's segments and Potts smoothing already pool neighbours, and "
                                       "smoothing twice cost demo seed 3 1.5 mIoU.")
    prior_coloured: bool = param(False,
                                 help="Apply the model's class-prior correction (the class shares of streets as "
                                      "captured, not the balanced ones it was trained on) on a coloured capture too. "
                                      "Off: there the views lead on the rare classes (signs, lights, bicycles) and "
                                      "the correction, which is for the geometry deciding alone, cost demo seeds 3 "
                                      "and 7 2-5 mIoU (docs/segmentation.md \"3D classifier\").")
    turns: int = param(4, ge=1, le=16,
                       help="Classify the cloud this many times, turned about the vertical by 90 / turns degrees "
                            "each time, and average the probabilities (geometric mean): the features' voxel grids are "
                            "square to the axes, and where a grid cuts a surface is noise. 1 = one pass. Measured "
                            "on the real labelled sweeps in docs/segmentation.md (\"Turned passes\"). Colourless "
                            "captures only, unless turns_coloured.")
    turns_coloured: bool = param(False,
                                 help="Turn a coloured capture's passes too. Off: there the views lead, and the "
                                      "turned passes cost demo seeds 0 / 3 / 7 0.3 / 1.5 / 0.0 mIoU (seed 3's signs "
                                      "61 -> 49: a sign is a few voxels, and one pass's answer for it fused better "
                                      "with the views).")
    ground_alpha: float = param(0.995, ge=0, lt=1,
                                help="Spread the road / sidewalk / terrain probabilities along the smooth ground, "
                                     "not across kerbs (its noise measured on the capture itself): how far, as "
                                     "the share each point takes from its neighbours (0.995: a few metres on a "
                                     "0.1 m grid; 0 = off). Colourless captures only, unless ground_coloured. "
                                     "Chosen on generated sweeps, measured on the real labelled sweeps in "
                                     "docs/segmentation.md (\"Ground diffusion\").")
    ground_coloured: bool = param(False,
                                  help="Spread a coloured capture's ground probabilities too. Off: there the views "
                                       "tell road from pavement by their look, and backproject's Potts smoothing "
                                       "already pools them.")
    vote_radius_m: float = param(0.4, gt=0,
                                 help="A vertex takes the probabilities of the classified points within this "
                                      "distance (m); farther vertices get a zero row.")
    vote_neighbours: int = param(8, ge=1, le=64, help="At most this many nearest classified points vote per vertex.")
    vote_fill_radius_m: float = param(1.5, ge=0,
                                      help="A vertex with no classified point within vote_radius_m (a sparse capture's "
                                           "ground fill between scan lines) takes the probabilities of those within "
                                           "this distance (m) instead; 0 or at most vote_radius_m = off (such vertices "
                                           "then take their mesh neighbours' labels in backproject). Colourless "
                                           "captures only, unless vote_fill_coloured. Measured in "
                                           "docs/segmentation.md (\"Votes for the fill between rings\").")
    vote_fill_coloured: bool = param(False,
                                     help="Give a coloured capture's far vertices the farther points' votes too. Off: "
                                          "there the views vote on them, and the farther votes cost demo seed 0 "
                                          "0.3 mIoU.")
    cut_tolerance_m: float = param(
        0.3, ge=0, le=2.0,
        help="On a single spinning sweep (ground sampled in rings: twinkit.surface.rings finds the sensor and its "
             "top beam), a point whose 0.5 m column reaches within this of the top beam's cone was cut by the scan, "
             "so its height is unknown: the classifier's 'wall', told from a building by its height, counts as "
             "building there. 0 = off.")
    model: str = param("", path=(".npz", ".json"), help="Model stem (path without .npz/.json); empty = the model shipped with the plugin.")
    ground_split: bool = param(True,
                               help="Share each point's ground probability between road, sidewalk and terrain as the "
                                    "ground model says (a model of those three alone, trained on captures whose "
                                    "intensity follows each surface's material: asphalt dark, paving and grass "
                                    "brighter); which points are ground stays the main model's answer. Measured on "
                                    "the real labelled sweeps in docs/segmentation.md (\"A ground model\"). "
                                    "Colourless captures with an intensity only (without one the ground model "
                                    "reads what the main model reads), unless ground_split_coloured.")
    ground_split_coloured: bool = param(False, help="Split a coloured capture's ground by the ground model too.")
    ground_weight: float = param(1.0, ge=0, le=1,
                                 help="How much of the ground split is the ground model's (geometric weight; 1 = its "
                                      "split alone, 0 = the main model's).")
    ground_model: str = param("", path=(".npz", ".json"),
                              help="Ground model stem (path without .npz/.json); empty = the one shipped with the "
                                   "plugin.")


def classify_geometry(params: ClassifyGeometryParams, ctx: StepContext, *, in_points_ply: Path,
                      in_textured_mesh_ply: Path, out_geometry_votes_npy: Path, out_geometry_labels_ply: Path,
                      in_points_meta_json: Path | None = None) -> dict:
    """Classify the cloud's points from their geometry (and intensity) and carry the probabilities to the
    mesh's vertices (docs/segmentation.md "3D classifier")."""
    import numpy as np

    from twinkit.cityscapes import N_CLASSES, PALETTE
    from twinkit.mesh import write_colored_ply
    from twinkit_segmentation.geometry.classify import classify_cloud, votes_at
    from twinkit_segmentation.geometry.features import has_intensity
    from twinkit_segmentation.geometry.model import GROUND_MODEL_NAME, load_model

    t0 = time.perf_counter()
    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    n = len(mesh.vertices)
    if not params.enabled:
        A.write_class_votes(out_geometry_votes_npy, np.zeros((n, N_CLASSES), np.float32))
        write_colored_ply(out_geometry_labels_ply, mesh.vertices, mesh.faces, np.full((n, 3), 128, np.uint8),
                          comment="twinkit-segmentation: 3D classifier off")
        return {"enabled": False, "vertices": n}
    from twinkit_segmentation.fusion import capture_kind

    cloud = A.read_points(in_points_ply)
    inten = cloud.attrs.get("intensity")
    kind = capture_kind(cloud.colors)
    smooth_m = params.smooth_m if (kind == "colourless" or params.smooth_coloured) else 0.0
    prior = kind == "colourless" or params.prior_coloured
    turns = params.turns if (kind == "colourless" or params.turns_coloured) else 1
    ground_alpha = params.ground_alpha if (kind == "colourless" or params.ground_coloured) else 0.0
    model = load_model(params.model or None)
    split = params.ground_split and (kind == "colourless" or params.ground_split_coloured) and has_intensity(inten)
    ground_model = load_model(params.ground_model or None, GROUND_MODEL_NAME) if split else None
    if params.ground_split and kind == "colourless" and not split:
        ctx.log.info("3D classifier: the cloud has no intensity, so the ground model (which reads road, pavement "
                     "and grass apart by it) stays off; the main model splits the ground")
    t_read = time.perf_counter() - t0
    res = classify_cloud(cloud.vertices, inten, model, base_voxel_m=params.base_voxel_m,
                         ground_window_m=params.ground_window_m, smooth_m=smooth_m, prior=prior,
                         turns=turns, ground_alpha=ground_alpha, ground_model=ground_model,
                         ground_weight=params.ground_weight)
    sensor, walls_cut = _cut_by_top_beam(params, ctx, cloud, res, in_points_meta_json)
    t1 = time.perf_counter()
    votes = votes_at(cloud.vertices[res.base], res.proba, mesh.vertices, radius_m=params.vote_radius_m,
                     neighbours=params.vote_neighbours, workers=max(1, int(ctx.threads)))
    far = np.flatnonzero(votes.sum(axis=1) <= 0)
    filled = 0
    fill_m = params.vote_fill_radius_m if (kind == "colourless" or params.vote_fill_coloured) else 0.0
    if fill_m > params.vote_radius_m and len(far):
        votes[far] = votes_at(cloud.vertices[res.base], res.proba, mesh.vertices[far],
                              radius_m=fill_m, neighbours=params.vote_neighbours,
                              workers=max(1, int(ctx.threads)))
        filled = int((votes[far].sum(axis=1) > 0).sum())
    A.write_class_votes(out_geometry_votes_npy, votes)
    has = votes.sum(axis=1) > 0
    lab = np.where(has, votes.argmax(axis=1), 255).astype(np.uint8)
    cols = np.where(has[:, None], PALETTE[np.minimum(lab, N_CLASSES - 1)], 0).astype(np.uint8)
    write_colored_ply(out_geometry_labels_ply, mesh.vertices, mesh.faces, cols, labels=lab,
                      comment="twinkit-segmentation: 3D classifier labels")
    t_votes = time.perf_counter() - t1
    hist = np.bincount(lab[has], minlength=N_CLASSES)
    if res.ground is not None and res.ground["noise_m"] is None:
        ctx.log.warning("3D classifier: ground diffusion skipped: %d ground points, too few near pairs to measure "
                        "the ground's noise", res.ground["points"])
    ctx.log.info("3D classifier: %d points -> %d base points; %.1f%% of %d vertices without a point within %.2f m "
                 "(%d of them given the points' within %.2f m), %.1f%% without any; timings %s", len(cloud.vertices),
                 len(res.base), 100 * len(far) / max(n, 1), n, params.vote_radius_m, filled, fill_m,
                 100 * (1 - has.mean()), res.seconds)
    return {"points": int(len(cloud.vertices)), "base_points": int(len(res.base)), "vertices": n,
            "vertices_without_votes": int((~has).sum()), "share_without_votes": round(float(1 - has.mean()), 4),
            "vertices_voted_from_farther": filled,
            "intensity": inten is not None, "capture": kind, "smooth_m": smooth_m, "prior": prior, "turns": turns,
            "ground_alpha": ground_alpha, "ground_diffusion": res.ground, "sensor": sensor, "walls_cut": walls_cut,
            "model": model.meta.get("name", params.model or "shipped"),
            "ground_model": ground_model.meta.get("name", params.ground_model or "shipped") if ground_model else None,
            "vertex_classes": {str(c): int(k) for c, k in enumerate(hist) if k},
            "seconds": {**res.seconds, "read": round(t_read, 3), "votes": round(t_votes, 3),
                        "total": round(time.perf_counter() - t0, 3)}}


def _cut_by_top_beam(params: ClassifyGeometryParams, ctx: StepContext, cloud, res,
                     in_points_meta_json: Path | None) -> tuple[dict | None, int]:
    """On a single spinning sweep, the classifier's walls in columns the top beam cut count as building
    (``res.proba`` replaced); (the sweep's sensor or None, how many base points that moved)."""
    from twinkit.cityscapes import WALL
    from twinkit.surface.density import RING_CAPTURE_SHARE
    from twinkit.surface.rings import ring_sensor
    from twinkit_segmentation.backproject_parts import capture_two_way_share
    from twinkit_segmentation.geometry.classify import cut_walls

    if params.cut_tolerance_m <= 0:
        return None, 0
    two_way = capture_two_way_share(in_points_meta_json, cloud)  # known: no need to look for rings
    sensor = ring_sensor(cloud.vertices) if two_way is None or two_way < RING_CAPTURE_SHARE else None
    if sensor is None:
        return None, 0
    proba, cut = cut_walls(cloud.vertices[res.base], res.proba, sensor, params.cut_tolerance_m)
    walls_cut = int((cut & (res.proba.argmax(axis=1) == WALL)).sum())
    res.proba = proba
    ctx.log.info("3D classifier: a single spinning sweep (sensor at %.1f, %.1f, top beam %.1f deg); %d of %d points "
                 "in columns the top beam cut (height unknown), %d of them walls counted as buildings",
                 *sensor["xy"], sensor["top_deg"], int(cut.sum()), len(cut), walls_cut)
    return sensor, walls_cut

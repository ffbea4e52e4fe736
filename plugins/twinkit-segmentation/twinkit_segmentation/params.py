"""The parameters of the view-based segmentation's steps (oversegment ... import_labels, in step order)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import List

from twinkit.ranges import param
from twinkit.surface.density import RING_CAPTURE_SHARE


@dataclass
class FelzenszwalbParams:
    k_threshold: float = param(0.3, ge=0, help="Felzenszwalb's k: larger = larger segments.")
    min_vertices: int = param(10, ge=0,
                              help="Merge segments smaller than this into a neighbour along the lightest edge; 0 = "
                                   "off.")
    max_vertices: int = param(5000, ge=0, help="Never grow a segment beyond this many vertices; 0 = unlimited.")
    normal_weight: float = param(1.0, ge=0,
                                 help="Weight of the normal difference (1 - n1.n2, squared on convex edges) in an "
                                      "edge's cost.")
    colour_weight: float = param(1.0, ge=0,
                                 help="Weight of the RGB distance (0..1) in an edge's cost; 0 = geometry only.")


@dataclass
class NoSegmentsParams:
    pass


@dataclass
class SampleViewsParams:
    max_views: int = param(-1, ge=0, also=(-1,),
                           help="Keep at most this many views, as whole camera positions (all their heights and "
                                "headings) spread over the site in farthest-point order. 0 = all; -1 = auto "
                                "(auto_max_views).")
    auto_max_views: int = param(480, ge=1,
                                help="The view budget of max_views=-1 (rendering and the 2D model take about 0.25 s "
                                     "a view on 2 cores: 480 views are about 2 minutes).")
    colourless_views: bool = param(False,
                                   help="Sample, render and segment views of a colourless capture too. Off (the "
                                        "default): a cloud without colours gets no views and its labels come from "
                                        "the 3D classifier (classify_geometry); its grey renders added nothing beside "
                                        "it on generated or real captures (docs/segmentation.md \"The grey views' "
                                        "worth\").")


@dataclass
class RenderParams:
    max_empty_fraction: float = param(0.6, ge=0, le=1,
                                      help="Drop views whose image is more than this share background.")
    fill_holes: bool = param(True,
                             help="Paint background below the horizon (a hole in the mesh or the capture's edge, "
                                  "never sky) with the nearest surface's colour, so the 2D model does not read "
                                  "sky-blue patches in the street; false = plain sky-blue background everywhere.")
    max_hole_px: float = param(16.0, ge=0,
                               help="fill_holes: a background gap at most 2x this wide (px) is a hole; wider = past "
                                    "the capture's edge, left as background.")
    min_signal_std: float = param(4.0, ge=0,
                                  help="A view whose mesh pixels vary less than this (standard deviation of the "
                                       "grey level, 0..255) is blank: the 2D model reads nothing from a flat grey "
                                       "silhouette.")
    max_blank_share: float = param(0.5, ge=0, le=1,
                                   help="The run is marked degraded when more than this share of the views is "
                                        "blank.")


@dataclass
class PhotoViewsParams:
    source: str = param("photos", choices=("photos", "rendered", "both"),
                        help="Which views to label: photos (the registered photos), rendered (views.json, as "
                             "render_views), or both.")
    long_side_px: int = param(1024, ge=0,
                              help="Downscale photos to this long side (px), the scale the CityScapes 2D models "
                                   "expect; 0 = full size.")
    min_coverage: float = param(0.1, ge=0, le=1,
                                help="Drop a photo whose pose sees the mesh in fewer than this share of its pixels "
                                     "(it missed the mesh).")
    max_empty_fraction: float = param(0.6, ge=0, le=1,
                                      help="Rendered views: drop those with more than this share background (as "
                                           "render_views).")
    max_photos: int = param(0, ge=0, help="Use at most this many photos, evenly spread in file order; 0 = all.")
    max_views: int = param(0, ge=0,
                           help="Rendered views sampled here (when no views.json is wired): at most this many; 0 = "
                                "all.")


@dataclass
class PredictParams:
    soft_votes: bool = param(False, help="Vote with the softmax probabilities instead of one vote per pixel.")
    vote_per_view: bool = param(True,
                                help="Each view gives each vertex it sees one vote in total, shared by its pixels' "
                                     "classes (false: one vote per pixel).")
    batch_views: int = param(4, ge=1, le=1024,
                             help="Views sent to the 2D model at once; lower it when the model runs out of memory.")
    save_pngs: bool = param(True,
                            help="Write predictions/<view>.png (a palette PNG whose pixel value is the trainId).")


@dataclass
class BackprojectParams:
    use_segments: bool = param(True,
                               help="Vote per segment of the over-segmentation, blended with the vertex's own votes "
                                    "(false: per vertex only).")
    segment_weight: float = param(0.5, ge=0, le=1,
                                  help="Share of the segment's vote against the vertex's own (1 = the segment "
                                       "only).")
    ignore_classes: List[int] = param(default_factory=lambda: [10], ge=0, le=255,
                                      help="trainIds outside the target set, whose votes are ignored (10 = sky).")
    class_weights: List[float] = param(default_factory=list, ge=0,
                                       help="One weight per class (19, in trainId order) multiplying its votes; "
                                            "empty = all 1.")
    min_votes: float = param(0.0, ge=0, help="Vertices with fewer votes than this stay unlabelled.")
    fill_unlabelled: bool = param(True, help="Vertices no view saw take their neighbours' label.")
    context: bool = param(True,
                          help='Scale the blended vote by geometric cues of the mesh (docs/segmentation.md "3D '
                               'context in the vote"); false = no cues (with smooth_beta 0 too: the plain blended '
                               "vote).")
    context_cues: List[str] = param(default_factory=lambda: ["ground", "raised", "high", "curb", "column", "mounted",
                                                             "low", "narrow"], free=True,
                                    help="Which geometric cues act (of ground, raised, high, curb, column, mounted, "
                                         "low, narrow, slender). slender is off by default: it helps only where the "
                                         'model votes fence at all (docs/segmentation.md "Shape cues").')
    ground_window_m: float = param(3.0, gt=0, help="metres: the local ground's window (street.ground.LocalGround, opening); wider than the widest vehicle (2.55 m)")
    max_curb_m: float = param(0.30, ge=0,
                              help="An up-facing vertex at most this high (m) above the local ground is ground (the "
                                   "highest curb).")
    min_object_m: float = param(0.50, ge=0,
                                help="A vertex more than this (m) above the local ground is not road, sidewalk or "
                                     "terrain.")
    max_vehicle_m: float = param(4.70, ge=0,
                                 help="A vertex more than this (m) above the local ground is no vehicle or person "
                                      "(above the tallest bus or truck).")
    min_curb_m: float = param(0.05, ge=0, help="The lowest curb step (m).")
    band_width_m: float = param(4.0, ge=0, help="A sidewalk lies at most this far (m) from its curb.")
    context_factor: float = param(0.1, ge=0, le=1,
                                  help="Prior (vote factor) of a class the geometry rules out (ground, raised, high "
                                       "cues).")
    curb_factor: float = param(0.2, ge=0, le=1,
                               help="Prior (vote factor) of road on a raised band beside the carriageway.")
    curb_face: bool = param(True,
                            help="The curb's own face and rounded edge count as the band (CityScapes labels them "
                                 "sidewalk).")
    band_default: bool = param(True, help="Band vertices whose votes the cues explained away become sidewalk.")
    min_retained: float = param(0.2, ge=0, le=1,
                                help="A vertex whose cues leave less than this share of its votes is decided by its "
                                     "neighbours; 0 = off.")
    keep_share: float = param(1.0, ge=0, le=1,
                              help="The floor: a vertex whose own votes give one class at least this share (from at "
                                   "least keep_votes votes) keeps the plain vote's label, no cue acts; 0 = off.")
    keep_votes: float = param(32.0, ge=0, help="The floor (keep_share) needs at least this many votes (views).")
    smooth_beta: float = param(1.0, ge=0,
                               help="Potts smoothing on the vertex graph: the weight of the neighbours' labels; 0 = "
                                    "off.")
    smooth_iters: int = param(5, ge=0, help="Iterations of the Potts smoothing.")
    file_classes: bool = param(True,
                               help="Use the scan file's own classes (ASPRS codes in points.ply's classification) "
                                    'as a prior beside the views (docs/segmentation.md "File classes").')
    file_class_factor: float = param(0.1, ge=0, le=1,
                                     help="A class the file's classification rules out (a car on ASPRS ground) "
                                          "keeps this factor of its votes; the same strength as context_factor.")
    file_class_spacings: float = param(3.0, gt=0,
                                       help="A vertex takes the class of its nearest point within this many point "
                                            "spacings.")
    cues_with_geometry: List[str] = param(default_factory=lambda: ["ground", "curb", "mounted"], free=True,
                                          help="Of context_cues, those that still act where geometry_votes.npy is "
                                               "wired: the cues that still added on the generated captures beside the "
                                               'classifier (docs/segmentation.md "Fusion"); the others read what '
                                               "the classifier already reads.")
    cue_gates: bool = param(True,
                            help="Gate the shape and curb cues by what the capture resolves at each vertex (point "
                                 'support and noise from points.ply; docs/segmentation.md "Cue gates").')
    furniture_geometry_share: float = param(0.1, ge=0, le=1,
                                            help="Where the 3D classifier speaks, the furniture cues (column, "
                                                 "mounted) act only where it gives pole, light and sign together at "
                                                 "least this share: a crown's fragment floating free in a sparse "
                                                 "scan is foliage to its multi-scale features (docs/segmentation.md "
                                                 '"Cue gates"); 0 = off.')
    furniture_min_two_way_share: float = param(RING_CAPTURE_SHARE, ge=0, le=1,
                                               help="The furniture cues (column, mounted) act only on a capture whose "
                                                    "ground is sampled in patches on at least this share "
                                                    "(points_meta.json density.ground_two_way_share): a single "
                                                    "spinning sweep cuts crowns and hedges into ring fragments that "
                                                    "float free and thin as a post would (docs/segmentation.md \"Cue "
                                                    "gates\"); 0 = off.")
    curb_min_two_way_share: float = param(RING_CAPTURE_SHARE, ge=0, le=1,
                                          help="Where the 3D classifier speaks, the curb cue acts only on a capture "
                                               "whose ground is sampled in patches on at least this share "
                                               "(points_meta.json density.ground_two_way_share): on a single "
                                               "spinning sweep it reads the rings near the sensor as kerbs, and the "
                                               "classifier's ground model already tells asphalt from paving by "
                                               "their intensity and the kerbs it sees (docs/segmentation.md \"A "
                                               'ground model"). 0 = no such gate.')
    geometry_floor_share: float = param(0.7, ge=0, le=1,
                                        help="On a colourless capture sampled in rings (ground two-way share under "
                                             "geometry_floor_max_two_way_share: a single spinning sweep), a vertex "
                                             "whose 3D-classifier votes give one class at least this share keeps it "
                                             "against the cues and the smoothing, as near-unanimous views do where "
                                             "they lead (docs/segmentation.md \"The classifier's floor on a "
                                             "sweep\"); 0 = off.")
    geometry_floor_max_two_way_share: float = param(RING_CAPTURE_SHARE, ge=0, le=1,
                                                    help="The geometry floor acts on captures whose ground is sampled "
                                                         "in patches on less than this share (points_meta.json "
                                                         "density.ground_two_way_share); a dense capture's mesh "
                                                         "resolves what the cues read.")
    fusion_weights: str = param("", free=True, path=True,
                                help="The views' and the geometry's weights per capture kind (a JSON file written by "
                                     "python -m twinkit_segmentation.fusion calibrate); empty = the plugin's "
                                     'shipped fusion_weights.json (docs/segmentation.md "Fusion").')
    low_confidence: float = param(0.5, ge=0, le=1,
                                  help="A fused label whose probability is under this is low-confidence (counted, "
                                       "and shown in confidence.png).")


@dataclass
class TransferGtParams:
    rule: str = param("face", choices=("face", "vertex"),
                      help="face: the label of the nearest ground-truth face (per-vertex labels where the faces "
                           "have none); vertex: that face's corner nearest the closest point, from per-vertex "
                           "labels (export_demo's stand-in labels.npy).")
    max_distance_m: float = param(0.5, gt=0,
                                  help="Vertices farther than this (m) from any ground-truth face stay unlabelled "
                                       "(255).")


@dataclass
class EvaluateParams:
    classes: List[int] = param(default_factory=list, ge=0, le=255,
                               help="trainIds to average the scores over; empty = those present in the ground "
                                    "truth.")


@dataclass
class ImportLabelsParams:
    pass

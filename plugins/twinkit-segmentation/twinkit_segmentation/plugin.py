"""twinkit entry point of twinkit-segmentation: segmenters, view samplers, the oracle image model, steps.

Importing this module imports nothing heavy (numpy, open3d, moderngl load inside the steps).
"""
from __future__ import annotations

from twinkit import hookimpl

from twinkit_segmentation import steps as S
from twinkit_segmentation import views as V
from twinkit_segmentation.geometry import step as G
from twinkit_segmentation.oracle import OracleParams, build_oracle
from twinkit_segmentation.preflight import classify_geometry_preflight
from twinkit_segmentation.report import twinkit_register_report_sections  # noqa: F401 (this plugin's sections of the run report)


@hookimpl
def twinkit_register_segmenters(register):
    register("felzenszwalb", S.oversegment, params=S.FelzenszwalbParams,
             description="Felzenszwalb over-segmentation of the mesh graph (normals, convexity, colour) -> segments.npy")
    register("vertices", S.no_oversegment, params=S.NoSegmentsParams,
             description="No over-segmentation: every vertex is a segment (ablation)")


@hookimpl
def twinkit_register_view_samplers(register):
    register("auto_street", V.build("auto_street"), params=V.AutoStreetParams)
    register("street_points", V.build("street_points"), params=V.StreetPointsParams)
    register("uniform", V.build("uniform"), params=V.UniformParams)
    register("random", V.build("random"), params=V.RandomParams)
    register("combined", V.build("combined"), params=V.CombinedParams)


@hookimpl
def twinkit_register_image_models(register):
    register("oracle", build_oracle, params=OracleParams,
             description="Ground truth through the renderer's vertex map (tests the 3D side exactly)")


@hookimpl
def twinkit_register_steps(register):
    register("sample_views", S.sample_views, params=S.SampleViewsParams, uses=("view_sampler",))
    register("render_views", S.render_views, params=S.RenderParams)
    register("photo_views", S.photo_views, params=S.PhotoViewsParams, uses=("view_sampler",))
    register("predict_views", S.predict_views, params=S.PredictParams, uses=("image_model",))
    register("classify_geometry", G.classify_geometry, params=G.ClassifyGeometryParams,
             preflight=classify_geometry_preflight)
    register("backproject", S.backproject, params=S.BackprojectParams)
    register("transfer_gt_labels", S.transfer_gt_labels, params=S.TransferGtParams)
    register("evaluate_segmentation", S.evaluate_segmentation, params=S.EvaluateParams)
    register("import_labels", S.import_labels, params=S.ImportLabelsParams)

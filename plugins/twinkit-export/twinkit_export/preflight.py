"""The exporters' preflight (twinkit/engine/preflight.py runs it before the first step): what the CARLA
package will need, found in seconds instead of after the meshing and the segmentation."""
from __future__ import annotations


def carla_package_preflight(site, params, inputs) -> list[str]:
    """``carla_package`` with ``frame=carla`` (the default): the site has a georeference (the package's frame
    is true north at the base point, carla_frame.py)."""
    from twinkit.geo.frame import georeference_problem

    if getattr(params, "frame", "carla") != "carla":
        return []
    problem = georeference_problem(
        site, "the CARLA package (frame=carla: its map is placed at the base point for CARLA's geolocation)",
        "or give the recipe's carla step params: {frame: site} (CARLA's geolocation is then wrong)")
    return [problem] if problem else []

"""Georeference: the one place that says where a site is and how coordinates become site-frame metres.

- :mod:`twinkit.geo.frame` -- :class:`SiteFrame` (the site frame: local <-> projected <-> WGS84 lon/lat,
  heights, the PROJ string for netconvert, lon/lat boxes) and :func:`check_bbox`.
- :mod:`twinkit.geo.crs` -- CRS helpers (:func:`parse_crs`, :func:`unit_factors`, :func:`short_crs`,
  :func:`base_point_in`) and the rules that bring a file's coordinates into the site frame
  (:func:`to_site_frame`, :func:`apply_frame`, :class:`FrameInfo`).
- :mod:`twinkit.geo.georef` -- :func:`site_georef`, the georeference block written into every export.
- :mod:`twinkit.geo.similarity` -- :func:`closed_form_similarity` (the one least-squares similarity, 2D/3D,
  :class:`SimilarityTransform`) and :func:`fit_similarity`, the robust camera-centres -> GPS fit.

pyproj (the ``twinkit[geo]`` extra) is imported inside the functions that need it, so importing this
package costs only numpy. See docs/georeferencing.md.
"""
from __future__ import annotations

from twinkit.geo.crs import (LARGE_COORD_M, FrameInfo, apply_frame, base_height, base_point_in,
                             check_base_point_area, horizontal, outside_area_of_use, parse_crs, short_crs,
                             site_dict, to_site_frame, unit_factors, utm_epsg)
from twinkit.geo.frame import PROJ_TOLERANCE_M, SiteFrame, check_bbox
from twinkit.geo.georef import FRAME, site_georef
from twinkit.geo.similarity import Similarity, SimilarityTransform, closed_form_similarity, fit_similarity

__all__ = [
    "FRAME", "LARGE_COORD_M", "PROJ_TOLERANCE_M", "FrameInfo", "SiteFrame", "Similarity", "SimilarityTransform",
    "apply_frame", "closed_form_similarity",
    "base_height", "base_point_in", "check_bbox", "fit_similarity", "horizontal", "parse_crs", "short_crs",
    "site_dict", "site_georef", "to_site_frame", "unit_factors", "check_base_point_area", "outside_area_of_use",
    "utm_epsg",
]

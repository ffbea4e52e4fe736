"""The site georeference block written into every export (FBX/USD/glTF metadata, the CARLA package)."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

FRAME = "site local: metres, x east, y north, z up; origin = base point; projected = local + base_point_projected"


def site_georef(site: Mapping[str, Any] | None, site_json: Path | None = None) -> dict:
    """{crs, lat, lon, alt, projected_x/y/z (when known), frame} from site.json or the site config.

    The projected base point is site.json's ``base_point_projected``; without it, that of
    :class:`twinkit.geo.SiteFrame` for the site (left out when the site has no lat/lon base point
    or the frame cannot be built).
    """
    src: dict = {}
    if site_json is not None and Path(site_json).exists():
        from twinkit.artefacts import read_site_info

        src = read_site_info(site_json).to_json()
    elif site:
        src = dict(site)
    bp = dict(src.get("base_point") or {})
    out: dict = {"frame": FRAME}
    if src.get("crs"):
        out["crs"] = str(src["crs"])
    for k in ("lat", "lon", "alt"):
        if k in bp and bp[k] is not None:
            out[k] = float(bp[k])
    proj = src.get("base_point_projected")
    if not proj and out.get("crs") and "lat" in out and "lon" in out:
        try:  # a site the frame refuses (unknown CRS, a pole) still gets the rest of the block
            from twinkit.geo.frame import SiteFrame

            proj = SiteFrame.from_site(src).georef_json()["base_point_projected"]
        except Exception:
            proj = None
    if proj:
        for k in ("x", "y", "z"):
            if k in proj:
                out[f"projected_{k}"] = float(proj[k])
    return out

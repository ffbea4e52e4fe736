"""Georeference of the demo site: a real place, a real metric CRS.

The site local frame is the projected CRS shifted by the base point's projected
coordinates: ``easting = E0 + x``, ``northing = N0 + y``, ``height = alt0 + z``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# A four-way junction in central Helsinki (Finland); ETRS89 / TM35FIN is the national metric CRS.
DEFAULT_CRS = "EPSG:3067"
DEFAULT_BASE = {"lat": 60.16945, "lon": 24.93365, "alt": 12.0}


@dataclass
class GeoRef:
    crs: str
    lat: float
    lon: float
    alt: float
    easting: float
    northing: float

    @classmethod
    def from_site(cls, site) -> "GeoRef":
        from pyproj import CRS, Transformer

        crs = str(site.get("crs", DEFAULT_CRS))
        bp = dict(site.get("base_point") or DEFAULT_BASE)
        CRS.from_user_input(crs)  # fail early on a bad CRS
        to_proj = Transformer.from_crs("EPSG:4326", crs, always_xy=True)
        if "lat" in bp and "lon" in bp:
            e, n = to_proj.transform(float(bp["lon"]), float(bp["lat"]))
            lat, lon = float(bp["lat"]), float(bp["lon"])
        else:  # projected base point given
            e, n = float(bp["x"]), float(bp["y"])
            lon, lat = Transformer.from_crs(crs, "EPSG:4326", always_xy=True).transform(e, n)
        return cls(crs=crs, lat=lat, lon=lon, alt=float(bp.get("alt", bp.get("z", 0.0))), easting=float(e), northing=float(n))

    def local_to_lonlat(self, xy: np.ndarray) -> np.ndarray:
        """(n, 2) site-frame metres -> (n, 2) lon, lat degrees (WGS84)."""
        from pyproj import Transformer

        t = Transformer.from_crs(self.crs, "EPSG:4326", always_xy=True)
        xy = np.asarray(xy, float).reshape(-1, 2)
        lon, lat = t.transform(xy[:, 0] + self.easting, xy[:, 1] + self.northing)
        return np.stack([np.asarray(lon), np.asarray(lat)], 1)

    def lonlat_to_local(self, lonlat: np.ndarray) -> np.ndarray:
        from pyproj import Transformer

        t = Transformer.from_crs("EPSG:4326", self.crs, always_xy=True)
        ll = np.asarray(lonlat, float).reshape(-1, 2)
        e, n = t.transform(ll[:, 0], ll[:, 1])
        return np.stack([np.asarray(e) - self.easting, np.asarray(n) - self.northing], 1)

    def to_json(self) -> dict:
        return {"crs": self.crs, "base_point": {"lat": self.lat, "lon": self.lon, "alt": self.alt},
                "base_point_projected": {"x": self.easting, "y": self.northing, "z": self.alt}}

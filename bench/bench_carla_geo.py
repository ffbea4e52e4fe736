"""CARLA geolocation of the package frame, measured with the carla 0.9.16 wheel against pyproj.

For each site and frame choice: the points of a 150 m disc around the base point (10 m grid + the
edge) in the site frame, their exact lon/lat (pyproj, site CRS), and what
``carla.Map(name, xodr).transform_to_geolocation`` reports for the same point of the package.
Prints two Markdown tables: the frame choices, and the error terms at the disc's edge.
Run: .venv/bin/python bench/bench_carla_geo.py [--radius 150]
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np

SITES = [("demo", "EPSG:3067", 60.16945, 24.93365), ("mex", "EPSG:32614", 19.4326, -99.1332),
         ("haparanda", "EPSG:3006", 65.8356, 24.1383), ("equator", "EPSG:32632", 0.5, 10.0)]


def _xodr(geo: str) -> str:
    return f"""<?xml version="1.0"?><OpenDRIVE><header revMajor="1" revMinor="4"><geoReference><![CDATA[{geo}]]>
</geoReference></header><road name="r" length="10" id="1" junction="-1"><planView><geometry s="0" x="0" y="0" hdg="0"
length="10"><line/></geometry></planView><lanes><laneSection s="0"><center><lane id="0" type="none" level="false"/>
</center><right><lane id="-1" type="driving" level="false"><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane>
</right></laneSection></lanes></road></OpenDRIVE>"""


def _grid(r: float) -> np.ndarray:
    g = np.arange(-r, r + 1e-9, 10.0)
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    a = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    return np.concatenate([xy[np.hypot(xy[:, 0], xy[:, 1]) <= r], r * np.stack([np.cos(a), np.sin(a)], 1)])


def _wheel(carla, m, xy):
    return np.array([(g.longitude, g.latitude) for g in
                     (m.transform_to_geolocation(carla.Location(float(x), float(y), 0.0)) for x, y in xy)])


def _dist(a, b):
    from pyproj import Geod

    return np.abs(np.asarray(Geod(ellps="WGS84").inv(a[:, 0], a[:, 1], b[:, 0], b[:, 1])[2]))


def main() -> int:
    import carla

    from twinkit.geo import SiteFrame

    ap = argparse.ArgumentParser()
    ap.add_argument("--radius", type=float, default=150.0)
    r = ap.parse_args().radius
    xy = _grid(r)
    from importlib.metadata import version

    print(f"Disc of {r:g} m, {len(xy)} points; errors in metres (max / mean); carla {version('carla')}\n")
    print("| site | CRS | convergence | mode | scale | k | CARLA formula, y north | CARLA 0.9.16 world (x, -y) "
          "| twinkit gnss_to_lonlat | similarity residual | fit s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    terms = []
    for name, crs, lat, lon in SITES:
        sf = SiteFrame.from_site({"crs": crs, "base_point": {"lat": lat, "lon": lon}})
        truth = sf.local_to_lonlat(xy)
        # today's geoReference (the site frame's exact string), then the base point but the site frame's axes
        m0 = carla.Map("s", _xodr(sf.proj_string()))
        e_today = _dist(_wheel(carla, m0, xy), truth)
        base = sf.carla_frame(scale="site")
        m1 = carla.Map("b", _xodr(base.geo_reference()))
        e_axes = _dist(_wheel(carla, m1, xy), truth)
        print(f"| {name} | {crs} | {math.degrees(base.rotation_rad):+.4f} deg | today's string | 1 | - | "
              f"{e_today.max() / 1000:,.0f} km | | | | |")
        print(f"| {name} | | | lat_0/lon_0 only, site axes | 1 | - | {e_axes.max():.3f} / {e_axes.mean():.3f} | | | | |")
        for mode in ("site", "true", "minimax", "auto"):
            t0 = time.perf_counter()
            f = sf.carla_frame(radius_m=r, scale=mode)
            dt = time.perf_counter() - t0
            pkg = f.site_to_package(xy)
            m = carla.Map(mode, _xodr(f.geo_reference()))
            e = _dist(_wheel(carla, m, pkg), truth)
            rep = _wheel(carla, m, np.stack([pkg[:, 0], -pkg[:, 1]], 1))
            e_mir = _dist(rep, truth)
            e_fix = _dist(f.gnss_to_lonlat(rep[:, 1], rep[:, 0]), truth)
            print(f"| {name} | | | {mode} | {f.scale:.6f} | {f.k:.6f} | {e.max():.3f} / {e.mean():.3f} | "
                  f"{e_mir.max():.1f} / {e_mir.mean():.1f} | {e_fix.max() * 1000:.2f} mm | "
                  f"{f.residual_m * 1000:.3f} mm | {dt:.2f} |")
        # error terms at the edge of the disc, for the frame with the site's own metric ("site")
        rot = r * abs(base.rotation_rad)
        grid_scale = r * abs(base.k - 1.0)
        terms.append((name, rot, grid_scale, base.carla_error_max_m, base.residual_m))
    print("\nError terms at the disc's edge (site-metric frame): what each part of the fix removes\n")
    print("| site | rotation (convergence x r) | CRS point scale (k-1) x r | CARLA sphere vs ellipsoid "
          "(remains) | higher order (similarity residual) |")
    print("|---|---|---|---|---|")
    for name, rot, gs, fe, res in terms:
        print(f"| {name} | {rot:.3f} | {gs:.3f} | {fe:.3f} | {res * 1000:.3f} mm |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The dense step alone on a real photo set: per-photo depth-map coverage and kept points, and its time.

    .venv/bin/python plugins/twinkit-photo/bench/bench_dense.py [--set lund|sceaux|berlin] [--out /tmp/dense_bench]
        [--param name=value ...] [--mesh]

The upstream steps (sfm, georeference, roi; defaults, as the image_site recipe runs them) are run once
into <out>/<set>/ and reused on later calls, so the dense step can be timed alone (``--fresh`` reruns
them). Prints a markdown table per photo: the depth map's coverage (share of its pixels with a depth),
the points that photo contributed to the fused cloud (after fusion, region of interest and voxels), and
the dense step's total. ``--mesh`` also runs Poisson (depth 10) + cleanup (8 cm) as the recipe does
and reports the faces and the mesh area.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]
PHOTOS = REPO.parent / "shared" / "data" / "photos"
SITES = {
    # base points near the photos (a local transverse Mercator frame around them)
    "lund": ("lund_street", {"name": "lund", "crs": "EPSG:4326", "base_point": {"lat": 55.6982, "lon": 13.1954, "alt": 0.0}}),
    "berlin": ("berlin_gcp", {"name": "berlin", "crs": "EPSG:4326", "base_point": {"lat": 52.5190, "lon": 13.4000, "alt": 0.0}}),
    "sceaux": ("sceaux_castle", None),
}


def _parse(kv: list[str]) -> dict:
    out = {}
    for s in kv:
        k, v = s.split("=", 1)
        for conv in (int, float):
            try:
                v = conv(v)
                break
            except ValueError:
                pass
        else:
            v = {"true": True, "false": False}.get(v.lower(), v)
        out[k] = v
    return out


def upstream(name: str, out: Path, fresh: bool) -> dict:
    from twinkit.testing import plugin_from_module, run_step
    import twinkit_photo.plugin as photo

    folder, site = SITES[name]
    photos = PHOTOS / folder
    base = out / name
    res = {"photos": photos}
    s_dir = base / "sfm" / "result"
    if fresh or not (s_dir / "sfm_report.json").exists():
        t = time.perf_counter()
        run_step(plugin_from_module(photo, "step", "sfm"), base / "sfm", {"in_photos_dir": photos}, photo.SfmParams())
        print(f"sfm {time.perf_counter() - t:.0f} s")
    g_dir = base / "georeference" / "result"
    if fresh or not (g_dir / "cameras_site.json").exists():
        kw = {"site": site} if site else {}
        gp = photo.GeorefParams() if site else photo.GeorefParams(method="none")
        run_step(plugin_from_module(photo, "step", "georeference"), base / "georeference",
                 {"in_sfm_dir": s_dir / "sfm"}, gp, **kw)
    r_dir = base / "roi" / "result"
    if fresh or not (r_dir / "roi.json").exists():
        rp = photo.RoiParams() if site else photo.RoiParams(margin_m=1.0, above_ground_m=5.0, below_ground_m=5.0,
                                                             max_depth_m=0.0, ground_threshold_m=0.02)
        run_step(plugin_from_module(photo, "step", "roi"), base / "roi",
                 {"in_cameras_site_json": g_dir / "cameras_site.json", "in_sparse_site_ply": g_dir / "sparse_site.ply"}, rp)
    res.update(sfm=s_dir / "sfm", cams=g_dir / "cameras_site.json", sparse=g_dir / "sparse_site.ply",
               georef=g_dir / "georef.json", roi=r_dir / "roi.json")
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", default="lund", choices=sorted(SITES))
    ap.add_argument("--out", default="/tmp/dense_bench")
    ap.add_argument("--param", nargs="*", default=[], help="DenseParams overrides, name=value")
    ap.add_argument("--fresh", action="store_true", help="rerun sfm, georeference and roi")
    ap.add_argument("--mesh", action="store_true", help="Poisson + cleanup on the cloud, faces and area")
    ap.add_argument("--label", default="dense")
    a = ap.parse_args()
    import numpy as np
    from twinkit.testing import plugin_from_module, run_step
    import twinkit_photo.plugin as photo

    out = Path(a.out)
    up = upstream(a.set, out, a.fresh)
    params = photo.DenseParams(**_parse(a.param))
    t = time.perf_counter()
    d = run_step(plugin_from_module(photo, "step", "dense"), out / a.set / a.label,
                 {"in_photos_dir": up["photos"], "in_cameras_site_json": up["cams"], "in_sparse_site_ply": up["sparse"],
                  "in_roi_json": up["roi"], "in_sfm_dir": up["sfm"], "in_georef_json": up["georef"]}, params)
    wall = time.perf_counter() - t
    meta = json.loads(d["points_meta.json"].read_text())
    dn = meta["dense"]
    per = dn.get("per_photo", {})
    rows = ["| photo | depth coverage | kept points |", "|---|---:|---:|"]
    cov = []
    for name in sorted(dn.get("valid_ratio", {})):
        c = dn["valid_ratio"][name]
        cov.append(c or 0.0)
        rows.append(f"| {name} | {'-' if c is None else f'{100 * c:.1f} %'} | {per.get(name, '-')} |")
    n = meta["counts"]["written"]
    maps = max(dn.get("depth_maps", 1), 1)
    print(f"### {a.set}: dense ({dn.get('backend')}, {', '.join(a.param) or 'defaults'})\n")
    print("\n".join(rows))
    print(f"\n{n:,} points from {dn.get('depth_maps')} depth maps ({n / maps:,.0f} per photo); depth coverage "
          f"mean {100 * float(np.mean(cov)):.1f} %, median {100 * float(np.median(cov)):.1f} %; dense step {wall:.0f} s "
          f"({json.dumps(meta.get('time', {}))})")
    if a.mesh:
        from twinkit.mesh import read_ply
        from twinkit.testing import run_plugin

        t = time.perf_counter()
        p = run_plugin("reconstructor", "poisson", out / a.set / (a.label + "_poisson"),
                       {"in_points_ply": d["points.ply"]}, depth=10)
        c = run_plugin("step", "clean_mesh", out / a.set / (a.label + "_clean"),
                       {"in_dense_mesh_ply": p["dense_mesh.ply"], "in_points_ply": d["points.ply"]}, max_dist_m=0.08)
        m = read_ply(c["clean_mesh.ply"])
        v, f = m.vertices, m.faces
        area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
        print(f"\nmesh (Poisson 10 + clean 8 cm): {len(f):,} faces, {area.sum():,.0f} m^2, {time.perf_counter() - t:.0f} s")


if __name__ == "__main__":
    main()

"""How well a photo set is levelled: the photos' horizon, the vertical lines, the ground plane, and checks.

    .venv/bin/python plugins/twinkit-photo/bench/bench_levelling.py --photos ../shared/data/photos/lund_street \
        [--site '{"name": "lund", "crs": "EPSG:3006", "base_point": {"lat": 55.6982, "lon": 13.1954, "alt": 37}}'] \
        [--sfm outputs/<site>/01_sfm/sfm] [--out /tmp/levelling]

Runs the sfm step (defaults; or reuses a finished ``sfm/`` folder with ``--sfm``) and the georeference step
with the photos (so the vertical lines are searched), then prints, in degrees:

* the photos' horizon (robust mean of the cameras' up axes): photos used, spread;
* the vertical lines: lines, photos, rms, and their angle to the horizon along the walk and sideways;
* the sparse ground plane: support, its angle to the final vertical (along / sideways), used or why not;
* the final vertical against the horizon (along / sideways) and which source gave it;
* independent checks of the final vertical: the three biggest planes of the sparse cloud (a facade should
  be at 90 degrees to the vertical), and with EXIF GPS heights the camera path's slope against the GPS
  heights' slope along the track.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def _slope(P, z):
    d = P - P.mean(0)
    _, _, Vt = np.linalg.svd(d, full_matrices=False)
    a = d @ Vt[0]
    k, b = np.polyfit(a, z, 1)
    res = z - (k * a + b)
    se = res.std(ddof=2) / np.sqrt(((a - a.mean()) ** 2).sum()) if len(z) > 3 else float("nan")
    return float(np.degrees(np.arctan(k))), float(np.degrees(se)), float(np.ptp(a))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photos", help="the photo folder (default: ../shared's Lund and Sceaux sets, as make bench does)")
    ap.add_argument("--site", default="{}", help="the site as JSON (crs, base_point) for the GPS route")
    ap.add_argument("--sfm", help="a finished sfm/ folder to reuse")
    ap.add_argument("--out", default="/tmp/twinkit_levelling")
    a = ap.parse_args(argv)
    if not a.photos:  # make bench: the shared real sets
        shared = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "photos"
        sets = [("lund_street", {"name": "lund", "crs": "EPSG:3006",
                                 "base_point": {"lat": 55.698167, "lon": 13.195389, "alt": 37.0}}),
                ("sceaux_castle", {})]
        for name, site in sets:
            if (shared / name).is_dir():
                print(f"\n## {name}\n", flush=True)
                main(["--photos", str(shared / name), "--site", json.dumps(site), "--out", f"{a.out}/{name}"])
            else:
                print(f"{shared / name}: absent, skipped")
        return 0
    from twinkit.testing import plugin_from_module, run_step

    import twinkit_photo.plugin as photo
    from twinkit_photo.georef import _angle_deg, camera_horizon, ransac_plane

    out, photos = Path(a.out), Path(a.photos)
    sfm = Path(a.sfm) if a.sfm else run_step(plugin_from_module(photo, "step", "sfm"), out / "sfm",
                                             {"in_photos_dir": photos}, photo.SfmParams())["sfm"]
    geo = run_step(plugin_from_module(photo, "step", "georeference"), out / "geo",
                   {"in_sfm_dir": sfm, "in_photos_dir": photos}, photo.GeorefParams(), site=json.loads(a.site))
    g = json.loads(geo["georef.json"].read_text())
    lv = g["level"]
    hz, vl, gp, fin = lv["camera_horizon"], lv.get("vertical_lines"), lv.get("ground_plane"), lv["final_vs_camera_horizon"]
    print(f"method {g['method']}, up from {lv['up_from']}")
    print(f"photos' horizon: {hz['used']} of {hz['photos']} photos, spread {hz['spread_deg']:.2f}, "
          f"standard error {hz['std_error_deg']:.2f}")
    if vl:
        print(f"vertical lines: {vl['lines']} lines in {vl['photos_with_lines']} photos, rms {vl['rms_deg']:.2f}, "
              f"{vl['vs_camera_horizon_deg']:.2f} from the horizon")
    if gp:
        t = gp["tilt_vs_photo_up"]
        print(f"ground plane: {100 * gp['inlier_ratio']:.1f} % of the points, {t['total_deg']:.2f} from the vertical "
              f"(along {t.get('along_walk_deg')}, sideways {t.get('sideways_deg')}); "
              + ("used" if gp["used"] else f"not used: {gp['why_not']}"))
    print(f"final vs. the horizon: {fin['total_deg']:.2f} (along the walk {fin.get('along_walk_deg')}, "
          f"sideways {fin.get('sideways_deg')})")
    # independent checks
    model = json.loads((Path(sfm) / "cameras_model.json").read_text())
    rows = {c["image"]: c for c in model["cameras"]}
    names = [n for n in sorted(rows) if n not in g["outlier_cameras"]]
    C = np.array([rows[n]["center"] for n in names], float)
    R = np.array([rows[n]["R_world_from_camera"] for n in names], float)
    up_fin = np.asarray(lv["up_model"], float)
    up_cam, _ = camera_horizon(R)
    pts = np.load(Path(sfm) / "sparse.npz")["xyz"]
    spread = float(np.median(np.linalg.norm(pts - np.median(pts, 0), axis=1)))
    rest = pts
    print("biggest planes of the sparse cloud (normal vs. the final up / vs. the horizon; 90 = vertical plane):")
    for k in range(3):
        if len(rest) < 50:
            break
        plane, inl = ransac_plane(rest, 0.01 * spread, iterations=2000, seed=k)
        if plane is None:
            break
        n = plane[0]
        print(f"  plane {k}: {100 * inl.mean():.1f} % of the rest, {_angle_deg(n, up_fin):.1f} / {_angle_deg(n, up_cam):.1f}")
        rest = rest[~inl]
    gps = model.get("exif_gps") or {}
    have = [n for n in names if n in gps and gps[n][2] is not None and np.isfinite(gps[n][2])]
    if len(have) >= 5 and "photos" in g:
        T = g["transform"]
        Cs = T["scale"] * C @ np.asarray(T["R"]).T + np.asarray(T["t"])
        k_cam, _, span = _slope(Cs[:, :2], Cs[:, 2])
        gxy = np.array([g["photos"][n]["gps_m"][:2] for n in have if g["photos"][n]["gps_m"]])
        alt = np.array([gps[n][2] for n in have if g["photos"][n]["gps_m"]], float)
        k_gps, se, _ = _slope(gxy, alt)
        from twinkit_photo.georef import rotation_between

        Ch = T["scale"] * C @ rotation_between(up_cam, [0, 0, 1.0]).T
        k_hz, _, _ = _slope(Ch[:, :2], Ch[:, 2])
        print(f"camera path slope over {span:.0f} m: final frame {k_cam:.2f}, horizon's frame {k_hz:.2f}; "
              f"EXIF GPS heights {k_gps:.2f} +- {se:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

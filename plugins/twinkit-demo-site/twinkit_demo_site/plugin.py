"""twinkit plugin: the built-in demo site generator (``site_generator=demo_intersection``).

Heavy libraries (open3d, laspy, pye57, PIL, pyproj) are imported inside the step.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from twinkit import StepContext, hookimpl
from twinkit.ranges import param

#: where the demo site is when the site config gives no georeference: a four-way junction in central
#: Helsinki (Finland); ETRS89 / TM35FIN is the national metric CRS
DEFAULT_CRS = "EPSG:3067"
DEFAULT_BASE = {"lat": 60.16945, "lon": 24.93365, "alt": 12.0}

#: size presets: site half size, scanner sampling (profile spacing, rays per profile), photo count
PRESETS = {
    "small": {"half_m": 30.0, "profile_spacing_m": 0.18, "rays_per_profile": 330, "photos": 40},
    "default": {"half_m": 30.0, "profile_spacing_m": 0.045, "rays_per_profile": 1320, "photos": 80},
    "large": {"half_m": 75.0, "profile_spacing_m": 0.03, "rays_per_profile": 2200, "photos": 200},
}


@dataclass
class DemoSiteParams:
    size: str = param("small", choices=("small", "default", "large"),
                      help="Preset of the generated intersection (PRESETS): small, default or large; it sets the "
                           "site's size, the scanner's point density and the photo count.")
    seed: int = param(0, ge=0, help="Random seed: the same seed and size give the same site, scan and photos.")
    photos: bool = param(True,
                         help="Render the photo walk (photos/, cameras.json, gcp.json). Recipes that read no photo "
                              "ask for none (recipe.site_params: the point-cloud recipes), which leaves those "
                              "files empty and saves most of the site step; +site.photos=true insists.")
    photo_count: int = param(0, ge=0, le=10000, help="Number of photos to render; 0 = the preset's count.")
    photo_width_px: int = param(1024, ge=16, le=16384, help="Width of each rendered photo (px).")
    photo_height_px: int = param(768, ge=16, le=16384, help="Height of each rendered photo (px).")
    focal_px: float = param(820.0, gt=0, help="Focal length of the photo camera (px).")
    photo_supersample: int = param(1, ge=1, le=8,
                                   help="Colour rays per pixel side when rendering photos (2 = 4 + 1 rays per "
                                        "pixel); higher = smoother and slower.")
    noise_mm: float = param(3.0, ge=0, help="Range noise of the simulated scanner (mm, 1 sigma, clipped at 3 sigma).")
    scanner_height_m: float = param(2.0, gt=0, help="Height (m) of the simulated scanner above the road.")
    max_range_m: float = param(80.0, gt=0, help="Maximum range (m) of the simulated scanner.")
    density_scale: float = param(1.0, gt=0, le=100, help="Multiplies the preset's point density.")
    gps_noise_m: float = param(2.5, ge=0,
                               help="Noise of the photos' EXIF GPS positions (m, 1 sigma horizontal; vertical "
                                    "1.6x).")
    osm_shift_m: float = param(3.5, ge=0,
                               help="Length (m) of the known translation applied to the generated OSM roads (what "
                                    "road alignment must recover).")
    osm_rotation_deg: float = param(0.8, ge=0, le=180,
                                    help="Magnitude (degrees) of the known rotation of the generated OSM roads "
                                         "about the base point.")
    shadows: bool = param(True, help="Cast sun shadows in the scan's and the photos' colours.")
    weathering: float = param(0.6, ge=0, le=1,
                              help="Strength of world-space stains in the photos, so that no two places look alike; 0 = "
                                   "off.")
    weathering_scan: bool = param(False,
                                  help="Weather the scanner's colours too (changes the segmentation demo's input).")
    gcp_survey_noise_m: float = param(0.005, ge=0,
                                      help="Noise (m) of the surveyed ground-control points written to gcp.json.")
    gcp_pixel_noise_px: float = param(0.5, ge=0,
                                      help="Noise (px) of the ground-control points' pixel observations (a user "
                                           "clicking them).")


def _osm_transform(params: DemoSiteParams, seed: int) -> dict:
    import numpy as np

    rng = np.random.default_rng([seed, 5])
    ang = rng.uniform(0, 2 * math.pi)
    rot = params.osm_rotation_deg * (1 if rng.random() < 0.5 else -1)
    return {"dx_m": round(params.osm_shift_m * math.cos(ang), 4), "dy_m": round(params.osm_shift_m * math.sin(ang), 4),
            "rotation_deg": round(rot, 4), "about": [0.0, 0.0],
            "definition": "osm_xy = Rz(rotation_deg) @ true_xy + [dx_m, dy_m] (site local frame); "
                          "undo: true_xy = Rz(-rotation_deg) @ (osm_xy - [dx_m, dy_m])"}


def apply_osm_transform(xy, tf: dict, inverse: bool = False):
    """Apply (or undo) the OSM shift/rotation recorded in site.json to (n, 2) site-frame points."""
    import numpy as np

    xy = np.asarray(xy, float).reshape(-1, 2)
    a = math.radians(tf["rotation_deg"])
    R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    t = np.array([tf["dx_m"], tf["dy_m"]])
    if inverse:
        return (xy - t) @ R  # R^T (p - t)
    return xy @ R.T + t


def site_frame(site):
    """The site frame (twinkit.geo) of the demo site: the site's ``crs`` and ``base_point``, or the defaults."""
    from twinkit.geo import SiteFrame, site_dict

    s = site_dict(site)
    if not s.get("crs"):
        s["crs"] = DEFAULT_CRS
    if not s.get("base_point"):
        s["base_point"] = dict(DEFAULT_BASE)
    return SiteFrame.from_site(s)


def generate_demo_site(params: DemoSiteParams, ctx: StepContext, *,
                       out_gt_mesh_obj: Path, out_gt_mesh_ply: Path, out_cloud_e57: Path, out_cloud_las: Path,
                       out_cloud_ply: Path, out_scanners_json: Path, out_photos_dir: Path, out_cameras_json: Path,
                       out_gcp_json: Path,
                       out_roads_osm: Path, out_roads_truth_json: Path, out_site_json: Path) -> dict:
    """Write a procedural four-way intersection with exact ground truth."""
    from twinkit import artefacts as A
    from twinkit_demo_site import writers
    from twinkit_demo_site.layout import build_scene
    from twinkit_demo_site.raycast import Tracer
    from twinkit_demo_site.textures import build_atlas

    pre = _preset(params.size)
    seed = int(params.seed)
    geo = site_frame(ctx.site)
    ctx.log.info("demo site '%s' seed %d at lat %.6f lon %.6f (%s)", params.size, seed, geo.lat, geo.lon, geo.crs)

    with ctx.substep("scene"):
        atlas = build_atlas(seed)
        scene = build_scene(pre["half_m"], seed, atlas)
        mesh = scene.mesh
    with ctx.substep("mesh_files"):
        writers.write_obj(out_gt_mesh_obj, mesh, atlas)
        A.write_gt_mesh(out_gt_mesh_ply, writers.gt_ply_mesh(mesh, atlas))

    with ctx.substep("tracer"):
        tracer = Tracer(mesh, atlas, threads=ctx.threads, weathering=params.weathering, seed=seed)
    with ctx.substep("scan"):
        cloud, traj, settings = _scan_cloud(scene, tracer, params, pre, seed, ctx)
    with ctx.substep("cloud_files"):
        _write_cloud_files(cloud, traj, settings, geo, (seed, params.size), out_cloud_ply=out_cloud_ply,
                           out_cloud_las=out_cloud_las, out_cloud_e57=out_cloud_e57, out_scanners_json=out_scanners_json)

    with ctx.substep("photos"):
        n_photos = _photos(scene, tracer, params, pre, seed, geo, ctx, out_photos_dir=out_photos_dir,
                           out_cameras_json=out_cameras_json, out_gcp_json=out_gcp_json)

    with ctx.substep("roads"):
        tf = _osm_transform(params, seed)
        _write_roads(scene, tf, geo, out_roads_osm=out_roads_osm, out_roads_truth_json=out_roads_truth_json)

    with ctx.substep("site_json"):
        site = _site_json(scene, params, geo, tf, cloud, traj, n_photos)
        A.write_site_info(out_site_json, site)
    n_points = site["counts"]["points"]
    ctx.log.info("demo site: %d faces, %d points, %d photos", len(mesh.faces), n_points, n_photos)
    return {"points": n_points, "faces": int(len(mesh.faces)), "vertices": int(len(mesh.vertices)),
            "photos": n_photos, "ghost_points": site["counts"]["ghost_points"]}


def _preset(size: str) -> dict:
    """The size preset's settings (PRESETS); an unknown size is an InputError."""
    if size not in PRESETS:
        from twinkit import InputError

        raise InputError(f"demo_intersection: unknown size '{size}'; choose one of {', '.join(PRESETS)}")
    return PRESETS[size]


def _scan_cloud(scene, tracer, params: DemoSiteParams, pre: dict, seed: int, ctx: StepContext):
    """Drive the scanner van along its passes: (cloud, trajectory, ScanSettings), the cloud being a dict of xyz (n, 3)
    site frame, normals, rgb, label, scanner (trajectory index) and intensity arrays."""
    import numpy as np

    from twinkit_demo_site.scanner import ScanSettings, scan, trajectory

    dens = math.sqrt(max(params.density_scale, 1e-3))
    settings = ScanSettings(profile_spacing_m=pre["profile_spacing_m"] / dens,
                            rays_per_profile=int(round(pre["rays_per_profile"] * dens)),
                            scanner_height_m=params.scanner_height_m, noise_mm=params.noise_mm,
                            max_range_m=params.max_range_m, shadows=params.shadows,
                            weathered=bool(params.weathering_scan))
    traj = trajectory(scene, settings, np.random.default_rng([seed, 2]))
    chunks = list(scan(scene, tracer, settings, traj, np.random.default_rng([seed, 3]), progress=ctx.progress))
    cloud = {k: np.concatenate([getattr(c, k) for c in chunks]) for k in ("xyz", "normals", "rgb", "label", "scanner", "intensity")}
    return cloud, traj, settings


def _write_cloud_files(cloud: dict, traj: dict, settings, geo, guid_seed, *, out_cloud_ply: Path, out_cloud_las: Path,
                       out_cloud_e57: Path, out_scanners_json: Path) -> None:
    """The cloud as PLY (site frame), LAS and E57 (projected), and the scanner positions as JSON."""
    import numpy as np

    from twinkit_demo_site import writers

    writers.write_cloud_ply(out_cloud_ply, cloud)
    writers.write_las(out_cloud_las, cloud, geo, traj["time_s"][cloud["scanner"]])
    writers.write_e57(out_cloud_e57, cloud, geo, guid_seed, traj["xyz"])
    writers.write_json(out_scanners_json, {
        "frame": "site local (metres, z up)",
        "description": "mobile-mapping van positions; each position fires one 360-degree profile per head; "
                       "the point attribute 'scanner' indexes these arrays",
        "heads": [{"name": "left", "plane_yaw_offset_deg": 45.0}, {"name": "right", "plane_yaw_offset_deg": -45.0}],
        "profile_spacing_m": settings.profile_spacing_m, "rays_per_profile": settings.rays_per_profile,
        "noise_mm": settings.noise_mm, "max_range_m": settings.max_range_m,
        "positions": np.round(traj["xyz"], 4), "heading_rad": np.round(traj["heading"], 6),
        "time_s": np.round(traj["time_s"], 5), "pass": traj["pass"],
    })


def _photos(scene, tracer, params: DemoSiteParams, pre: dict, seed: int, geo, ctx: StepContext, *,
            out_photos_dir: Path, out_cameras_json: Path, out_gcp_json: Path) -> int:
    """Render the photo walk, write the cameras and the ground-control points; returns the photo count."""
    import numpy as np

    from twinkit import artefacts as A
    from twinkit_demo_site.photos import gcp_observations, render_photos, walk_poses

    if not params.photos:
        A.write_no_photos(out_photos_dir, "No photo walk: the demo site was generated with photos=false (what the "
                                          "point-cloud recipes ask for, recipe.site_params). For the photos: "
                                          "site.photos=true, or recipe=image_site without site.photos=false.")
        A.write_demo_cameras(out_cameras_json, {"cameras": []})
        A.write_gcp(out_gcp_json, {"points": []})
        ctx.log.info("demo site: no photo walk (photos=false)")
        return 0
    n_photos = params.photo_count or pre["photos"]
    path = scene.walk_path if params.size == "small" else np.concatenate([scene.walk_path, scene.walk_extra])
    poses = walk_poses(path, n_photos, np.random.default_rng([seed, 4]))
    cams = render_photos(tracer, poses, out_photos_dir, geo, np.random.default_rng([seed, 6]),
                         width=params.photo_width_px, height=params.photo_height_px, focal_px=params.focal_px,
                         gps_noise_m=params.gps_noise_m, supersample=params.photo_supersample,
                         shadows=params.shadows, progress=ctx.progress, threads=ctx.threads or 1)
    A.write_demo_cameras(out_cameras_json, cams)
    A.write_gcp(out_gcp_json, gcp_observations(
        tracer, cams, scene.gcp_points, np.random.default_rng([seed, 8]),
        survey_noise_m=params.gcp_survey_noise_m, pixel_noise_px=params.gcp_pixel_noise_px))
    return n_photos


def _write_roads(scene, tf: dict, geo, *, out_roads_osm: Path, out_roads_truth_json: Path) -> None:
    """roads.osm (its nodes moved by the known OSM transform ``tf``) and roads_truth.json."""
    import numpy as np

    from twinkit import artefacts as A
    from twinkit_demo_site import writers

    ids = sorted(scene.osm["nodes"])
    xy = np.array([scene.osm["nodes"][i][:2] for i in ids])
    moved = apply_osm_transform(xy, tf)
    nodes = {i: (float(p[0]), float(p[1]), scene.osm["nodes"][i][2]) for i, p in zip(ids, moved)}
    A.write_osm(out_roads_osm, writers.osm_text(nodes, scene.osm["ways"], geo))
    A.write_roads_truth(out_roads_truth_json, scene.roads_truth)


def _site_json(scene, params: DemoSiteParams, geo, tf: dict, cloud: dict, traj: dict, n_photos: int) -> dict:
    """site.json: the georeference, bounds, OSM transform, counts, labels, solids, files and parameters."""
    import numpy as np

    from twinkit_demo_site.layout import LABELS

    mesh = scene.mesh
    H = scene.dims.half_m
    zmax = float(mesh.vertices[:, 2].max())
    labels_present = sorted(int(v) for v in np.unique(mesh.face_attrs["label"]))
    counts = {**scene.counts, "points": len(cloud["xyz"]), "ghost_points": int((cloud["label"] == LABELS["person"]).sum()),
              "photos": n_photos, "scanner_positions": int(len(traj["xyz"]))}
    return {
        **geo.georef_json(),
        "frame": "site local: metres, x east, y north, z up; origin = base point; "
                 "projected = local + base_point_projected (LAS and E57 are in projected coordinates, z + alt)",
        "bounds_local": {"min": [-H, -H, 0.0], "max": [H, H, round(zmax, 4)]},
        "osm_transform": tf,
        "preset": params.size, "seed": int(params.seed), "counts": counts,
        "labels_present": labels_present,
        "label_names": {str(v): k for k, v in sorted(LABELS.items(), key=lambda kv: kv[1])},
        "solids": [{"min": np.round(s["min"], 4), "max": np.round(s["max"], 4)} for s in scene.solids],
        "files": {"gt_mesh": "gt_mesh.obj (+ .mtl, .png) and gt_mesh.ply", "cloud": "cloud.e57, cloud.las, cloud.ply",
                  "photos": "photos/ (+ photos/labels/)", "cameras": "cameras.json",
                  "gcp": "gcp.json (zebra-corner ground-control points with their pixels in the photos)", "roads": "roads.osm, roads_truth.json"},
        "params": {k: getattr(params, k) for k in params.__dataclass_fields__},
    }


def output_paths(folder: Path) -> dict[str, Path]:
    """Keyword arguments naming every output of :func:`generate_demo_site` inside ``folder`` (for scripts and
    tests that call the generator directly; the engine does the same from the signature)."""
    from twinkit.signature import parse_signature

    return {o.param: Path(folder) / o.filename for o in parse_signature(generate_demo_site).outputs}


@hookimpl
def twinkit_register_site_generators(register):
    register("demo_intersection", generate_demo_site, params=DemoSiteParams,
             description="Procedural four-way intersection with exact ground truth (mesh, cloud, photos, OSM)")

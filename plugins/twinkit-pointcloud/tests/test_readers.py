"""Readers, frames and bad input."""
from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pytest
from twinkit import InputError
from twinkit.testing import make_context

from twinkit_pointcloud import plugin as P
from twinkit.mesh import Mesh, read_ply, write_ply
from twinkit_pointcloud.readers import read_e57

from conftest import shared_file


def _read(ctx, src: Path, params=None):
    out = ctx.workdir / "points.ply"
    meta = ctx.workdir / "points_meta.json"
    res = P.read_cloud(params or P.ReadCloudParams(), ctx, in_cloud=src, out_points_ply=out, out_points_meta_json=meta)
    return res, read_ply(out), json.loads(meta.read_text())


def _assert_no_outputs(ctx):
    assert not (ctx.workdir / "points.ply").exists()
    assert not (ctx.workdir / "points_meta.json").exists()


# ----------------------------------------------------------------------------- shared real files

def test_lille_ply_keeps_file_normals(ctx):
    # file_normals_flip_share=1: the check is off (it flips 58 % of this file's normals; docs/pointcloud.md
    # "Normals from the file"; test_frames_normals.py tests it on a small cloud)
    res, m, meta = _read(ctx, shared_file("lille_street_small_normals.ply"), P.ReadCloudParams(file_normals_flip_share=1.0))
    assert m.n_vertices == 170610
    assert meta["fields"]["normals"] == "file" and not meta["fields"]["colors"]
    assert meta["frame"]["shift_m"] == [0.0, 0.0, 0.0]
    raw = read_ply(shared_file("lille_street_small_normals.ply"))
    assert np.allclose(m.normals, raw.normals / np.linalg.norm(raw.normals, axis=1, keepdims=True), atol=1e-5)


def test_pump_e57_colours_intensity_scanner(ctx):
    # the reader itself, on a scan that read_cloud refuses as no street (the next test): the check is off here
    res, m, meta = _read(ctx, shared_file("pump_colored_scan.e57"), P.ReadCloudParams(min_street_extent_m=0))
    assert m.n_vertices > 150_000
    assert m.colors is not None and m.colors.max() > 100
    assert "intensity" in m.attrs and 0 <= m.attrs["intensity"].min() and m.attrs["intensity"].max() <= 1
    assert meta["fields"]["normals"] == "estimated"
    assert meta["fields"]["normals_orientation"] == "scanner"  # gridded scan: scanner at the origin
    to_scanner = -m.vertices  # scanner at (0, 0, 0)
    assert (np.einsum("ij,ij->i", to_scanner, m.normals) >= 0).mean() > 0.99


def test_indoor_scan_is_refused_as_no_street_before_anything_is_written(ctx):
    from twinkit_pointcloud.preflight import read_cloud_preflight

    src = shared_file("pump_colored_scan.e57")  # an indoor scan of a pump, 4.6 x 4.5 m
    problems = read_cloud_preflight({"name": "pump"}, P.ReadCloudParams(), {"in_cloud": src})
    assert len(problems) == 1 and "not a street" in problems[0] and "pump_colored_scan.e57" in problems[0]
    assert "min_street_extent_m=0" in problems[0]  # the way on, named
    with pytest.raises(InputError, match=r"pump_colored_scan.e57: the capture spans only 4\.6 x 4\.5 m"):
        _read(ctx, src)
    _assert_no_outputs(ctx)
    # a street-sized cloud passes both (Lille: 25 x 37 m)
    assert read_cloud_preflight({"name": "lille"}, P.ReadCloudParams(),
                                {"in_cloud": shared_file("lille_street_small_normals.ply")}) == []


def test_two_point_e57_too_few_points_but_normals_read(ctx):
    src = shared_file("two_points_with_normals.e57")
    with pytest.raises(InputError, match="two_points_with_normals.e57: too few points"):
        _read(ctx, src)
    _assert_no_outputs(ctx)
    raw = read_e57(src)  # the nor: extension is read
    assert raw.normals is not None and raw.normals.shape == (2, 3)
    assert np.allclose(np.linalg.norm(raw.normals, axis=1), 1, atol=1e-5)
    assert raw.normals[1, 1] > 0.99


def test_ign_laz_crs_shift_classification(ctx):
    res, m, meta = _read(ctx, shared_file("ign_lidarhd_village_street.laz"))
    assert m.n_vertices == 70840
    assert meta["frame"]["target_crs"] == "EPSG:2154"
    assert meta["frame"]["shift_source"] == "rounded_centre"
    sx, sy, _ = meta["frame"]["shift_m"]
    assert 870000 <= sx <= 870400 and 6617000 <= sy <= 6617200
    assert np.abs(m.vertices[:, :2]).max() < 200  # local, float32-safe
    assert set(np.unique(m.attrs["classification"])) >= {1, 2, 6}
    assert m.colors is not None and m.colors.max() > 200  # 16-bit RGB scaled down


def test_ign_laz_with_site_base_point_latlon(tmp_path):
    ctx = make_context(tmp_path / "w", site={"name": "ign", "crs": "EPSG:2154",
                                             "base_point": {"lat": 46.6335, "lon": 5.2310, "alt": 180.0}})
    res, m, meta = _read(ctx, shared_file("ign_lidarhd_village_street.laz"))
    assert meta["frame"]["shift_source"] == "base_point"
    assert np.abs(m.vertices[:, :2]).max() < 5000


def test_autzen_feet_to_metres(ctx):
    src = shared_file("autzen_trim.laz")
    import laspy

    las = laspy.read(str(src))
    res, m, meta = _read(ctx, src)
    assert m.n_vertices == 110000
    ext_ft = float(np.ptp(np.asarray(las.x)))
    ext_m = float(np.ptp(m.vertices[:, 0]))
    assert ext_m == pytest.approx(ext_ft * 0.3048, rel=1e-3)
    assert meta["frame"]["unit_factor_xy"] == pytest.approx(0.3048, rel=1e-4)


# ----------------------------------------------------------------------------- synthetic files

def _write_las(path: Path, xyz: np.ndarray, rgb=None, crs=None, point_format=3, cls=None):
    import laspy

    hdr = laspy.LasHeader(point_format=point_format, version="1.4" if point_format >= 6 else "1.2")
    hdr.offsets = np.floor(xyz.min(axis=0))
    hdr.scales = np.array([0.001, 0.001, 0.001])
    if crs is not None:
        from pyproj import CRS

        hdr.add_crs(CRS.from_user_input(crs))
    las = laspy.LasData(hdr)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    if rgb is not None:
        las.red, las.green, las.blue = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    if cls is not None:
        las.classification = cls
    las.write(str(path))


def _grid(n=400, z=0.0, origin=(0.0, 0.0)):
    k = int(np.sqrt(n))
    x, y = np.meshgrid(np.linspace(0, 10, k), np.linspace(0, 10, k))
    return np.c_[x.ravel() + origin[0], y.ravel() + origin[1], np.full(k * k, z) + 0.05 * np.sin(x.ravel())]


@pytest.mark.parametrize("bits", [8, 16])
def test_las_rgb_8_and_16_bit(tmp_path, ctx, bits):
    xyz = _grid(400)
    rgb8 = np.tile(np.array([[200, 100, 50]], np.uint16), (len(xyz), 1))
    rgb = rgb8 * 257 if bits == 16 else rgb8
    src = tmp_path / f"c{bits}.las"
    _write_las(src, xyz, rgb=rgb, cls=np.full(len(xyz), 2, np.uint8))
    res, m, meta = _read(ctx, src)
    assert np.all(m.colors == [200, 100, 50])
    assert np.all(m.attrs["classification"] == 2)


def test_laz_projected_with_site_base_point_xyz(tmp_path):
    xyz = _grid(900, z=35.0, origin=(652000.0, 6862000.0))
    src = tmp_path / "p.laz"
    _write_las(src, xyz, crs="EPSG:2154")
    site = {"name": "s", "crs": "EPSG:2154", "base_point": {"x": 652000.0, "y": 6862000.0, "z": 30.0},
            "bounds_m": [[-5, -5, -5], [20, 20, 20]]}
    ctx = make_context(tmp_path / "w", site=site)
    res, m, meta = _read(ctx, src)
    assert meta["frame"]["shift_m"] == [652000.0, 6862000.0, 30.0]
    assert np.allclose(m.vertices.min(axis=0)[:2], [0, 0], atol=2e-3)
    assert m.vertices[:, 2].min() == pytest.approx(5.0 - 0.05, abs=0.01)


def test_wrong_crs_for_site_is_an_error(tmp_path):
    # a cloud in Lambert-93 near Paris for a site in Lille (bounds given): wrong CRS / wrong place
    xyz = _grid(900, z=35.0, origin=(652000.0, 6862000.0))
    src = tmp_path / "paris.laz"
    _write_las(src, xyz, crs="EPSG:2154")
    site = {"name": "lille", "crs": "EPSG:2154", "base_point": {"lat": 50.6292, "lon": 3.0573, "alt": 20.0},
            "bounds_m": [[-100, -100, -10], [100, 100, 40]]}
    ctx = make_context(tmp_path / "w", site=site)
    with pytest.raises(InputError, match="paris.laz: .*wrong CRS"):
        _read(ctx, src)
    _assert_no_outputs(ctx)
    # same without bounds: the distance from the base point gives it away
    ctx2 = make_context(tmp_path / "w2", site={k: v for k, v in site.items() if k != "bounds_m"})
    with pytest.raises(InputError, match="km from the site base point"):
        _read(ctx2, src)


def test_wrong_crs_declared_in_file_is_reprojected(tmp_path):
    # the file says EPSG:2154 and the site uses UTM 31N: reprojected, lands on the base point
    from pyproj import Transformer

    xyz = _grid(400, z=20.0, origin=(704000.0, 7059000.0))  # Lambert-93, around Lille
    src = tmp_path / "l93.las"
    _write_las(src, xyz, crs="EPSG:2154")
    lon, lat = Transformer.from_crs("EPSG:2154", "EPSG:4326", always_xy=True).transform(704005.0, 7059005.0)
    ctx = make_context(tmp_path / "w", site={"name": "s", "crs": "EPSG:32631",
                                             "base_point": {"lat": lat, "lon": lon, "alt": 20.0}})
    res, m, meta = _read(ctx, src, P.ReadCloudParams(min_street_extent_m=0))  # a 10 m grid: reprojected it is 9.99 m
    assert meta["frame"]["reprojected"]
    c = 0.5 * (m.vertices.min(axis=0) + m.vertices.max(axis=0))
    assert np.hypot(c[0], c[1]) < 1.0


def test_empty_cloud(tmp_path, ctx):
    src = tmp_path / "empty.ply"
    write_ply(src, Mesh(np.zeros((0, 3))))
    with pytest.raises(InputError, match="empty.ply: the cloud is empty"):
        _read(ctx, src)
    _assert_no_outputs(ctx)
    zero = tmp_path / "zero.laz"
    zero.write_bytes(b"")
    with pytest.raises(InputError, match="zero.laz: the file is empty"):
        _read(ctx, zero)


def test_nan_and_inf_points(tmp_path, ctx, caplog):
    xyz = _grid(400)
    xyz[5] = [np.nan, 0, 0]
    xyz[7] = [np.inf, 1, 1]
    src = tmp_path / "nan.ply"
    write_ply(src, Mesh(xyz), xyz_dtype="f8")
    with caplog.at_level(logging.WARNING):
        res, m, meta = _read(ctx, src)
    assert m.n_vertices == 398 and meta["counts"]["dropped_invalid"] == 2
    assert "nan.ply" in caplog.text and "NaN or infinite" in caplog.text
    ctx2 = make_context(tmp_path / "w2")
    with pytest.raises(InputError, match="nan.ply: 2 of 400 points have NaN"):
        _read(ctx2, src, P.ReadCloudParams(drop_invalid_points=False))
    _assert_no_outputs(ctx2)
    allnan = tmp_path / "allnan.ply"
    write_ply(allnan, Mesh(np.full((50, 3), np.nan)))
    with pytest.raises(InputError, match="allnan.ply: all 50 points have NaN") as e:
        _read(ctx2, allnan)
    assert "drop_invalid_points" not in str(e.value)  # already the default: no use suggesting it


def test_identical_points(tmp_path, ctx):
    src = tmp_path / "same.ply"
    write_ply(src, Mesh(np.tile([[1.0, 2.0, 3.0]], (100, 1))))
    with pytest.raises(InputError, match="same.ply: all 100 points are identical"):
        _read(ctx, src)
    _assert_no_outputs(ctx)


def test_truncated_laz(tmp_path, ctx):
    src = tmp_path / "full.laz"
    _write_las(src, _grid(20000), rgb=np.full((len(_grid(20000)), 3), 100, np.uint16))
    data = src.read_bytes()
    bad = tmp_path / "truncated.laz"
    bad.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="truncated.laz"):
        _read(ctx, bad)
    _assert_no_outputs(ctx)


def _write_e57(path: Path, scans):
    import pye57

    e = pye57.E57(str(path), mode="w")
    for xyz, rgb, rot, tr in scans:
        data = {"cartesianX": xyz[:, 0], "cartesianY": xyz[:, 1], "cartesianZ": xyz[:, 2]}
        if rgb is not None:
            data.update(colorRed=rgb[:, 0], colorGreen=rgb[:, 1], colorBlue=rgb[:, 2])
        e.write_scan_raw(data, rotation=rot, translation=tr)
    e.close()


def test_truncated_e57(tmp_path, ctx):
    src = tmp_path / "full.e57"
    xyz = _grid(40000)
    _write_e57(src, [(xyz, None, np.array([1.0, 0, 0, 0]), np.zeros(3))])
    data = src.read_bytes()
    bad = tmp_path / "truncated.e57"
    bad.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="truncated.e57"):
        _read(ctx, bad)
    _assert_no_outputs(ctx)
    garbage = tmp_path / "garbage.e57"
    garbage.write_bytes(b"not an e57 file at all" * 100)
    with pytest.raises(InputError, match="garbage.e57: not a readable E57") as e:
        _read(ctx, garbage)
    assert "\n" not in str(e.value) and "Debug info" not in str(e.value)  # libE57's dump stays out


def test_e57_several_scans_merged_with_poses(tmp_path, ctx):
    # two scans of the same gently waved ground z = 0.01 sin(x) (a flat cloud is refused), each in its
    # scanner's frame; scanners at 1.5 m height
    rng = np.random.default_rng(1)
    scans = []
    for tr, yaw in (([0.0, 0.0, 1.5], 0.0), ([3.0, 1.0, 1.5], np.pi / 2)):
        world = np.c_[rng.uniform(-4, 4, 3000), rng.uniform(-4, 4, 3000), np.zeros(3000)]
        world[:, 2] = 0.01 * np.sin(world[:, 0])
        R = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
        local = (world - np.asarray(tr)) @ R  # world = R @ local + tr
        q = np.array([np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)])
        scans.append((local, np.full((len(local), 3), 90 if yaw == 0 else 180, np.uint8), q, np.asarray(tr)))
    src = tmp_path / "two_scans.e57"
    _write_e57(src, scans)
    res, m, meta = _read(ctx, src, P.ReadCloudParams(min_street_extent_m=0))  # an 8 m plane
    assert m.n_vertices == 6000
    assert np.abs(m.vertices[:, 2] - 0.01 * np.sin(m.vertices[:, 0])).max() < 1e-3  # both scans land on the ground
    assert np.allclose(meta["scanner_positions_m"], [[0, 0, 1.5], [3, 1, 1.5]], atol=1e-6)
    assert meta["fields"]["normals_orientation"] == "scanner"
    assert (m.normals[:, 2] > 0.99).all()  # towards the scanners above the plane
    assert set(np.unique(m.attrs["scanner"])) == {0, 1}
    assert set(map(tuple, np.unique(m.colors, axis=0))) == {(90, 90, 90), (180, 180, 180)}


def test_cloud_without_colours_warns(tmp_path, ctx, caplog):
    src = tmp_path / "grey.ply"
    write_ply(src, Mesh(_grid(400)))
    with caplog.at_level(logging.WARNING):
        res, m, meta = _read(ctx, src)
    assert "grey.ply" in caplog.text and "no colours" in caplog.text
    assert meta["fields"]["colors"] is False


def test_unsupported_and_missing(tmp_path, ctx):
    f = tmp_path / "cloud.xyz"
    f.write_text("1 2 3\n")
    with pytest.raises(InputError, match="unsupported point cloud format"):
        _read(ctx, f)
    with pytest.raises(InputError, match="not found"):
        _read(ctx, tmp_path / "nope.ply")
    (tmp_path / "scans").mkdir()
    with pytest.raises(InputError, match="scans: is a folder, not a point cloud file"):
        _read(ctx, tmp_path / "scans")
    (tmp_path / "link.ply").symlink_to(tmp_path / "moved.ply")
    with pytest.raises(InputError, match="link.ply: a broken link"):
        _read(ctx, tmp_path / "link.ply")


def test_a_sweep_is_read_without_the_vehicle_that_carried_its_sensor(ctx, tmp_path):
    from twinkit.testing import spinning_sweep

    pts, part = spinning_sweep(platform=True)
    truth = part == 3
    src = tmp_path / "sweep.ply"
    write_ply(src, Mesh(pts), xyz_dtype="f8")
    res, m, meta = _read(ctx, src)
    assert meta["counts"]["dropped_platform"] == truth.sum() and m.n_vertices == len(pts) - truth.sum()
    assert meta["blind_circle"]["radius_m"] > 3.0
    kept = np.asarray(m.vertices)
    assert np.hypot(kept[:, 0] - 3.0, kept[:, 1] + 2.0).min() > 3.0  # nothing left inside the blind circle
    ctx2 = make_context(tmp_path / "w2", site={"name": "test"})
    _, m2, meta2 = _read(ctx2, src, P.ReadCloudParams(drop_platform=False))
    assert m2.n_vertices == len(pts) and meta2["counts"]["dropped_platform"] == 0

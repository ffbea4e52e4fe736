"""Issue 28 "Frames": a cloud in its own local frame placed by site.cloud_frame (offset + heading, or a 4x4),
a base point in a feet CRS meaning the same in read_cloud and in the roads frame, inward file normals
flipped, and the file's classification kept for the labels."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from twinkit import InputError
from twinkit.mesh import Mesh, read_ply, write_ply
from twinkit.testing import make_context

import twinkit_pointcloud.plugin as P
from twinkit_pointcloud.preflight import read_cloud_preflight

# Lambert-93 around the IGN extract
E0, N0 = 870250.0, 6617100.0


def _read(tmp_path: Path, src: Path, site: dict, params=None, name: str = "out"):
    ctx = make_context(tmp_path / name / "work", site=site)
    out, meta = tmp_path / name / "points.ply", tmp_path / name / "points_meta.json"
    res = P.read_cloud(params or P.ReadCloudParams(), ctx, in_cloud=src, out_points_ply=out, out_points_meta_json=meta)
    return read_ply(out), json.loads(meta.read_text()), res


def _local_cloud(tmp_path: Path) -> tuple[Path, np.ndarray]:
    """A sensor sweep in its own frame: 0..20 m along its x, 0..6 m along its y, a ground and a wall."""
    rng = np.random.default_rng(0)
    g = np.c_[rng.uniform(0, 20, 3000), rng.uniform(0, 6, 3000), np.zeros(3000)]
    w = np.c_[rng.uniform(0, 20, 1000), np.full(1000, 6.0), rng.uniform(0, 4, 1000)]
    pts = np.vstack([g, w])
    p = tmp_path / "sweep.ply"
    write_ply(p, Mesh(vertices=pts))
    return p, pts


def _site(**extra) -> dict:
    from pyproj import Transformer

    lon, lat = Transformer.from_crs("EPSG:2154", "EPSG:4326", always_xy=True).transform(E0, N0)
    return {"name": "sweep", "crs": "EPSG:2154", "base_point": {"lat": lat, "lon": lon, "alt": 180.0}, **extra}


def test_offset_and_heading_place_a_local_cloud(tmp_path):
    src, pts = _local_cloud(tmp_path)
    # the sweep's origin 30 m east and 10 m north of the base point, its x axis pointing north (90 deg)
    site = _site(cloud_frame={"offset": [E0 + 30.0, N0 + 10.0, 181.5], "heading_deg": 90.0})
    m, meta, res = _read(tmp_path, src, site)
    expect = np.c_[30.0 - pts[:, 1], 10.0 + pts[:, 0], pts[:, 2] + 1.5]  # x' = -y, y' = x; then the offset
    assert np.allclose(m.vertices, expect, atol=1e-3)
    assert meta["frame"]["cloud_frame"]["heading_deg"] == 90.0
    assert res["cloud_frame"]["offset"] == [E0 + 30.0, N0 + 10.0, 181.5]
    # the same as a 4x4 transform
    t = [[0, -1, 0, E0 + 30.0], [1, 0, 0, N0 + 10.0], [0, 0, 1, 181.5], [0, 0, 0, 1]]
    m2, meta2, _ = _read(tmp_path, src, _site(cloud_frame={"transform": t}), name="m4")
    assert np.allclose(m2.vertices, expect, atol=1e-3)
    assert np.allclose(meta2["frame"]["cloud_frame"]["transform"], t)
    # without it the sweep stays where it is (local, small coordinates)
    m3, meta3, _ = _read(tmp_path, src, _site(), name="none")
    assert np.allclose(m3.vertices, pts, atol=1e-3) and meta3["frame"]["cloud_frame"] is None


def test_preflight_checks_the_placed_box(tmp_path):
    src, _ = _local_cloud(tmp_path)
    near = _site(cloud_frame={"offset": [E0 + 30.0, N0 + 10.0, 181.5], "heading_deg": 90.0})
    assert read_cloud_preflight(near, P.ReadCloudParams(), {"in_cloud": src}) == []
    far = _site(cloud_frame={"offset": [E0 + 900.0, N0, 181.5]})
    probs = read_cloud_preflight(far, P.ReadCloudParams(), {"in_cloud": src})
    assert len(probs) == 1 and "outside the cloud's box" in probs[0]


@pytest.mark.parametrize("bad, words", [
    ({"transform": [[1, 0, 0], [0, 1, 0]]}, "4x4"),
    ({"transform": [[2, 0, 0, 0], [0, 2, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]]}, "not a rigid motion"),
    ({"offset": [1, 2, 3], "transform": np.eye(4).tolist()}, "both transform and offset"),
    ({"offset": [1, 2, 3, 4]}, "offset must be"),
    ({"shift": [1, 2]}, "unknown cloud_frame keys"),
])
def test_a_bad_cloud_frame_is_refused_naming_the_key(tmp_path, bad, words):
    src, _ = _local_cloud(tmp_path)
    with pytest.raises(InputError, match=words):
        _read(tmp_path, src, _site(cloud_frame=bad))
    assert not (tmp_path / "out" / "points.ply").exists()


def test_a_feet_crs_base_point_lands_in_the_same_place_in_read_cloud_and_roads(tmp_path):
    """Autzen's case: NAD83(HARN) Oregon Lambert in international feet, base point {x, y, z} in feet."""
    import laspy
    from pyproj import CRS

    from twinkit.geo import SiteFrame

    crs = "EPSG:2994"
    bx, by, bz = 636600.0, 849200.0, 400.0  # feet
    rng = np.random.default_rng(1)
    h = laspy.LasHeader(point_format=3, version="1.2")
    h.add_crs(CRS(crs))
    h.offsets, h.scales = [bx, by, 0.0], [0.01, 0.01, 0.01]
    las = laspy.LasData(h)
    xs, ys, zs = bx + rng.uniform(-300, 300, 500), by + rng.uniform(-300, 300, 500), bz + rng.uniform(0, 50, 500)
    las.x, las.y, las.z = xs, ys, zs
    src = tmp_path / "feet.las"
    las.write(str(src))
    site = {"name": "autzen", "crs": crs, "base_point": {"x": bx, "y": by, "z": bz}}
    m, meta, _ = _read(tmp_path, src, site)
    frame = SiteFrame.from_site(site)
    roads_xy = frame.projected_to_local(np.c_[las.x, las.y])  # what the roads steps use
    assert np.allclose(m.vertices[:, :2], roads_xy, atol=1e-3)
    # z: the base point's z is in the CRS's feet too: 10 ft above it is 3.048 m up in both
    assert np.allclose(m.vertices[:, 2], (np.asarray(las.z) - bz) * 0.3048, atol=1e-3)
    assert np.allclose(frame.local_to_height(m.vertices[:, 2]), np.asarray(las.z) * 0.3048, atol=1e-3)
    # and through lon/lat (the OSM route): the same point
    ll = frame.local_to_lonlat(m.vertices[:5, :2])
    assert np.allclose(frame.lonlat_to_local(ll), m.vertices[:5, :2], atol=1e-3)
    assert abs(frame.alt - bz * 0.3048) < 1e-9


def _plane_wall(n=4000, seed=0):
    """A ground (normals up) and a wall facing -y (normals -y), as a scan from the street sees them."""
    rng = np.random.default_rng(seed)
    g = np.c_[rng.uniform(0, 12, n), rng.uniform(0, 5, n), rng.normal(0, 0.003, n)]
    w = np.c_[rng.uniform(0, 12, n // 2), 5.0 + rng.normal(0, 0.003, n // 2), rng.uniform(0.2, 4, n // 2)]
    pts = np.vstack([g, w])
    nrm = np.vstack([np.tile([0, 0, 1.0], (n, 1)), np.tile([0, -1.0, 0], (n // 2, 1))]).astype(np.float32)
    return pts, nrm


def test_inward_file_normals_are_flipped_with_a_metric(tmp_path, caplog):
    pts, true_n = _plane_wall()
    rng = np.random.default_rng(2)
    flipped = rng.random(len(pts)) < 0.24
    src = tmp_path / "normals.ply"
    write_ply(src, Mesh(vertices=pts, attrs={"normals": np.where(flipped[:, None], -true_n, true_n)}))
    caplog.set_level("INFO")
    m, meta, res = _read(tmp_path, src, {"name": "t"})
    got = m.attrs["normals"]
    assert (np.einsum("ij,ij->i", got, true_n) > 0).mean() > 0.99
    chk = meta["fields"]["normals_check"]
    assert 0.2 < chk["disagreeing_share"] < 0.28 and chk["flipped"] == res["normals_flipped"] > 0
    assert chk["near_horizontal_down_before"] > 0.2 and chk["near_horizontal_down_after"] < 0.01
    assert "point into the surface" in caplog.text
    # consistent normals from the file are kept as they are
    src2 = tmp_path / "good.ply"
    write_ply(src2, Mesh(vertices=pts, attrs={"normals": true_n}))
    m2, meta2, _ = _read(tmp_path, src2, {"name": "t"}, name="good")
    assert np.array_equal(m2.attrs["normals"], true_n) and meta2["fields"]["normals_check"]["flipped"] == 0
    # measuring only (file_normals_flip_share=1): nothing changes
    m3, meta3, _ = _read(tmp_path, src, {"name": "t"}, P.ReadCloudParams(file_normals_flip_share=1.0), name="off")
    assert np.array_equal(m3.attrs["normals"], np.where(flipped[:, None], -true_n, true_n).astype(np.float32))


def test_classification_fields_of_ply_are_kept(tmp_path):
    pts, _ = _plane_wall(400)
    src = tmp_path / "cc.ply"
    codes = np.where(pts[:, 2] < 0.1, 2, 6).astype(np.float32)  # CloudCompare writes its scalar fields as float
    write_ply(src, Mesh(vertices=pts, attrs={"scalar_Classification": codes}))
    m, meta, _ = _read(tmp_path, src, {"name": "t"})
    assert m.attrs["classification"].dtype == np.uint8
    assert np.array_equal(m.attrs["classification"], codes.astype(np.uint8)) and meta["fields"]["classification"]


def test_a_wrong_reference_does_not_turn_the_ground_upside_down():
    """The demo's E57 case: scanner positions that are not where the points were seen from (here below the
    ground) disagree with correct file normals; flipping would point the ground down, so the file is kept."""
    from twinkit_pointcloud.normals import check_file_normals

    pts, true_n = _plane_wall()
    out, chk = check_file_normals(pts, true_n, "scanner", scanner_index=np.zeros(len(pts), np.int32),
                                  scanner_positions=np.array([[5.0, 2.0, -3.0]]))
    assert chk["disagreeing_share"] > 0.5 and chk["flipped"] == 0 and "turn" in chk["kept_because"]
    assert np.array_equal(out, true_n)

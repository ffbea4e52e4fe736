"""read_cloud checks what it reads (issue 47): declared counts, duplicates, flat clouds, far outliers."""
from __future__ import annotations

import numpy as np
import pytest
from twinkit import InputError
from twinkit.mesh import Mesh, write_ply

from twinkit_pointcloud import plugin as P
from twinkit_pointcloud.readers import duplicate_rows, read_any
from twinkit_pointcloud.street import flat_capture


def _street(n=2000, seed=0):
    rng = np.random.default_rng(seed)
    return np.c_[rng.uniform(0, 30, n), rng.uniform(0, 12, n), rng.uniform(0, 3, n)]


def _read(ctx, src):
    return P.read_cloud(P.ReadCloudParams(), ctx, in_cloud=src, out_points_ply=ctx.workdir / "points.ply",
                        out_points_meta_json=ctx.workdir / "points_meta.json")


def test_a_binary_ply_holding_more_vertices_than_declared_is_refused(tmp_path):
    src = tmp_path / "more.ply"
    write_ply(src, Mesh(_street(100)))
    data = src.read_bytes().replace(b"element vertex 100", b"element vertex 60 ")  # same header length
    src.write_bytes(data)
    with pytest.raises(InputError, match=r"more.ply: the header declares 60 vertices, but the file holds more "
                                         r"\(about 40 more after them\)"):
        read_any(src)
    ok = tmp_path / "newline.ply"
    write_ply(ok, Mesh(_street(100)))
    ok.write_bytes(ok.read_bytes() + b"\n")  # less than a row after the last element: accepted
    assert read_any(ok).n == 100


def test_duplicate_rows_keep_the_first_of_each_group():
    xyz = np.array([[1.0, 2, 3], [4, 5, 6], [1, 2, 3], [-0.0, 0, 0], [0, 0, 0], [4, 5, 6.000001]])
    assert duplicate_rows(xyz).tolist() == [False, False, True, False, True, False]
    assert duplicate_rows(_street()) is None


def test_flat_clouds_are_refused_with_the_reason(tmp_path, ctx):
    plan = _street()
    plan[:, 2] = 12.5
    assert "only 0.0000 m in height (all z equal" in flat_capture("p.ply", np.ptp(plan, axis=0), plan)
    tilted = _street()
    tilted[:, 2] = 0.1 * tilted[:, 0] + 0.05 * tilted[:, 1]  # a tilted plane: 3 m high, still 2D
    assert "all its points lie in one plane" in flat_capture("t.ply", np.ptp(tilted, axis=0), tilted)
    assert flat_capture("s.ply", np.ptp(_street(), axis=0), _street()) is None
    src = tmp_path / "tilted.ply"
    write_ply(src, Mesh(tilted), xyz_dtype="f8")
    with pytest.raises(InputError, match="tilted.ply: the cloud is flat"):
        _read(ctx, src)
    assert not (ctx.workdir / "points.ply").exists()


def test_a_geographic_file_crs_names_site_crs_and_a_zone(tmp_path):
    from twinkit.geo import to_site_frame

    deg = np.c_[[24.93, 60.17] + _street()[:, :2] * 1e-5, _street()[:, 2]]
    site = {"name": "t", "crs": "EPSG:4326", "base_point": {"lat": 60.17, "lon": 24.93, "alt": 0}}
    with pytest.raises(InputError, match=r"site.crs \(WGS 84\) is not a projected CRS in metres.*EPSG:32635"):
        to_site_frame(deg, "EPSG:4326", site, "deg.las")

"""read_cloud's preflight (issue 28): the cloud's box from its header, its centre as lat/lon, and a refusal
when the site's base point lies far outside it -- before any long step runs."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pyproj import Transformer

from conftest import REPO

from twinkit_pointcloud.plugin import ReadCloudParams
from twinkit_pointcloud.preflight import cloud_bounds, read_cloud_preflight

# a 100 x 60 m street of points in Lambert-93 (the IGN LiDAR HD CRS), like the IGN extract
X0, Y0 = 870200.0, 6617083.0


def _las(path: Path, n: int = 2000) -> Path:
    import laspy
    from pyproj import CRS

    rng = np.random.default_rng(0)
    h = laspy.LasHeader(point_format=3, version="1.2")
    h.add_crs(CRS("EPSG:2154"))
    h.offsets = [X0, Y0, 0.0]
    h.scales = [0.01, 0.01, 0.01]
    las = laspy.LasData(h)
    las.x = X0 + rng.uniform(0, 100, n)
    las.y = Y0 + rng.uniform(0, 60, n)
    las.z = 180 + rng.uniform(0, 15, n)
    las.write(str(path))
    return path


def _site(east_of_cloud_m: float) -> dict:
    """A site whose base point is ``east_of_cloud_m`` east of the cloud's east edge (0: at its centre)."""
    x = X0 + 100.0 + east_of_cloud_m if east_of_cloud_m else X0 + 50.0
    lon, lat = Transformer.from_crs("EPSG:2154", "EPSG:4326", always_xy=True).transform(x, Y0 + 30.0)
    return {"name": "ign", "crs": "EPSG:2154", "base_point": {"lat": lat, "lon": lon, "alt": 180.0}}


def test_header_bounds_without_reading_the_points(tmp_path):
    lo, hi, crs = cloud_bounds(_las(tmp_path / "street.laz"))
    assert lo[0] == pytest.approx(X0, abs=0.5) and hi[0] == pytest.approx(X0 + 100, abs=0.5)
    assert "Lambert-93" in crs


def test_binary_ply_bounds(tmp_path):
    from twinkit.mesh import Mesh, write_ply

    v = np.array([[1.0, 2.0, 3.0], [-4.0, 5.0, 0.5], [2.0, -1.0, 9.0]])
    p = tmp_path / "c.ply"
    write_ply(p, Mesh(v, np.zeros((0, 3), np.int64)))
    lo, hi, crs = cloud_bounds(p)
    assert lo.tolist() == [-4.0, -1.0, 0.5] and hi.tolist() == [2.0, 5.0, 9.0] and crs is None


def test_base_point_430_m_off_the_cloud_is_refused_naming_both_positions(tmp_path, caplog):
    las = _las(tmp_path / "street.laz")
    caplog.set_level("INFO")
    assert read_cloud_preflight(_site(0), ReadCloudParams(), {"in_cloud": las}) == []
    assert "centre lat 46.63" in caplog.text  # the cloud centre as lat/lon
    assert read_cloud_preflight(_site(100), ReadCloudParams(), {"in_cloud": las}) == []  # a rounded base point
    probs = read_cloud_preflight(_site(430), ReadCloudParams(), {"in_cloud": las})
    assert len(probs) == 1 and "430 m outside the cloud's box" in probs[0], probs
    assert "site.base_point.lat=" in probs[0] and "base point (lat " in probs[0]
    # the limit is a parameter; 0 switches the check off
    assert read_cloud_preflight(_site(430), ReadCloudParams(max_base_point_offset_m=0), {"in_cloud": las}) == []


def test_unreadable_header_is_left_to_the_reader(tmp_path):
    """A broken file is read_cloud's to name (its messages are tested in test_readers.py / test_bad_input.py)."""
    bad = tmp_path / "broken.laz"
    bad.write_bytes(b"LASF" + b"\0" * 20)
    assert read_cloud_preflight(_site(0), ReadCloudParams(), {"in_cloud": bad}) == []


def test_a_run_is_refused_before_the_first_step(tmp_path):
    """The real command: a cloud whose base point is 430 m off, road_source=none: exit 2 in seconds, no step
    folder written, the base point and the cloud centre both named."""
    las = _las(tmp_path / "street.laz")
    bp = _site(430)["base_point"]
    env = {k: v for k, v in os.environ.items() if not k.startswith("TWINKIT_")}
    p = subprocess.run([sys.executable, "-m", "twinkit", "recipe=pointcloud_site", "site=mex",
                        f"site.inputs.cloud={las}", "site.crs=EPSG:2154", f"site.base_point.lat={bp['lat']}",
                        f"site.base_point.lon={bp['lon']}", "road_source=none",
                        f"engine.outputs_dir={tmp_path / 'out'}"],
                       capture_output=True, text=True, cwd=REPO, env=env, timeout=300)
    assert p.returncode == 2, p.stderr[-3000:]
    errors = [ln for ln in p.stderr.splitlines() if "error" in ln.lower()]
    assert len(errors) == 1 and "430 m outside the cloud's box" in errors[0], p.stderr[-3000:]
    assert "step 'read_cloud' (step/read_cloud): street.laz: the site's base point" in errors[0]
    assert not list((tmp_path / "out" / "mex").glob("0*"))

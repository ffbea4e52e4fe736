"""The roads-only recipe (recipes/roads.yaml) end to end through the CLI: no point cloud, a road source,
OpenDRIVE in the site frame, the carla.Map check, the top view and the run report."""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import HERE, OSM_DIR, SHARED

ROOT = (HERE / "../../..").resolve()


def run(tmp_path: Path, site_yaml: str, *args: str) -> subprocess.CompletedProcess:
    conf = tmp_path / "conf"
    if not conf.exists():
        shutil.copytree(ROOT / "conf", conf, symlinks=False, ignore=shutil.ignore_patterns("local"))
    (conf / "site" / "roadsite.yaml").write_text(site_yaml)
    env = {k: v for k, v in os.environ.items() if not k.startswith("TWINKIT_")}
    env["TWINKIT_CONFIG_DIR"] = str(conf)
    return subprocess.run([sys.executable, "-m", "twinkit", "recipe=roads", "site=roadsite",
                           f"engine.outputs_dir={tmp_path / 'out'}", *args], capture_output=True, text=True,
                          cwd=tmp_path, env=env, timeout=600)


def outputs(tmp_path: Path) -> dict:
    return {p.name: p for p in (tmp_path / "out" / "roadsite").glob("0*/*") if p.is_file()}


def test_roads_recipe_from_an_osm_file(tmp_path):
    osm = OSM_DIR / "helsinki_center.osm.pbf"
    if not osm.is_file():
        pytest.skip(f"shared sample data absent: {osm}")
    site = ("name: roadsite\ncrs: EPSG:3067\nbase_point: {lat: 60.1699, lon: 24.9384, alt: 0.0}\n"
            f"inputs:\n  osm: {osm}\n")
    p = run(tmp_path, site)
    assert p.returncode == 0, p.stderr[-2000:]
    out = outputs(tmp_path)
    chk = json.loads(out["roads_check.json"].read_text())
    assert chk["ok"] and chk["roads"] > 20 and chk["carla"]["waypoints_inside"] > 500
    assert out["roads_overview.png"].stat().st_size > 10000
    report = next((tmp_path / "out" / "roadsite" / "runs").glob("*/report/report.html")).read_text()
    assert "roads_overview.png" in report and "roads_check.json" in report
    assert "cropped to 300 m around the base point" in p.stderr + p.stdout


def test_roads_recipe_from_an_opendrive_map(tmp_path):
    xodr = SHARED / "opendrive" / "soderleden.xodr"
    if not xodr.is_file():
        pytest.skip(f"shared sample data absent: {xodr}")
    # UTM zone 32 map, a site in SWEREF 99 TM's projection with its base point on the map (a PROJ string:
    # EPSG:3006 itself is refused at lat 0, lon 4.5, outside its area of use)
    site = ("name: roadsite\ncrs: '+proj=utm +zone=33 +ellps=GRS80 +units=m +no_defs'\n"
            "base_point: {lat: -0.0000685, lon: 4.5164, alt: 0.0}\n"
            f"osm_radius_m: 900\ninputs:\n  xodr: {xodr}\n")
    p = run(tmp_path, site, "road_source=opendrive")
    assert p.returncode == 0, p.stderr[-2000:]
    out = outputs(tmp_path)
    rep = json.loads(out["reprojection.json"].read_text())
    assert rep["residual_max_m"] < 0.01
    chk = json.loads(out["roads_check.json"].read_text())
    assert chk["ok"] and chk["source"] == "opendrive" and chk["roads"] == 5
    assert out["roads.xodr"].read_text() == out["opendrive.xodr"].read_text()
    assert out["roads_overview.png"].is_file() and "osm.osm" not in out

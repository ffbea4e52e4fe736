"""Fixtures for the run report: a real demo run (made once per session), the same run with the files
of later stages added (segmentation labels and metrics, OpenDRIVE, alignment, renders and predictions),
and a headless Chromium driven by Selenium.

Chromium is found through $TWINKIT_CHROMIUM / $TWINKIT_CHROMEDRIVER, else ``chromium`` (or
``chromium-browser``, ``google-chrome``) and ``chromedriver`` on PATH (Debian: apt-get install chromium
chromium-driver). Browser tests skip, saying why, when Selenium, the browser, its driver or three.js
(``npm ci``) is missing. Screenshots are kept in $TWINKIT_TEST_ARTIFACTS (default build/test-artifacts/report).
"""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = Path(os.environ.get("TWINKIT_TEST_ARTIFACTS") or ROOT / "build" / "test-artifacts" / "report")
DEMO_ARGS = ["recipe=report_test", "site=demo", "+site.photo_count=3", "reconstructor.depth=8",
             "steps.bake_texture.texture_px=1024"]
#: the mesh branch of recipes/pointcloud_site.yaml: the full recipe (segmentation on CPU, roads, export)
#: takes many minutes; the later stages' files are stood in for by ``future_run``.
RECIPE = """# @package _global_
defaults:
  - /reconstructor: poisson
  - _self_
recipe:
  name: report_test
  steps:
    - {id: read_cloud, uses: step/read_cloud, inputs: {in_cloud: "${oc.select:site.cloud_file,cloud}"}}
    - {id: reconstruct, uses: reconstructor}
    - {id: clean, uses: step/clean_mesh}
    - {id: simplify, uses: step/simplify}
    - {id: texture, uses: step/bake_texture}
    - {id: evaluate, uses: step/evaluate_reconstruction}
"""


def make_test_config(tmp: Path) -> Path:
    """A copy of conf/ (recipes resolved) with the recipe ``report_test`` added."""
    conf = tmp / "conf"
    shutil.copytree(ROOT / "conf", conf, symlinks=False, ignore=shutil.ignore_patterns("local"))
    (conf / "local").mkdir(exist_ok=True)
    (conf / "recipe" / "report_test.yaml").write_text(RECIPE)
    return conf


class DemoRun:
    def __init__(self, out: Path, proc: subprocess.CompletedProcess):
        self.out = out
        self.ws = out / "demo"
        self.proc = proc
        self.text = proc.stdout + proc.stderr
        m = re.search(r"twinkit: report file://(\S+)", self.text)
        self.report = Path(m.group(1)) if m else None
        runs = sorted((self.ws / "runs").iterdir())
        self.run_dir = runs[-1]
        self.manifest = json.loads((self.run_dir / "manifest.json").read_text())

    def engine(self, ws: Path | None = None, site_root: Path | None = None):
        from types import SimpleNamespace

        return SimpleNamespace(workspace=ws or self.ws, site_root=site_root or self.ws)


@pytest.fixture(scope="session")
def demo_run(tmp_path_factory) -> DemoRun:
    """The real command on the demo site, mesh branch, small settings (about 40-60 s on 2 cores)."""
    out = tmp_path_factory.mktemp("report-demo")
    env = dict(os.environ)
    env.setdefault("OMP_NUM_THREADS", "2")
    env["TWINKIT_CONFIG_DIR"] = str(make_test_config(tmp_path_factory.mktemp("report-conf")))
    proc = subprocess.run([sys.executable, "-m", "twinkit", *DEMO_ARGS, f"engine.outputs_dir={out}"],
                          capture_output=True, text=True, cwd=ROOT, env=env, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return DemoRun(out, proc)


def _fake_labels(xyz: np.ndarray, colors: np.ndarray) -> np.ndarray:
    """Plausible CityScapes trainIds from height and colour (a stand-in for the segmentation stage)."""
    z = xyz[:, 2]
    lab = np.full(len(z), 2, np.uint8)  # building
    low = z < 0.25
    lab[low] = 0  # road
    lab[low & (np.abs(xyz[:, 0]) > 8) & (np.abs(xyz[:, 1]) > 8)] = 1  # sidewalk corners
    c = colors.astype(int)
    lab[(c[:, 1] > c[:, 0] + 15) & (c[:, 1] > c[:, 2])] = 8  # vegetation
    lab[(z > 0.25) & (z < 2.0) & (c[:, 2] > c[:, 0] + 40)] = 13  # blue cars
    return lab


XODR = """<?xml version="1.0" standalone="yes"?>
<OpenDRIVE><header revMajor="1" revMinor="6" name="test"/>
<road id="1" length="60" junction="-1"><planView>
 <geometry s="0" x="-30" y="0" hdg="0" length="60"><line/></geometry></planView>
 <lanes><laneSection s="0">
  <left><lane id="2" type="driving"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane>
        <lane id="1" type="driving"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane></left>
  <center><lane id="0" type="none"/></center>
  <right><lane id="-1" type="driving"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane>
         <lane id="-2" type="driving"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane></right>
 </laneSection></lanes></road>
<road id="2" length="21" junction="-1"><planView>
 <geometry s="0" x="0" y="9" hdg="1.5707963" length="6"><line/></geometry>
 <geometry s="6" x="0" y="15" hdg="1.5707963" length="15"><arc curvature="0.03"/></geometry></planView>
 <lanes><laneSection s="0">
  <left><lane id="1" type="driving"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane></left>
  <center><lane id="0" type="none"/></center>
  <right><lane id="-1" type="driving"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane></right>
 </laneSection></lanes></road>
</OpenDRIVE>
"""

#: shaped like twinkit-segmentation's seg_metrics.json: scores, and the upper bound of the same tables
SEG_METRICS = {
    "scores": {"miou": 0.612, "accuracy": 0.884, "per_class": {
        "road": {"id": 0, "iou": 0.91, "f1": 0.953, "gt_vertices": 10234},
        "sidewalk": {"id": 1, "iou": 0.72, "f1": 0.837, "gt_vertices": 3120},
        "building": {"id": 2, "iou": 0.83, "f1": 0.907, "gt_vertices": 8123},
        "vegetation": {"id": 8, "iou": 0.41, "f1": 0.581, "gt_vertices": 902},
        "car": {"id": 13, "iou": 0.19, "f1": 0.319, "gt_vertices": 311}}},
    "upper_bound": {"miou": 0.777, "per_class": {"road": {"id": 0, "iou": 0.98, "f1": 0.99}}},
}


class FutureRun(DemoRun):
    """The demo run plus an 08_segment step with the files the stages still being built will write."""


@pytest.fixture(scope="session")
def future_run(demo_run) -> FutureRun:
    from PIL import Image

    from twinkit.report.render import read_view_mesh

    ws = demo_run.ws
    seg = ws / "08_segment"
    seg.mkdir(exist_ok=True)
    mesh = read_view_mesh(ws / "06_texture" / "textured_mesh.ply")
    np.save(seg / "labels.npy", _fake_labels(mesh.vertices, mesh.colors))
    (seg / "seg_metrics.json").write_text(json.dumps(SEG_METRICS))
    (seg / "alignment.json").write_text(json.dumps({"residual_rms_m": 0.042, "residual_max_m": 0.118, "pairs": 38}))
    (seg / "roads.xodr").write_text(XODR)
    Image.new("RGB", (200, 120), (30, 120, 200)).save(seg / "road_qa.png")
    for sub in ("renders", "predictions"):
        (seg / sub).mkdir(exist_ok=True)
    photos = sorted((ws / "01_site" / "photos").glob("*.jpg"))
    for i, p in enumerate(photos):
        shutil.copy(p, seg / "renders" / f"view_{i:03d}.jpg")
        lab = Image.open(ws / "01_site" / "photos" / "labels" / f"{p.stem}.png")
        lab.save(seg / "predictions" / f"view_{i:03d}.png")
    manifest = json.loads(json.dumps(demo_run.manifest))
    manifest["steps"].append({"id": "segment", "folder": "08_segment", "plugin": "segmenter/test_stand_in",
                              "status": "ran", "why": "no earlier result", "duration_s": 3.2, "peak_rss_mb": 812.0,
                              "key": "0" * 32, "metrics": {"miou": 0.612}})
    run_dir = ws / "runs" / "future"
    run_dir.mkdir()
    (run_dir / "manifest.json").write_text(json.dumps(manifest, indent=1))
    (run_dir / "run.log").write_text("")
    from twinkit.report import write_report

    fr = FutureRun.__new__(FutureRun)
    fr.out, fr.ws, fr.proc, fr.text = demo_run.out, ws, demo_run.proc, ""
    fr.run_dir, fr.manifest = run_dir, manifest
    fr.report = write_report(run_dir, manifest, fr.engine())
    assert fr.report is not None
    return fr


# --------------------------------------------------------------------------- the browser

def _which(*names: str) -> str | None:
    for n in names:
        p = shutil.which(n)
        if p:
            return p
    return None


def find_chromium() -> tuple[str | None, str | None]:
    """(browser, driver): $TWINKIT_CHROMIUM / $TWINKIT_CHROMEDRIVER when set (and existing), else PATH."""
    def pick(var: str, *names: str) -> str | None:
        if os.environ.get(var):
            p = os.environ[var]
            return p if Path(p).is_file() or shutil.which(p) else None
        return _which(*names)

    return (pick("TWINKIT_CHROMIUM", "chromium", "chromium-browser", "google-chrome"),
            pick("TWINKIT_CHROMEDRIVER", "chromedriver"))


CHROMIUM_FLAGS = [
    "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--disable-dev-shm-usage", "--hide-scrollbars", "--window-size=1400,1000", "--force-device-scale-factor=1",
    # WebGL without a GPU: Chromium's software rasteriser (SwiftShader through ANGLE)
    "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
]


@pytest.fixture(scope="session")
def browser():
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        pytest.skip("Selenium is not installed (pip install selenium; scripts/setup.sh should do it)")
    from twinkit.report.viewer import three_bundle

    if three_bundle() is None:
        pytest.skip("three.js is not bundled: run 'npm ci && npm run bundle' in the repository root")
    chrome, driver = find_chromium()
    if not chrome:
        pytest.skip("no Chromium: apt-get install chromium chromium-driver (or set TWINKIT_CHROMIUM)")
    if not driver:
        pytest.skip("no chromedriver: apt-get install chromium-driver (or set TWINKIT_CHROMEDRIVER)")
    opts = webdriver.ChromeOptions()
    opts.binary_location = chrome
    profile = tempfile.mkdtemp(prefix="twinkit-chromium-")
    for a in CHROMIUM_FLAGS + [f"--user-data-dir={profile}"]:
        opts.add_argument(a)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    try:
        d = webdriver.Chrome(service=Service(driver), options=opts)
    except Exception as exc:  # a broken install is a skip with the reason, not an error in every test
        shutil.rmtree(profile, ignore_errors=True)
        pytest.skip(f"Chromium did not start ({type(exc).__name__}: {str(exc).splitlines()[0][:200]})")
    d.set_page_load_timeout(60)
    yield d
    d.quit()
    shutil.rmtree(profile, ignore_errors=True)


@pytest.fixture(scope="session")
def artifacts() -> Path:
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    return ARTIFACTS


def open_report(driver, path: Path, timeout: float = 60) -> dict:
    """Load a report and wait for its 3D view to be drawn (or to report an error)."""
    driver.get(Path(path).resolve().as_uri())
    t0 = time.time()
    st = None
    while time.time() - t0 < timeout:
        st = driver.execute_script(
            "var v = window.twinkitViewer; return v ? {ready: v.ready, error: v.error, frames: v.frames, "
            "mode: v.mode, seg: v.hasSegmentation} : null;")
        if st and (st["ready"] or st["error"]):
            return st
        time.sleep(0.2)
    return st or {}

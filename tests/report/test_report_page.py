"""The run report's content, read from a real demo run (no browser needed)."""
from __future__ import annotations

import json
import logging
import re
import shutil
import struct
import subprocess
import time
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlparse

import numpy as np
import pytest

from twinkit import report as R
from twinkit.mesh.glb import write_colored_glb
from twinkit.report import render, viewer
from twinkit.report.page import fmt


class _Links(HTMLParser):
    def __init__(self):
        super().__init__()
        self.href: list[str] = []
        self.src: list[str] = []
        self.ids: list[str] = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if "href" in a:
            self.href.append(a["href"])
        if "src" in a:
            self.src.append(a["src"])
        if "id" in a:
            self.ids.append(a["id"])


def parse(page: Path) -> _Links:
    p = _Links()
    p.feed(page.read_text())
    return p


def local_target(page: Path, url: str) -> Path:
    return (page.parent / unquote(url.split("#")[0])).resolve()


def section_ids(page: Path) -> list[str]:
    return re.findall(r"<section id=\"([^\"]+)\"", page.read_text())


# --------------------------------------------------------------------------- the real run

def test_the_command_writes_the_report_and_logs_its_link(demo_run):
    assert demo_run.report is not None, demo_run.text
    assert demo_run.report == demo_run.run_dir / "report" / "report.html"
    assert demo_run.report.is_file()
    info = json.loads((demo_run.report.parent / "report.json").read_text())
    assert info["timings_s"]["total_s"] < 30


def test_sections_follow_the_stages_that_exist(demo_run):
    ids = section_ids(demo_run.report)
    for sid in ("summary", "timeline", "pictures", "roads", "view3d", "samples", "recon", "provenance", "files"):
        assert sid in ids, ids
    # no segmentation metrics or alignment in this recipe yet: no empty sections for them
    assert "segmetrics" not in ids and "alignment" not in ids


def test_timeline_has_every_step_with_status_reason_and_duration(demo_run):
    text = demo_run.report.read_text()
    table = text.split("<table class=\"timeline\">", 1)[1].split("<p class=\"legend\">", 1)[0]
    # a step that ran with substeps has a folded row (its own small table) under it
    folded = re.compile(r"<tr class=\"substeps\">.*?</details></td></tr>", re.S)
    ran_with_parts = [s for s in demo_run.manifest["steps"]
                      if s["status"] == "ran" and (s.get("metrics") or {}).get("substeps")]
    assert len(folded.findall(table)) == len(ran_with_parts)
    rows = folded.sub("", table).split("<tr>")[2:]
    assert len(rows) == len(demo_run.manifest["steps"])
    for row, step in zip(rows, demo_run.manifest["steps"]):
        assert step["folder"] in row and f"st-{step['status']}" in row
        assert f"{step['duration_s']:.1f} s" in row
        assert step["why"] in row


def test_links_reach_every_intermediate_file(demo_run):
    page = demo_run.report
    targets = {local_target(page, h) for h in parse(page).href if not urlparse(h).scheme}
    for step in demo_run.manifest["steps"]:
        folder = demo_run.ws / step["folder"]
        for f in folder.rglob("*"):
            if f.is_file():
                assert f.resolve() in targets, f"no link to {f}"
    assert (demo_run.run_dir / "manifest.json").resolve() in targets


def test_page_is_offline_and_every_local_reference_exists(demo_run):
    page = demo_run.report
    links = parse(page)
    for url in links.src + links.href:
        scheme = urlparse(url).scheme
        assert scheme in ("", "file"), f"remote reference {url}"
        if not scheme and not url.startswith("#"):
            assert local_target(page, url).exists(), url
    for s in links.src:
        assert not s.startswith("/"), s
    # the pictures and the 3D view live in the report folder itself
    folder = page.parent
    for name in ("img/ortho.png", "viewer/model.glb.js", "viewer/viewer.js", "report.css"):
        assert (folder / name).is_file(), name


def test_orthophoto_is_a_top_down_picture_of_the_mesh(demo_run):
    from PIL import Image

    im = np.asarray(Image.open(demo_run.report.parent / "img" / "ortho.png"))
    assert im.shape[2] == 4 and max(im.shape[:2]) == R.ORTHO_PX
    covered = im[..., 3] > 0
    assert 0.2 < covered.mean() < 0.95  # the demo's streets cover part of the square site
    assert len(np.unique(im[covered][:, :3].reshape(-1, 3), axis=0)) > 1000  # textured, not flat


def test_recon_metrics_tables(demo_run):
    text = demo_run.report.read_text()
    sec = text.split("<section id=\"recon\">", 1)[1].split("</section>", 1)[0]
    metrics = json.loads((demo_run.ws / "07_evaluate" / "recon_metrics.json").read_text())
    assert "cloud_to_mesh_m" in sec and "mesh_to_cloud_m" in sec
    assert fmt(metrics["cloud_to_mesh_m"]["mean"]) in sec
    assert fmt(metrics["counts"]["faces"]) in sec
    assert "recon_metrics.png" in text  # the distance heat map


def test_provenance(demo_run):
    text = demo_run.report.read_text()
    sec = text.split("<section id=\"provenance\">", 1)[1].split("</section>", 1)[0]
    m = demo_run.manifest
    assert m["site"]["crs"] in sec
    for p in m["plugins"]:
        assert p["name"] in sec
    for e in m["inputs"]:
        assert e["sha256"][:16] in sec
    assert "numpy" in sec


def test_no_segmentation_yet_means_no_segmentation_toggle_data(demo_run):
    gltf = read_glb_json(demo_run.report.parent / "viewer" / "model.glb.js")
    attrs = gltf["meshes"][0]["primitives"][0]["attributes"]
    assert "COLOR_0" in attrs and "_CLASS_COLOR" not in attrs  # texture colours only
    assert not (demo_run.report.parent / "img" / "ortho_seg.png").exists()


def test_second_report_reuses_the_cached_pictures(demo_run, tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    t = time.perf_counter()
    page = R.write_report(run_dir, demo_run.manifest, demo_run.engine())
    took = time.perf_counter() - t
    info = json.loads((page.parent / "report.json").read_text())
    assert info["timings_s"].get("ortho_cached") == 1 and "glb_s" not in info["timings_s"]
    assert took < 5
    a, b = page.parent / "img" / "ortho.png", demo_run.report.parent / "img" / "ortho.png"
    assert a.read_bytes() == b.read_bytes()
    assert a.stat().st_ino == b.stat().st_ino  # hard links to the one cached file


# --------------------------------------------------------------------------- later stages (stand-in files)

def test_later_stages_add_their_sections(future_run):
    ids = section_ids(future_run.report)
    for sid in ("segmetrics", "alignment", "roads", "samples"):
        assert sid in ids
    folder = future_run.report.parent
    assert (folder / "img" / "ortho_seg.png").is_file()
    assert (folder / "img" / "contact_sheet.jpg").is_file()


def test_segmentation_metrics_table(future_run):
    text = future_run.report.read_text()
    sec = text.split("<section id=\"segmetrics\">", 1)[1].split("</section>", 1)[0]
    for name, v in (("road", 0.91), ("vegetation", 0.41), ("car", 0.19)):
        assert name in sec and fmt(v) in sec
    assert "f1" in sec and "iou" in sec and "miou" in sec and fmt(0.612) in sec
    assert "rgb(128, 64, 128)" in sec  # road's colour swatch
    assert "upper_bound" in sec and fmt(0.777) in sec  # every table of the file


def test_alignment_residual(future_run):
    text = future_run.report.read_text()
    sec = text.split("<section id=\"alignment\">", 1)[1].split("</section>", 1)[0]
    assert "residual_rms_m" in sec and "0.042" in sec
    assert sec.index("residual_rms_m") < sec.index("pairs")  # residuals first


def test_road_network_is_drawn_over_the_orthophoto(future_run):
    text = future_run.report.read_text()
    sec = text.split("<section id=\"roads\">", 1)[1].split("</section>", 1)[0]
    assert "<image href=\"img/ortho.png\"" in sec
    lines = re.findall(r"<polyline class=\"xodr\" points=\"([^\"]+)\"", sec)
    assert len(lines) == 6  # the driving lanes' centre lines: 4 on road 1, 2 on road 2
    assert len(re.findall(r"<polygon class=\"band\"", sec)) == 6  # and each lane's paved band
    # road 1 runs west-east along y = 0: its lane -1 half a lane (1.625 m) south of it, from x = -30
    meta = json.loads(next((future_run.ws / ".cache" / "report").glob("ortho-*.json")).read_text())
    w, h = meta["size"]
    b = meta["bounds"]
    expect = (b[3] + 1.625) / (b[3] - b[1]) * h
    lanes = [[tuple(map(float, p.split(","))) for p in ln.split()] for ln in lines]
    (pts,) = [p for p in lanes if all(abs(y - expect) < 0.2 for _, y in p)]
    assert min(x for x, _ in pts) == pytest.approx((-30 - b[0]) / (b[2] - b[0]) * w, abs=0.2)
    assert "road_qa.png" in sec


def test_segmentation_orthophoto_uses_the_cityscapes_palette(future_run):
    from PIL import Image

    im = np.asarray(Image.open(future_run.report.parent / "img" / "ortho_seg.png"))
    cols = {tuple(c) for c in im[im[..., 3] > 0][:, :3].reshape(-1, 3)[::50]}
    pal = {c for _, c in R.CITYSCAPES}
    assert cols <= pal | {R.IGNORE_COLOR}
    assert (128, 64, 128) in cols and (70, 70, 70) in cols


def test_viewer_model_carries_both_colourings(future_run):
    gltf = read_glb_json(future_run.report.parent / "viewer" / "model.glb.js")
    attrs = gltf["meshes"][0]["primitives"][0]["attributes"]
    # COLOR_0 = texture colours (what every viewer draws), _CLASS_COLOR = segmentation (darkens nothing)
    assert {"POSITION", "COLOR_0", "_CLASS_COLOR"} <= set(attrs) and "_TEXCOLOR" not in attrs


# --------------------------------------------------------------------------- pieces

def read_glb_json(path: Path) -> dict:
    """The JSON chunk of a GLB, or of the GLB a report's model script carries (``model.glb.js``)."""
    from twinkit.report.viewer import read_glb_js

    data = read_glb_js(path) if path.name.endswith(".js") else path.read_bytes()
    magic, version, total = struct.unpack_from("<4sII", data)
    assert magic == b"glTF" and version == 2 and total == len(data)
    n, kind = struct.unpack_from("<I4s", data, 12)
    assert kind == b"JSON"
    return json.loads(data[20:20 + n])


def test_glb_writer_roundtrip(tmp_path):
    xyz = np.array([[0, 0, 0], [2, 0, 0], [0, 3, 1], [2, 3, 1]], float)
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    cols = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 255]], np.uint8)
    seg = R.palette()[[0, 0, 2, 2]]
    p = tmp_path / "m.glb"
    write_colored_glb(p, xyz, faces, cols, seg)
    g = read_glb_json(p)
    data = p.read_bytes()
    n = struct.unpack_from("<I", data, 12)[0]
    binary = data[20 + n + 8:]
    prim = g["meshes"][0]["primitives"][0]
    acc = g["accessors"][prim["attributes"]["POSITION"]]
    view = g["bufferViews"][acc["bufferView"]]
    pos = np.frombuffer(binary[view["byteOffset"]:view["byteOffset"] + view["byteLength"]], "<f4").reshape(-1, 3)
    # y up: site z -> glTF y, site y -> glTF -z (centred on x/y, ground at 0)
    np.testing.assert_allclose(pos[3], [1, 1, -1.5])
    assert acc["min"] == [-1, 0, -1.5] and acc["max"] == [1, 1, 1.5]
    idx = g["accessors"][prim["indices"]]
    assert idx["count"] == 6 and idx["componentType"] == 5125
    for name in ("COLOR_0", "_CLASS_COLOR"):
        c = g["accessors"][prim["attributes"][name]]
        assert c["normalized"] and c["type"] == "VEC4"
    for v in g["bufferViews"]:
        assert v["byteOffset"] % 4 == 0


def test_render_topdown_is_north_up_and_keeps_the_highest_surface():
    # a low red square over the whole frame and a high blue triangle in the north-east corner
    xyz = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0], [6, 6, 5], [10, 6, 5], [10, 10, 5]], float)
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6]])
    cols = np.array([[255, 0, 0]] * 4 + [[0, 0, 255]] * 3, np.uint8)
    img = render.render_topdown(xyz, faces, cols, (0, 0, 10, 10), 100, 100)
    assert img.shape == (100, 100, 4)
    assert tuple(img[5, 95, :3]) == (0, 0, 255)  # top right = north-east: the high triangle wins
    assert tuple(img[95, 5, :3]) == (255, 0, 0)  # south-west: the square
    assert img[..., 3].min() == 255


def test_without_gl_the_orthophoto_is_splatted(monkeypatch):
    def no_gl(*a):
        raise RuntimeError("no EGL here")

    monkeypatch.setattr(render, "_render_gl", no_gl)
    xyz = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 0], [6, 6, 5]], float)
    cols = np.array([[255, 0, 0]] * 3 + [[0, 0, 255]], np.uint8)
    img = render.render_topdown(xyz, np.array([[0, 1, 2]]), cols, (0, 0, 10, 10), 20, 20)
    assert tuple(img[8, 12, :3]) == (0, 0, 255)  # the high point at (6, 6), north-east of the centre
    assert img[19, 19, 3] == 255 and img[0, 0, 3] == 0


def test_ply_reader_matches_plyfile(demo_run):
    from plyfile import PlyData

    path = demo_run.ws / "06_texture" / "textured_mesh.ply"
    mesh = render.read_view_mesh(path)
    ref = PlyData.read(str(path))
    v = ref["vertex"]
    np.testing.assert_allclose(mesh.vertices[:, 0], np.asarray(v["x"], float))
    np.testing.assert_array_equal(mesh.colors[:, 2], np.asarray(v["blue"]))
    faces = np.stack(ref["face"].data["vertex_indices"])
    np.testing.assert_array_equal(mesh.faces, faces)


def test_three_bundle_is_a_classic_script(tmp_path):
    bundle = viewer.three_bundle()
    if bundle is None:
        pytest.skip("three.js is not bundled: run 'npm ci && npm run bundle' in the repository root")
    text = bundle.read_text(encoding="utf-8")
    assert not re.search(r"^\s*(import|export)\s*[{*]", text, re.M)
    assert "window.TWINKIT_THREE" in text
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed")
    (tmp_path / "b.js").write_text(text)
    r = subprocess.run([node, "-e", "globalThis.window = globalThis; require(process.argv[1]); const T = window.TWINKIT_THREE;"
                        "console.log(typeof T.THREE.WebGLRenderer, typeof T.GLTFLoader, typeof T.OrbitControls, T.version)",
                        str(tmp_path / "b.js")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    pinned = json.loads((Path(__file__).resolve().parents[2] / "package.json").read_text())["dependencies"]["three"]
    assert r.stdout.split() == ["function"] * 3 + [pinned]


def test_without_three_the_report_is_written_without_its_3d_view(demo_run, tmp_path, monkeypatch, caplog):
    monkeypatch.setattr(viewer, "three_bundle", lambda: None)
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    with caplog.at_level(logging.WARNING, logger="twinkit"):
        page = R.write_report(run_dir, demo_run.manifest, demo_run.engine())
    assert page is not None and page.is_file()
    warnings = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(warnings) == 1 and "npm ci" in warnings[0].getMessage()
    text = page.read_text()
    assert "three-bundle.js" not in text and "npm ci" in text
    assert "ortho.png" in text  # everything else is there


def test_write_report_never_raises(tmp_path, caplog):
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("")
    with caplog.at_level(logging.WARNING, logger="twinkit"):
        assert R.write_report(blocker, {"steps": []}, None) is None
    assert "no report" in caplog.text
    # a manifest with nothing usable still gives a page
    run = tmp_path / "run"
    run.mkdir()
    page = R.write_report(run, {"steps": ["junk", {"folder": "01_x", "status": "ran"}], "workspace": str(tmp_path)})
    assert page is not None and "01_x" in page.read_text()


# --------------------------------------------------------------------------- sweeps

def _fake_sweep(demo_run, root: Path, values=(6, 7, 8)) -> Path:
    sweep = root / "sweeps" / "20260101-000000"
    for i, depth in enumerate(values):
        job = sweep / f"job{i}"
        job.mkdir(parents=True)
        m = json.loads(json.dumps(demo_run.manifest))
        m["overrides"] = [f"reconstructor.depth={depth}", "site=demo"]
        for s in m["steps"]:
            if s["id"] == "evaluate":
                s["metrics"]["cloud_to_mesh_mean_m"] = 0.2 / depth
            if s["id"] == "reconstruct":
                s["metrics"]["faces"] = 1000 * depth
        (job / "manifest.json").write_text(json.dumps(m))
    (sweep / "job1" / "report").mkdir()
    (sweep / "job1" / "report" / "report.html").write_text("<html></html>")
    return sweep


def test_sweep_summary_table_and_plot(demo_run, tmp_path):
    sweep = _fake_sweep(demo_run, tmp_path)
    page = R.write_sweep_summary(sweep)
    assert page == sweep / "report" / "sweep.html"
    text = page.read_text()
    table = text.split("<table class=\"sweep\">", 1)[1].split("</table>", 1)[0]
    head = table.split("</thead>")[0]
    assert "reconstructor.depth" in head and "evaluate.cloud_to_mesh_mean_m" in head
    assert "site" not in head.replace("site_", "")  # not swept: not a column
    assert len(table.split("<tr>")) - 2 == 3
    assert "href=\"../job1/report/report.html\"" in table
    plots = re.findall(r"<svg class=\"plot\".*?</svg>", text, re.S)
    assert plots and "evaluate.cloud_to_mesh_mean_m" in plots[0]
    pts = re.findall(r"<circle cx=\"([\d.]+)\" cy=\"([\d.]+)\"", plots[0])
    assert len(pts) == 3
    xs, ys = [float(x) for x, _ in pts], [float(y) for _, y in pts]
    assert xs[0] < xs[1] < xs[2]
    assert ys[0] < ys[1] < ys[2]  # the metric falls as depth grows: lower on the plot (larger SVG y)


def test_sweep_callback(demo_run, tmp_path, capsys):
    from hydra.experimental.callback import Callback
    from omegaconf import OmegaConf

    sweep = _fake_sweep(demo_run, tmp_path)
    cb = R.SweepSummaryCallback()
    assert isinstance(cb, Callback)
    cb.on_multirun_end(OmegaConf.create({"hydra": {"sweep": {"dir": str(sweep)}}}))
    assert (sweep / "report" / "sweep.html").is_file()
    assert "sweep summary file://" in capsys.readouterr().out

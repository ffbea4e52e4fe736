"""The report in headless Chromium: loads from file:// without console errors, the 3D view draws,
the texture/segmentation toggle changes what is drawn. Screenshots are kept as test artefacts.

Set TWINKIT_UPDATE_DOCS_SCREENSHOT=1 to also refresh docs/img/report.png (the README's picture).
"""
from __future__ import annotations

import io
import json
import os
import struct
import time
from pathlib import Path

import numpy as np
import pytest

from tests.report.conftest import ROOT, open_report
from twinkit import report as R


def severe_logs(driver) -> list[dict]:
    return [e for e in driver.get_log("browser") if e.get("level") == "SEVERE"]


def canvas_pixels(driver, path: Path | None = None) -> np.ndarray:
    from PIL import Image
    from selenium.webdriver.common.by import By

    el = driver.find_element(By.ID, "viewer-canvas")
    driver.execute_script("arguments[0].scrollIntoView({block: 'center'});", el)
    time.sleep(0.3)
    png = el.screenshot_as_png
    if path is not None:
        path.write_bytes(png)
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)


def wait_frames(driver, after: int, timeout: float = 20) -> None:
    t0 = time.time()
    while time.time() - t0 < timeout:
        if driver.execute_script("return window.twinkitViewer.frames") > after:
            time.sleep(0.2)
            return
        time.sleep(0.1)
    raise AssertionError("the 3D view did not redraw")


def click_mode(driver, mode: str) -> None:
    from selenium.webdriver.common.by import By

    frames = driver.execute_script("return window.twinkitViewer.frames")
    driver.find_element(By.ID, f"mode-{mode}").click()
    wait_frames(driver, frames)
    assert driver.execute_script("return window.twinkitViewer.mode") == mode


def non_background(px: np.ndarray) -> float:
    bg = np.array([0xEE, 0xF0, 0xF3])  # the viewer's background (viewer.js)
    return float((np.abs(px - bg).sum(-1) > 30).mean())


def test_demo_report_loads_without_console_errors_and_draws(browser, demo_run, artifacts):
    st = open_report(browser, demo_run.report)
    assert st.get("ready") and not st.get("error"), st
    assert severe_logs(browser) == []
    px = canvas_pixels(browser, artifacts / "demo_canvas_texture.png")
    assert non_background(px) > 0.10, "the 3D canvas is blank"
    assert len(np.unique(px.reshape(-1, 3), axis=0)) > 500  # textured, not a flat fill
    # no segmentation in this run yet: the toggle says so instead of showing nothing
    assert st["seg"] is False
    assert browser.execute_script("return document.getElementById('mode-segmentation').disabled") is True
    browser.save_screenshot(str(artifacts / "demo_report.png"))


def test_toggle_switches_to_segmentation_colours(browser, future_run, artifacts):
    st = open_report(browser, future_run.report)
    assert st.get("ready") and st.get("seg") is True, st
    tex = canvas_pixels(browser, artifacts / "future_canvas_texture.png")
    click_mode(browser, "segmentation")
    seg = canvas_pixels(browser, artifacts / "future_canvas_segmentation.png")
    changed = (np.abs(tex - seg).sum(-1) > 40).mean()
    assert changed > 0.05, f"the toggle changed only {changed:.1%} of the pixels"
    # the road purple of the CityScapes palette (shaded) shows up only in segmentation mode
    def purple(px):
        r, g, b = px[..., 0], px[..., 1], px[..., 2]
        return float(((r > g + 30) & (b > g + 30) & (abs(r - b) < 60)).mean())
    assert purple(seg) > 0.05 and purple(seg) > 5 * purple(tex)
    click_mode(browser, "texture")
    back = canvas_pixels(browser)
    assert (np.abs(back - tex).sum(-1) > 40).mean() < 0.01  # same picture as before
    assert severe_logs(browser) == []
    full_page_screenshot(browser, artifacts / "future_report_full.png")
    if os.environ.get("TWINKIT_UPDATE_DOCS_SCREENSHOT"):
        docs_screenshot(browser, ROOT / "docs" / "img" / "report.png")


# --------------------------------------------------------------------------- a GLB with a real texture

def _png_bytes(img: np.ndarray) -> bytes:
    from PIL import Image

    b = io.BytesIO()
    Image.fromarray(img).save(b, format="PNG")
    return b.getvalue()


def textured_glb(path: Path, seg_attr: str = "_CLASS_COLOR") -> None:
    """A 20 m square with a black-and-white checker texture and red segmentation colours in ``seg_attr``:
    ``_CLASS_COLOR`` as twinkit's export step writes them, ``COLOR_0`` as it did before (still shown)."""
    pos = np.array([[-10, 0, -10], [10, 0, -10], [10, 0, 10], [-10, 0, 10]], "<f4")
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], "<f4")
    col = np.tile(np.array([[1.0, 0.0, 0.0, 1.0]], "<f4"), (4, 1))
    idx = np.array([0, 2, 1, 0, 3, 2], "<u2")
    check = (np.indices((64, 64)).sum(0) // 8 % 2 * 255).astype(np.uint8)
    png = _png_bytes(np.stack([check] * 3, -1))
    blobs, views = [], []
    off = 0
    for arr, target in ((pos.tobytes(), 34962), (uv.tobytes(), 34962), (col.tobytes(), 34962),
                        (idx.tobytes(), 34963), (png, None)):
        v = {"buffer": 0, "byteOffset": off, "byteLength": len(arr)}
        if target:
            v["target"] = target
        views.append(v)
        pad = (-len(arr)) % 4
        blobs.append(arr + b"\0" * pad)
        off += len(arr) + pad
    gltf = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1, seg_attr: 2}, "indices": 3,
                                    "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0},
                       "doubleSided": True}],
        "textures": [{"source": 0, "sampler": 0}], "samplers": [{"magFilter": 9728, "minFilter": 9728}],
        "images": [{"bufferView": 4, "mimeType": "image/png"}],
        "buffers": [{"byteLength": off}], "bufferViews": views,
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [-10, 0, -10], "max": [10, 0, 10]},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC4"},
            {"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"},
        ],
    }
    js = json.dumps(gltf).encode()
    js += b" " * ((-len(js)) % 4)
    binary = b"".join(blobs)
    with open(path, "wb") as f:
        f.write(struct.pack("<4sII", b"glTF", 2, 12 + 8 + len(js) + 8 + len(binary)))
        f.write(struct.pack("<I4s", len(js), b"JSON") + js + struct.pack("<I4s", len(binary), b"BIN\0") + binary)


@pytest.mark.parametrize("seg_attr", ["_CLASS_COLOR", "COLOR_0"])
def test_exported_glb_with_texture_and_segmentation_colours(browser, tmp_path, artifacts, seg_attr):
    ws = tmp_path / "ws"
    (ws / "01_export").mkdir(parents=True)
    textured_glb(ws / "01_export" / "twin.glb", seg_attr)
    run = tmp_path / "run"
    run.mkdir()
    manifest = {"status": "ok", "steps": [{"id": "export", "folder": "01_export", "status": "ran", "why": "test",
                                           "duration_s": 0.1, "plugin": "step/export_glb", "metrics": {}}],
                "workspace": str(ws)}
    page = R.write_report(run, manifest, None)
    assert page is not None and (page.parent / "viewer" / "model.glb.js").is_file()
    st = open_report(browser, page)
    assert st.get("ready") and st.get("seg") is True, st
    tex = canvas_pixels(browser, artifacts / f"glb_texture{seg_attr}.png")
    lum = tex.mean(-1)
    assert (lum < 40).mean() > 0.1 and (lum > 215).mean() > 0.1, "no checker texture"
    click_mode(browser, "segmentation")
    seg = canvas_pixels(browser, artifacts / f"glb_segmentation{seg_attr}.png")
    red = ((seg[..., 0] > 120) & (seg[..., 1] < 60) & (seg[..., 2] < 60)).mean()
    assert red > 0.2, f"only {red:.1%} red pixels in segmentation mode"
    assert severe_logs(browser) == []


def test_sweep_summary_page_loads(browser, demo_run, tmp_path, artifacts):
    from tests.report.test_report_page import _fake_sweep

    page = R.write_sweep_summary(_fake_sweep(demo_run, tmp_path))
    browser.get(page.resolve().as_uri())
    time.sleep(0.5)
    assert severe_logs(browser) == []
    n = browser.execute_script("return document.querySelectorAll('svg.plot circle').length")
    assert n >= 3
    browser.save_screenshot(str(artifacts / "sweep_summary.png"))


# --------------------------------------------------------------------------- screenshots

def full_page_screenshot(driver, path: Path) -> None:
    size = driver.get_window_size()
    h = driver.execute_script("return document.documentElement.scrollHeight")
    driver.set_window_size(size["width"], min(h + 120, 16000))
    time.sleep(0.8)
    driver.save_screenshot(str(path))
    driver.set_window_size(size["width"], size["height"])
    time.sleep(0.3)


def docs_screenshot(driver, path: Path) -> None:
    """The top of the report down to the end of the 3D view and the first pictures, 1000 px wide."""
    from PIL import Image

    size = driver.get_window_size()
    driver.set_window_size(1400, 2300)
    driver.execute_script("window.scrollTo(0, 0)")
    time.sleep(1.0)
    png = driver.get_screenshot_as_png()
    driver.set_window_size(size["width"], size["height"])
    im = Image.open(io.BytesIO(png)).convert("RGB")
    im = im.resize((1000, round(im.height * 1000 / im.width)), Image.LANCZOS)
    path.parent.mkdir(parents=True, exist_ok=True)
    im.save(path, optimize=True)

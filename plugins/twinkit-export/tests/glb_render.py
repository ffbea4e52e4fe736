"""Render a GLB as a standard viewer does: three.js's GLTFLoader with the materials it builds from the
file (KHR_materials_unlit -> MeshBasicMaterial, COLOR_0 -> vertexColors, as glTF prescribes), in headless
Chromium (WebGL through SwiftShader), top down, orthographic. Used by the GLB brightness test and by
``python glb_render.py twin.glb`` to measure an exported file.

``render(driver, glb, texture_only=False)`` returns the (h, w, 4) uint8 picture; with ``texture_only`` every
material is replaced by the bare texture (the reference: what the photo texture alone looks like).
"""
from __future__ import annotations

import base64
import io
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

PX = 768
FLAGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage", "--hide-scrollbars",
         "--window-size=900,900", "--force-device-scale-factor=1", "--use-angle=swiftshader",
         "--enable-unsafe-swiftshader"]

PAGE = """<!doctype html><html><body style="margin:0"><canvas id="c" width="%(px)d" height="%(px)d"></canvas>
<script src="three-bundle.js"></script><script src="model.js"></script><script>
(function () {
  var T = window.TWINKIT_THREE, THREE = T.THREE, c = document.getElementById('c');
  var r = new THREE.WebGLRenderer({canvas: c, preserveDrawingBuffer: true, alpha: true, antialias: false});
  r.setClearColor(0x000000, 0);
  var bin = atob(window.MODEL), u = new Uint8Array(bin.length);
  for (var i = 0; i < bin.length; i++) u[i] = bin.charCodeAt(i);
  new T.GLTFLoader().parse(u.buffer, '', function (g) {
    var info = {meshes: 0, vertexColors: 0, basic: 0};
    g.scene.traverse(function (o) {
      if (!o.isMesh) return;
      info.meshes += 1;
      if (o.material.vertexColors) info.vertexColors += 1;
      if (o.material.isMeshBasicMaterial) info.basic += 1;
      if (window.TEXTURE_ONLY) o.material = new THREE.MeshBasicMaterial({map: o.material.map});
    });
    var scene = new THREE.Scene();
    scene.add(g.scene);
    var b = new THREE.Box3().setFromObject(g.scene), ctr = b.getCenter(new THREE.Vector3());
    var h = Math.max(b.max.x - b.min.x, b.max.z - b.min.z) / 2 * 1.02;
    var cam = new THREE.OrthographicCamera(-h, h, h, -h, 0.1, (b.max.y - b.min.y) + 100);
    cam.position.set(ctr.x, b.max.y + 10, ctr.z);
    cam.up.set(0, 0, -1);  // glTF -z is north: north up
    cam.lookAt(ctr.x, b.min.y, ctr.z);
    r.render(scene, cam);
    info.png = c.toDataURL('image/png');
    window.DONE = info;
  }, function (e) { window.DONE = {error: String(e)}; });
})();
</script></body></html>
"""


def find_browser() -> tuple[str | None, str | None]:
    chrome = os.environ.get("TWINKIT_CHROMIUM") or next(
        (shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)), None)
    driver = os.environ.get("TWINKIT_CHROMEDRIVER") or shutil.which("chromedriver")
    return chrome, driver


def start_driver():
    """A headless Chromium driver, or a string saying why there is none."""
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        return "selenium is not installed"
    from twinkit.report.viewer import three_bundle

    if three_bundle() is None:
        return "three.js is not bundled (npm ci && npm run bundle, or scripts/setup.sh)"
    chrome, driver = find_browser()
    if not chrome or not driver:
        return "no Chromium / chromedriver (apt-get install chromium chromium-driver)"
    opts = webdriver.ChromeOptions()
    opts.binary_location = chrome
    profile = tempfile.mkdtemp(prefix="twinkit-glb-")
    for a in FLAGS + [f"--user-data-dir={profile}"]:
        opts.add_argument(a)
    try:
        d = webdriver.Chrome(service=Service(driver), options=opts)
    except Exception as exc:
        shutil.rmtree(profile, ignore_errors=True)
        return f"Chromium did not start ({type(exc).__name__})"
    d.set_page_load_timeout(120)
    d.twinkit_profile = profile
    return d


def stop_driver(d) -> None:
    """Quit the browser and remove its profile folder (a few MB per start, left in /tmp otherwise)."""
    d.quit()
    shutil.rmtree(getattr(d, "twinkit_profile", ""), ignore_errors=True)


def render(driver, glb: Path, workdir: Path, texture_only: bool = False, px: int = PX) -> tuple[np.ndarray, dict]:
    """(picture (px, px, 4) uint8, what the loader built: meshes, vertexColors, basic materials)."""
    from PIL import Image

    import shutil

    from twinkit.report.viewer import three_bundle

    workdir.mkdir(parents=True, exist_ok=True)
    bundle = workdir / "three-bundle.js"
    shipped = three_bundle()
    if not bundle.exists() and shipped is not None:
        shutil.copyfile(shipped, bundle)
    b64 = base64.b64encode(Path(glb).read_bytes()).decode("ascii")
    (workdir / "model.js").write_text(f"window.MODEL = {json.dumps(b64)}; window.TEXTURE_ONLY = "
                                      f"{'true' if texture_only else 'false'};\n", encoding="ascii")
    page = workdir / "page.html"
    page.write_text(PAGE % {"px": px}, encoding="utf-8")
    driver.get(page.resolve().as_uri())
    t0 = time.time()
    done = None
    while time.time() - t0 < 120:
        done = driver.execute_script("return window.DONE || null;")
        if done:
            break
        time.sleep(0.2)
    if not done or "error" in done:
        raise RuntimeError(f"{glb}: three.js did not render it ({done})")
    png = base64.b64decode(done.pop("png").split(",", 1)[1])
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGBA")), done


def brightness_ratio(driver, glb: Path, workdir: Path) -> dict:
    """Mean brightness of the GLB as loaded over the same pixels drawn with the bare texture."""
    img, info = render(driver, glb, workdir / "as_loaded")
    ref, _ = render(driver, glb, workdir / "texture_only", texture_only=True)
    cover = (img[..., 3] > 0) & (ref[..., 3] > 0)
    lum = img[..., :3].astype(float).mean(-1)[cover]
    lum_ref = ref[..., :3].astype(float).mean(-1)[cover]
    per_px = np.abs(img[..., :3].astype(float) - ref[..., :3].astype(float)).max(-1)[cover]
    return {"ratio": float(lum.mean() / max(lum_ref.mean(), 1e-9)), "mean": float(lum.mean()),
            "mean_texture": float(lum_ref.mean()), "covered_px": int(cover.sum()),
            "px_off_by_more_than_8": float((per_px > 8).mean()), **info, "images": (img, ref)}


if __name__ == "__main__":  # python glb_render.py a.glb [b.glb ...]: brightness of each against its texture
    from PIL import Image

    drv = start_driver()
    if isinstance(drv, str):
        sys.exit(drv)
    try:
        for arg in sys.argv[1:]:
            wd = Path(tempfile.mkdtemp(prefix="glb-render-"))
            r = brightness_ratio(drv, Path(arg), wd)
            img, ref = r.pop("images")
            Image.fromarray(img).save(wd / "as_loaded.png")
            Image.fromarray(ref).save(wd / "texture_only.png")
            print(json.dumps({"glb": arg, **r, "pictures": str(wd)}))
    finally:
        stop_driver(drv)

"""The 3D view: three.js as one classic script (pages opened from ``file://`` may not import ES modules),
bundled by esbuild at set-up and shipped in ``twinkit/report_assets``; the model as a script (one file,
kept once in the report cache by content); and the section that shows them."""
from __future__ import annotations

import hashlib
import logging
import os
import shutil
import time
from pathlib import Path

from twinkit.mesh import ply_vertex_count
from twinkit.mesh.glb import decimate, write_colored_glb
from twinkit.report.html import esc, link
from twinkit.report.page import ASSETS, palette, size
from twinkit.report.render import RENDER_VERSION, TopDown, labels_for, mesh_for_ortho
from twinkit.report.run import RunView, link_or_copy, rel, touch

log = logging.getLogger("twinkit.report")

VIEWER_FILE = "viewer.js"
VIEWER_MAX_FACES = 200_000  # the light GLB written when the run has none
MAX_GLB_BYTES = 64 * 2**20  # a bigger GLB is linked, and the page gets the light one instead


#: three.js, GLTFLoader and OrbitControls as one classic script defining ``window.TWINKIT_THREE``: built once
#: at set-up by esbuild (``npm run bundle``: scripts/bundle-three.mjs) and shipped with the package
THREE_BUNDLE = "three-bundle.js"
THREE_LICENSE = "three-LICENSE.txt"


def three_bundle() -> Path | None:
    """The shipped three.js bundle (``twinkit/report_assets/three-bundle.js``), or None when it was not built."""
    path = ASSETS / THREE_BUNDLE
    return path if path.is_file() else None


def vendor_three(dest: Path) -> bool:
    """Put the three.js bundle and its licence into ``dest`` (linked, else copied). False (and one
    warning) when the bundle was not built."""
    bundle = three_bundle()
    if bundle is None:
        log.warning("twinkit: report without its 3D view: three.js is not bundled "
                    "(run 'npm ci && npm run bundle' in the twinkit repository, or scripts/setup.sh)")
        return False
    dest.mkdir(parents=True, exist_ok=True)
    link_or_copy(bundle, dest / THREE_BUNDLE)
    if (ASSETS / THREE_LICENSE).is_file():
        shutil.copyfile(ASSETS / THREE_LICENSE, dest / THREE_LICENSE)
    return True


GLB_JS_HEAD, GLB_JS_TAIL = b'window.TWINKIT_GLB = "', b'";\n'


def write_glb_js(glb: Path, js: Path) -> None:
    """The GLB as a classic script (``window.TWINKIT_GLB``, base64): pages opened from file:// may not
    fetch() their neighbours (Chromium refuses), but they may load scripts."""
    import base64

    b64 = base64.b64encode(glb.read_bytes())
    tmp = js.with_name(js.name + f".{os.getpid()}.tmp")
    tmp.write_bytes(GLB_JS_HEAD + b64 + GLB_JS_TAIL)
    tmp.replace(js)


def read_glb_js(js: Path) -> bytes:
    """The GLB a model script (:func:`write_glb_js`) carries."""
    import base64

    data = js.read_bytes()
    if not (data.startswith(GLB_JS_HEAD) and data.endswith(GLB_JS_TAIL)):
        raise ValueError(f"{js}: not a model script")
    return base64.b64decode(data[len(GLB_JS_HEAD):-len(GLB_JS_TAIL)])


def glb_js_size(js: Path) -> int:
    """Bytes of the GLB a model script carries, without decoding it."""
    n = js.stat().st_size - len(GLB_JS_HEAD) - len(GLB_JS_TAIL)
    with open(js, "rb") as f:
        f.seek(max(0, js.stat().st_size - len(GLB_JS_TAIL) - 2))
        pad = f.read(2).count(b"=")
    return n // 4 * 3 - pad


def _key(*parts: object) -> str:
    return hashlib.sha256("|".join(str(p) for p in parts).encode()).hexdigest()[:20]


def model_script(run: RunView, pics: TopDown) -> tuple[Path | None, str, str]:
    """The 3D view's model as a script in the report cache, keyed by content, so that runs that show the
    same model share one file (hard-linked into each report): (script or None, where it comes from, note).

    The model is the latest ``*.glb`` of the run, else a light GLB written from the pictured mesh."""
    cache = run.cache_dir
    cache.mkdir(parents=True, exist_ok=True)
    glbs = [(s, f) for s, f in run.find("*.glb") if not f.name.startswith("gt_")]
    note = ""
    if glbs and glbs[0][1].stat().st_size > MAX_GLB_BYTES:
        s, f = glbs[0]
        note = (f" {esc(s.get('folder'))}/{esc(f.name)} ({size(f.stat().st_size)}) is too heavy for the page; "
                f"{link(rel(f, pics.out), 'download it')}.")
        glbs = []
    if glbs:
        s, f = glbs[0]
        js = cache / f"model-{_key(RENDER_VERSION, 'run-glb', run.key_of(s, f))}.glb.js"
        if not js.is_file():
            write_glb_js(f, js)
        touch(js)
        return js, f"{s.get('folder')}/{f.name}", note
    hit = mesh_for_ortho(run)
    if hit is None:
        return None, "", note
    s, f = hit
    lab = labels_for(run, ply_vertex_count(f), f)
    js = cache / f"view-{_key(RENDER_VERSION, 'glb', VIEWER_MAX_FACES, run.key_of(s, f), lab[1] if lab else '')}.glb.js"
    if not js.is_file():
        t = time.perf_counter()
        mesh = pics._mesh()
        if mesh is None or mesh.faces is None or not len(mesh.faces):
            return None, "", note
        labels = lab[0] if lab else mesh.attrs.get("label")
        xyz, faces, near = decimate(mesh.vertices, mesh.faces, VIEWER_MAX_FACES)
        cols = mesh.colors[near] if mesh.colors is not None else None
        seg = palette()[labels[near]] if labels is not None else None
        glb = cache / f".{js.stem}.{os.getpid()}.glb"
        try:
            write_colored_glb(glb, xyz, faces, cols, seg)
            write_glb_js(glb, js)
        finally:
            glb.unlink(missing_ok=True)
        pics.timings["glb_s"] = round(time.perf_counter() - t, 3)
    touch(js)
    return js, f"{s.get('folder')}/{f.name} (decimated to at most {VIEWER_MAX_FACES:,} faces for the page)", note


def sec_viewer(run: RunView, out: Path, pics: TopDown) -> str:
    """The 3D view: the model as one script (``viewer/model.glb.js``, a hard link into the report cache;
    the page offers it for download as ``model.glb``), three.js and the viewer."""
    js, source, note = model_script(run, pics)
    if js is None:
        return f"<p>{note}</p>" if note else ""
    vdir = out / "viewer"
    if not vendor_three(vdir):
        return ("<p class=\"warn\">The 3D view needs three.js, which is not bundled: run <code>npm ci &amp;&amp; "
                "npm run bundle</code> (or scripts/setup.sh) in the twinkit repository and run again.</p>")
    link_or_copy(js, vdir / "model.glb.js")
    shutil.copyfile(ASSETS / VIEWER_FILE, vdir / VIEWER_FILE)
    return (
        "<div id=\"viewer\" class=\"viewer\"><canvas id=\"viewer-canvas\"></canvas>"
        "<div class=\"viewer-ui\">"
        "<label><input type=\"radio\" name=\"colours\" id=\"mode-texture\" value=\"texture\" checked> texture</label>"
        "<label><input type=\"radio\" name=\"colours\" id=\"mode-segmentation\" value=\"segmentation\"> segmentation"
        "</label><button id=\"view-reset\" type=\"button\">reset view</button>"
        "<span id=\"viewer-status\">loading…</span></div></div>"
        f"<p class=\"dim\">From {esc(source)}: <a id=\"viewer-download\" download=\"model.glb\">model.glb</a> "
        f"({size(glb_js_size(js))}).{note} Drag to orbit, right-drag to pan, wheel to zoom.</p>"
        "<script src=\"viewer/three-bundle.js\"></script><script src=\"viewer/model.glb.js\"></script>"
        "<script src=\"viewer/viewer.js\"></script>"
    )

"""The 3D view: three.js as one classic script (pages opened from ``file://`` may not import ES modules),
bundled by esbuild at set-up and shipped in ``twinkit/report_assets``; the model as a script; and the
section that shows them."""
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
from twinkit.report.run import RunView, copy_into, link_or_copy, rel, touch

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


def write_glb_js(glb: Path, js: Path) -> None:
    """The GLB as a classic script (``window.TWINKIT_GLB``, base64): pages opened from file:// may not
    fetch() their neighbours, but they may load scripts."""
    import base64

    b64 = base64.b64encode(glb.read_bytes()).decode("ascii")
    tmp = js.with_name(js.name + f".{os.getpid()}.tmp")
    tmp.write_text(f'window.TWINKIT_GLB = "{b64}";\n', encoding="ascii")
    tmp.replace(js)



def sec_viewer(run: RunView, out: Path, pics: TopDown) -> str:
    """The 3D view: the latest ``*.glb`` of the run, else a light GLB written from the pictured mesh."""
    vdir = out / "viewer"
    glbs = [(s, f) for s, f in run.find("*.glb") if not f.name.startswith("gt_")]
    source = None
    cache = run.cache_dir
    note = ""
    if glbs and glbs[0][1].stat().st_size > MAX_GLB_BYTES:
        s, f = glbs[0]
        note = (f" {esc(s.get('folder'))}/{esc(f.name)} ({size(f.stat().st_size)}) is too heavy for the page; "
                f"{link(rel(f, out), 'download it')}.")
        glbs = []
    if glbs:
        s, f = glbs[0]
        copy_into(f, vdir / "model.glb")
        source = f"{s.get('folder')}/{f.name}"
    else:
        hit = mesh_for_ortho(run)
        if hit is None:
            return f"<p>{note}</p>" if note else ""
        s, f = hit
        nverts = ply_vertex_count(f)
        lab = labels_for(run, nverts, f)
        tag = hashlib.sha256(f"{RENDER_VERSION}|glb|{VIEWER_MAX_FACES}|{run.key_of(s, f)}|"
                             f"{lab[1] if lab else ''}".encode()).hexdigest()[:20]
        cached = cache / f"view-{tag}.glb"
        if not cached.is_file():
            t = time.perf_counter()
            mesh = pics._mesh()
            if mesh is None or mesh.faces is None or not len(mesh.faces):
                return ""
            labels = lab[0] if lab else mesh.attrs.get("label")
            xyz, faces, near = decimate(mesh.vertices, mesh.faces, VIEWER_MAX_FACES)
            cols = mesh.colors[near] if mesh.colors is not None else None
            seg = palette()[labels[near]] if labels is not None else None
            write_colored_glb(cached, xyz, faces, cols, seg)
            pics.timings["glb_s"] = round(time.perf_counter() - t, 3)
        else:
            touch(cached)
        link_or_copy(cached, vdir / "model.glb")
        source = f"{s.get('folder')}/{f.name} (decimated to at most {VIEWER_MAX_FACES:,} faces for the page)"
    if not vendor_three(vdir):
        return ("<p class=\"warn\">The 3D view needs three.js, which is not bundled: run <code>npm ci &amp;&amp; "
                "npm run bundle</code> (or scripts/setup.sh) in the twinkit repository and run again. "
                f"The model is here: {link('viewer/model.glb')}</p>")
    glb_stat = (vdir / "model.glb").stat()
    cache.mkdir(parents=True, exist_ok=True)
    js_cached = cache / f"model-{glb_stat.st_ino}-{glb_stat.st_size}-{glb_stat.st_mtime_ns}.glb.js"
    if not js_cached.is_file():
        write_glb_js(vdir / "model.glb", js_cached)
    else:
        touch(js_cached)
    link_or_copy(js_cached, vdir / "model.glb.js")
    shutil.copyfile(ASSETS / VIEWER_FILE, vdir / VIEWER_FILE)
    return (
        "<div id=\"viewer\" class=\"viewer\"><canvas id=\"viewer-canvas\"></canvas>"
        "<div class=\"viewer-ui\">"
        "<label><input type=\"radio\" name=\"colours\" id=\"mode-texture\" value=\"texture\" checked> texture</label>"
        "<label><input type=\"radio\" name=\"colours\" id=\"mode-segmentation\" value=\"segmentation\"> segmentation"
        "</label><button id=\"view-reset\" type=\"button\">reset view</button>"
        "<span id=\"viewer-status\">loading…</span></div></div>"
        f"<p class=\"dim\">From {esc(source)}: {link('viewer/model.glb', 'model.glb')} "
        f"({size((vdir / 'model.glb').stat().st_size)}).{note} Drag to orbit, right-drag to pan, wheel to zoom.</p>"
        "<script src=\"viewer/three-bundle.js\"></script><script src=\"viewer/model.glb.js\"></script>"
        "<script src=\"viewer/viewer.js\"></script>"
    )

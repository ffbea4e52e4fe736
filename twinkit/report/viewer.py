"""The 3D view: three.js bundled into one classic script (pages opened from ``file://`` may not import
ES modules), the model as a script, and the section that shows them."""
from __future__ import annotations

import hashlib
import json
import logging
import os
import posixpath
import re
import shutil
import time
from pathlib import Path

from twinkit.mesh import ply_vertex_count
from twinkit.mesh.glb import decimate, write_colored_glb
from twinkit.report.page import ASSETS, esc, palette, size
from twinkit.report.render import RENDER_VERSION, TopDown, labels_for, mesh_for_ortho
from twinkit.report.run import RunView, copy_into, link_or_copy, read_json, rel, touch

log = logging.getLogger("twinkit.report")

VIEWER_FILE = "viewer.js"
VIEWER_MAX_FACES = 200_000  # the light GLB written when the run has none
MAX_GLB_BYTES = 64 * 2**20  # a bigger GLB is linked, and the page gets the light one instead


def find_node_modules(start: Path | None = None) -> Path | None:
    """``node_modules`` with three.js: $TWINKIT_NODE_MODULES, else the repository root's."""
    env = os.environ.get("TWINKIT_NODE_MODULES")
    cands = [Path(env)] if env else []
    cands.append(Path(__file__).resolve().parents[2] / "node_modules")
    if start is not None:
        cands.append(Path(start) / "node_modules")
    for c in cands:
        if (c / "three" / "build" / "three.module.js").is_file():
            return c
    return None


_IMPORT_NAMED = re.compile(r"^import\s*\{([^}]*)\}\s*from\s*(['\"])([^'\"]+)\2\s*;?", re.M)
_IMPORT_NS = re.compile(r"^import\s*\*\s*as\s+([\w$]+)\s+from\s*(['\"])([^'\"]+)\2\s*;?", re.M)
_IMPORT_DEFAULT = re.compile(r"^import\s+([\w$]+)\s+from\s*(['\"])([^'\"]+)\2\s*;?", re.M)
_IMPORT_BARE = re.compile(r"^import\s*(['\"])([^'\"]+)\1\s*;?", re.M)
_EXPORT_FROM = re.compile(r"^export\s*\{([^}]*)\}\s*from\s*(['\"])([^'\"]+)\2\s*;?", re.M)
_EXPORT_STAR = re.compile(r"^export\s*\*\s*from\s*(['\"])([^'\"]+)\1\s*;?", re.M)
_EXPORT_LIST = re.compile(r"^export\s*\{([^}]*)\}\s*;?", re.M)
_EXPORT_DECL = re.compile(r"^export\s+(?:default\s+)?((?:async\s+)?function\*?|class|const|let|var)\s+([\w$]+)", re.M)
_EXPORT_DEFAULT = re.compile(r"^export\s+default\s+", re.M)
BUNDLE_ENTRIES = {
    "THREE": ("three", None),
    "GLTFLoader": ("examples/jsm/loaders/GLTFLoader.js", "GLTFLoader"),
    "OrbitControls": ("examples/jsm/controls/OrbitControls.js", "OrbitControls"),
}


def _specs(names: str) -> list[tuple[str, str]]:
    out = []
    for part in names.split(","):
        part = " ".join(part.split())
        if not part:
            continue
        a, _, b = part.partition(" as ")
        out.append((a.strip(), (b or a).strip()))
    return out


def _resolve(spec: str, importer: str) -> str:
    if spec == "three":
        return "build/three.module.js"
    if spec.startswith("three/"):
        sub = spec[len("three/"):]
        return sub.replace("addons/", "examples/jsm/", 1) if sub.startswith("addons/") else sub
    if spec.startswith("."):
        return posixpath.normpath(posixpath.join(posixpath.dirname(importer), spec))
    raise ValueError(f"cannot resolve import {spec!r} in {importer}")


def _to_classic(src: str, mid: str) -> tuple[str, list[str]]:
    """One ES module's text -> the body of ``function(__exp, __req)``; returns it and its dependencies."""
    deps: list[str] = []
    tail: list[str] = []

    def dep(spec: str) -> str:
        d = _resolve(spec, mid)
        deps.append(d)
        return json.dumps(d)

    def named(m):
        binds = ", ".join(a if a == b else f"{a}: {b}" for a, b in _specs(m.group(1)))
        return f"const {{ {binds} }} = __req({dep(m.group(3))});"

    src = _IMPORT_NAMED.sub(named, src)
    src = _IMPORT_NS.sub(lambda m: f"const {m.group(1)} = __req({dep(m.group(3))});", src)
    src = _IMPORT_DEFAULT.sub(lambda m: f"const {m.group(1)} = __req({dep(m.group(3))}).default;", src)
    src = _IMPORT_BARE.sub(lambda m: f"__req({dep(m.group(2))});", src)

    def export_from(m):
        d = dep(m.group(3))
        sets = " ".join(f"__exp[{json.dumps(b)}] = __m[{json.dumps(a)}];" for a, b in _specs(m.group(1)))
        return f"{{ const __m = __req({d}); {sets} }}"

    src = _EXPORT_FROM.sub(export_from, src)
    src = _EXPORT_STAR.sub(lambda m: f"Object.assign(__exp, __req({dep(m.group(2))}));", src)

    def export_list(m):
        tail.extend(f"__exp[{json.dumps(b)}] = {a};" for a, b in _specs(m.group(1)))
        return ""

    src = _EXPORT_LIST.sub(export_list, src)

    def export_decl(m):
        is_default = m.group(0).split()[1] == "default"
        tail.append(f"__exp[{json.dumps('default' if is_default else m.group(2))}] = {m.group(2)};")
        return f"{m.group(1)} {m.group(2)}"

    src = _EXPORT_DECL.sub(export_decl, src)
    src = _EXPORT_DEFAULT.sub("__exp.default = ", src)
    left = re.findall(r"^\s*(?:import\s*[{*'\"\w]|export\s)", src, re.M)
    if left or "import.meta" in src or re.search(r"\bimport\s*\(", src):
        raise ValueError(f"{mid}: module syntax this rewriter does not handle")
    return src + "\n" + "\n".join(tail) + "\n", deps


def bundle_three(node_modules: Path) -> str:
    """three.js (core, GLTFLoader, OrbitControls) as one classic script that defines
    ``window.TWINKIT_THREE``. Browsers refuse ES-module imports from ``file://`` pages, so the
    modules are wrapped in functions (a tiny linker: imports become lookups, exports assignments)."""
    root = node_modules / "three"
    version = (read_json(root / "package.json") or {}).get("version", "?")
    mods: dict[str, str] = {}
    todo = [_resolve(spec, "") if spec == "three" else spec for spec, _ in BUNDLE_ENTRIES.values()]
    while todo:
        mid = todo.pop()
        if mid in mods:
            continue
        body, deps = _to_classic((root / mid).read_text(encoding="utf-8"), mid)
        mods[mid] = body
        todo.extend(deps)
    parts = [
        f"/* three.js {version} (MIT License, Copyright 2010-2026 Three.js Authors; see three-LICENSE.txt),\n"
        f"   from the npm package 'three', wrapped by twinkit.report into one classic script so that the\n"
        f"   report works from file:// (browsers refuse ES-module imports there). */\n",
        "(function () {\n'use strict';\nconst __defs = {}, __done = {};\n",
        "function __req(id) { if (!(id in __done)) { __done[id] = {}; __defs[id](__done[id], __req); }"
        " return __done[id]; }\n",
    ]
    for mid, body in mods.items():
        parts.append(f"__defs[{json.dumps(mid)}] = function (__exp, __req) {{\n{body}}};\n")
    entries = ", ".join(
        f"{name}: __req({json.dumps(_resolve(spec, '') if spec == 'three' else spec)})"
        + (f"[{json.dumps(attr)}]" if attr else "")
        for name, (spec, attr) in BUNDLE_ENTRIES.items()
    )
    parts.append(f"window.TWINKIT_THREE = {{ {entries}, version: {json.dumps(version)} }};\n}})();\n")
    return "".join(parts)


def vendor_three(dest: Path, cache: Path | None = None) -> bool:
    """Write ``dest/three-bundle.js`` (+ licence). False (and one warning) when node_modules is missing."""
    nm = find_node_modules()
    if nm is None:
        log.warning("twinkit: report without its 3D view: three.js is not installed "
                    "(run 'npm ci' in the twinkit repository, or set TWINKIT_NODE_MODULES)")
        return False
    pkg = nm / "three" / "package.json"
    key = hashlib.sha256((RENDER_VERSION + str(pkg.stat().st_mtime_ns) + pkg.read_text()).encode()
                         + Path(__file__).read_bytes()).hexdigest()[:16]
    dest.mkdir(parents=True, exist_ok=True)
    cached = (cache / f"three-bundle-{key}.js") if cache else None
    if cached is not None and cached.is_file():
        touch(cached)
        link_or_copy(cached, dest / "three-bundle.js")
    else:
        text = bundle_three(nm)
        out = cached or dest / "three-bundle.js"
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(out.name + f".{os.getpid()}.tmp")
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(out)
        if cached is not None:
            link_or_copy(cached, dest / "three-bundle.js")
    lic = nm / "three" / "LICENSE"
    if lic.is_file():
        shutil.copyfile(lic, dest / "three-LICENSE.txt")
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
                f"<a href=\"{rel(f, out)}\">download it</a>.")
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
    if not vendor_three(vdir, cache):
        return ("<p class=\"warn\">The 3D view needs three.js, which is not installed: run <code>npm ci</code> "
                "in the twinkit repository and run again. "
                "The model is here: <a href=\"viewer/model.glb\">viewer/model.glb</a></p>")
    glb_stat = (vdir / "model.glb").stat()
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
        f"<p class=\"dim\">From {esc(source)}: <a href=\"viewer/model.glb\">model.glb</a> "
        f"({size((vdir / 'model.glb').stat().st_size)}).{note} Drag to orbit, right-drag to pan, wheel to zoom.</p>"
        "<script src=\"viewer/three-bundle.js\"></script><script src=\"viewer/model.glb.js\"></script>"
        "<script src=\"viewer/viewer.js\"></script>"
    )

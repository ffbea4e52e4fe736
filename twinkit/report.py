"""The run report: ``<run folder>/report/report.html``, readable offline from ``file://``.

``write_report(run_dir, manifest, engine)`` is called by the command after every successful run; it reads
the manifest and the numbered step folders of ``engine.workspace`` and shows whatever exists (each section
appears once the stage that feeds it has produced its files). It never fails the run: any problem is
logged as one warning and the report is written without the part concerned (or not at all).

``write_sweep_summary(sweep_dir)`` gathers the ``job*/manifest.json`` of a multirun sweep into one page
(swept overrides against metrics, and a plot of each metric against each numeric swept parameter);
``SweepSummaryCallback`` calls it at the end of a multirun (a Hydra callback).

Heavy pictures (top-down orthophotos, the light GLB of the 3D view) are cached by the content of their
inputs in ``<site>/.cache/report/`` and hard-linked into each report, so a run that changed nothing pays
nothing for them. See docs/report.md.
"""
from __future__ import annotations

import datetime as _dt
import hashlib
import html
import json
import logging
import math
import os
import posixpath
import re
import shutil
import struct
import time
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from twinkit import cityscapes

log = logging.getLogger("twinkit.report")

REPORT_DIR = "report"
ASSETS = Path(__file__).with_name("report_assets")
#: bump when a cached picture or model would come out differently for the same inputs.
RENDER_VERSION = "3"
ORTHO_PX = 2048            # long side of the orthophotos
VIEWER_MAX_FACES = 200_000  # the light GLB written when the run has none
CONTACT_ROWS = 6
MAX_GLB_BYTES = 64 * 2**20  # a bigger GLB is linked, and the page gets the light one instead
MAX_FILES_LISTED = 200      # per step folder; the folder itself is linked too

#: CityScapes trainIds 0..18: names and colours (the official palette, from twinkit.cityscapes).
CITYSCAPES = [(name, tuple(int(v) for v in cityscapes.PALETTE[i])) for i, name in enumerate(cityscapes.NAMES)]
IGNORE_COLOR = cityscapes.IGNORE_RGB


def palette() -> np.ndarray:
    """256 x 3 uint8: CityScapes colours for trainIds 0..18, black for everything else (255 = ignore)."""
    return cityscapes.lut()


# =========================================================================== small helpers

def _esc(x: Any) -> str:
    return html.escape(str(x), quote=True)


def _fmt(v: Any) -> str:
    if isinstance(v, bool) or v is None:
        return str(v)
    if isinstance(v, int):
        return f"{v:,}".replace(",", "\u2009")
    if isinstance(v, float):
        if v != v:
            return "nan"
        a = abs(v)
        if a == 0:
            return "0"
        if a >= 1e5 or a < 1e-3:
            return f"{v:.3g}"
        if a >= 100:
            return f"{v:.1f}"
        return f"{v:.4g}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return str(v)


def _size(n: int) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if n < 1024 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return str(n)


def _read_json(p: Path, limit: int = 4_000_000) -> Any:
    try:
        if p.stat().st_size > limit:
            return None
        return json.loads(p.read_text())
    except (OSError, ValueError):
        return None


def _flatten(d: Any, prefix: str = "") -> dict[str, Any]:
    """Nested dicts -> {"a.b.c": scalar}; lists of scalars stay as values."""
    out: dict[str, Any] = {}
    if isinstance(d, dict):
        for k, v in d.items():
            key = f"{prefix}.{k}" if prefix else str(k)
            if isinstance(v, dict):
                out.update(_flatten(v, key))
            else:
                out[key] = v
    return out


def _link_or_copy(src: Path, dst: Path) -> None:
    dst.parent.mkdir(parents=True, exist_ok=True)
    if dst.exists() or dst.is_symlink():
        dst.unlink()
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def _write_text(path: Path, text: str) -> None:
    """Atomic (parallel multirun jobs share the cache)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)


CACHE_KEEP_DAYS = 30


def _touch(p: Path) -> None:
    try:
        os.utime(p)
    except OSError:
        pass


def prune_cache(cache: Path, keep_days: float = CACHE_KEEP_DAYS) -> int:
    """Delete cached pictures and models not used for ``keep_days`` (reports keep their hard links)."""
    if not cache.is_dir():
        return 0
    limit = time.time() - keep_days * 86400
    n = 0
    for p in cache.iterdir():
        try:
            if p.is_file() and p.stat().st_mtime < limit:
                p.unlink()
                n += 1
        except OSError:
            pass
    return n


def _rel(target: Path, start: Path) -> str:
    """A relative URL from folder ``start`` to ``target`` (quoted for HTML attributes)."""
    try:
        r = os.path.relpath(target, start)
    except ValueError:
        return Path(target).resolve().as_uri()
    from urllib.parse import quote

    return quote(r.replace(os.sep, "/"))


def _file_key(p: Path, known: dict[str, str] | None = None) -> str:
    """The content hash recorded by the step (step.json), else a (size, mtime, inode) stamp."""
    if known and p.name in known:
        return known[p.name]
    st = p.stat()
    return f"{st.st_size}-{st.st_mtime_ns}-{st.st_ino}"


# =========================================================================== the run folder, as read

class RunView:
    """What a run produced: its steps (manifest + step.json) and the files in their numbered folders."""

    def __init__(self, run_dir: Path, manifest: dict, engine=None):
        self.run_dir = Path(run_dir)
        self.manifest = manifest or {}
        ws = getattr(engine, "workspace", None) or self.manifest.get("workspace") or self.run_dir
        self.workspace = Path(ws)
        site_root = getattr(engine, "site_root", None)
        self.site_root = Path(site_root) if site_root else self.workspace
        self.report_dir = self.run_dir / REPORT_DIR
        self.steps: list[dict] = []
        for i, s in enumerate(self.manifest.get("steps") or []):
            if not isinstance(s, dict):
                continue
            folder = self.workspace / str(s.get("folder") or f"{i + 1:02d}_{s.get('id', 'step')}")
            rec = _read_json(folder / "step.json") or {}
            files = []
            if folder.is_dir():
                files = sorted((p for p in folder.rglob("*") if p.is_file() and not p.name.startswith(".")),
                               key=lambda p: str(p.relative_to(folder)))
            hashes = {k: v.get("sha256") for k, v in (rec.get("files") or {}).items() if isinstance(v, dict)}
            self.steps.append({**s, "dir": folder, "record": rec, "files": files, "hashes": hashes})

    # ------------------------------------------------------------------ finding files
    def all_files(self) -> Iterable[tuple[dict, Path]]:
        for s in self.steps:
            for f in s["files"]:
                yield s, f

    def find(self, pattern: str, latest: bool = True) -> list[tuple[dict, Path]]:
        """Files whose name matches a glob (latest step first)."""
        import fnmatch

        hits = [(s, f) for s, f in self.all_files() if fnmatch.fnmatch(f.name.lower(), pattern.lower())]
        return list(reversed(hits)) if latest else hits

    def first(self, pattern: str) -> tuple[dict, Path] | None:
        hits = self.find(pattern)
        return hits[0] if hits else None

    def key_of(self, step: dict, p: Path) -> str:
        return _file_key(p, step.get("hashes"))

    @property
    def cache_dir(self) -> Path:
        return self.site_root / ".cache" / "report"


# =========================================================================== PLY meshes

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


class Mesh:
    def __init__(self, xyz: np.ndarray, faces: np.ndarray, colors: np.ndarray | None, labels: np.ndarray | None):
        self.xyz, self.faces, self.colors, self.labels = xyz, faces, colors, labels


def read_ply(path: Path) -> Mesh:
    """Vertices, triangles, vertex colours and a vertex ``label`` property of a PLY (fast path: binary with
    fixed-length face lists, read with numpy in one go; anything else through plyfile)."""
    with open(path, "rb") as f:
        head = b""
        while not head.endswith(b"end_header\n") and not head.endswith(b"end_header\r\n"):
            line = f.readline()
            if not line:
                raise ValueError(f"{path}: no PLY header")
            head += line
        body_at = f.tell()
    lines = head.decode("ascii", "replace").splitlines()
    fmt = next((ln.split()[1] for ln in lines if ln.startswith("format")), "")
    elements: list[list] = []
    for ln in lines:
        t = ln.split()
        if not t:
            continue
        if t[0] == "element":
            elements.append([t[1], int(t[2]), []])
        elif t[0] == "property" and elements:
            elements[-1][2].append(t[1:])
    if fmt not in ("binary_little_endian", "binary_big_endian"):
        return _read_ply_slow(path)
    end = "<" if fmt == "binary_little_endian" else ">"
    data = np.memmap(path, dtype=np.uint8, mode="r", offset=body_at)
    pos = 0
    out: dict[str, np.ndarray] = {}
    for name, count, props in elements:
        fields = []
        for p in props:
            if p[0] == "list":
                # peek at the first row's count to make the list fixed-length
                ctype, itype, pname = _PLY_TYPES[p[1]], _PLY_TYPES[p[2]], p[3]
                off = pos + sum(np.dtype(end + t).itemsize * (n or 1) for _, t, n in fields)
                if count == 0:
                    n = 3
                else:
                    n = int(np.frombuffer(data[off:off + np.dtype(ctype).itemsize], dtype=end + ctype)[0])
                fields.append((pname + "__n", ctype, 0))
                fields.append((pname, itype, n))
            else:
                fields.append((p[1], _PLY_TYPES[p[0]], 0))
        dt = np.dtype([(n, end + t) if not k else (n, end + t, (k,)) for n, t, k in fields])
        nbytes = dt.itemsize * count
        arr = np.frombuffer(data[pos:pos + nbytes], dtype=dt, count=count)
        for n, _, k in fields:
            if n.endswith("__n") and count and not np.all(arr[n] == arr[n][0]):
                return _read_ply_slow(path)  # variable-length lists
        out[name] = arr
        pos += nbytes
    v = out.get("vertex")
    if v is None:
        raise ValueError(f"{path}: no vertex element")
    xyz = np.column_stack([v["x"], v["y"], v["z"]]).astype(np.float64)
    faces = np.zeros((0, 3), np.int64)
    fe = out.get("face")
    if fe is not None and len(fe):
        key = "vertex_indices" if "vertex_indices" in fe.dtype.names else "vertex_index"
        idx = np.asarray(fe[key])
        if idx.ndim == 2 and idx.shape[1] == 3:
            faces = idx.astype(np.int64)
        elif idx.ndim == 2 and idx.shape[1] == 4:
            faces = np.concatenate([idx[:, [0, 1, 2]], idx[:, [0, 2, 3]]]).astype(np.int64)
    names = v.dtype.names
    colors = None
    if all(c in names for c in ("red", "green", "blue")):
        colors = np.column_stack([v["red"], v["green"], v["blue"]])
        if colors.dtype != np.uint8:
            colors = (np.clip(colors.astype(np.float64), 0, 1) * 255).astype(np.uint8) \
                if colors.dtype.kind == "f" else colors.astype(np.uint8)
    labels = np.asarray(v["label"]).astype(np.uint8) if "label" in names else None
    return Mesh(xyz, faces, colors, labels)


def _read_ply_slow(path: Path) -> Mesh:
    from plyfile import PlyData

    ply = PlyData.read(str(path))
    v = ply["vertex"]
    names = v.data.dtype.names
    xyz = np.column_stack([np.asarray(v[c], np.float64) for c in ("x", "y", "z")])
    colors = np.column_stack([np.asarray(v[c]) for c in ("red", "green", "blue")]).astype(np.uint8) \
        if all(c in names for c in ("red", "green", "blue")) else None
    labels = np.asarray(v["label"]).astype(np.uint8) if "label" in names else None
    faces = np.zeros((0, 3), np.int64)
    if "face" in ply:
        fn = ply["face"].data.dtype.names
        key = "vertex_indices" if "vertex_indices" in fn else "vertex_index"
        rows = [r for r in ply["face"].data[key] if len(r) >= 3]
        tris = []
        for r in rows:
            for k in range(1, len(r) - 1):
                tris.append((r[0], r[k], r[k + 1]))
        faces = np.asarray(tris, np.int64).reshape(-1, 3)
    return Mesh(xyz, faces, colors, labels)


# =========================================================================== top-down orthophotos

_GL: dict = {}

_VS = """
#version 330
uniform vec4 bounds;  // xmin ymin xmax ymax
uniform vec2 zr;      // zmin zmax
in vec3 in_pos;
in vec3 in_col;
out vec3 v_col;
flat out vec3 f_col;
void main() {
    vec2 xy = (in_pos.xy - bounds.xy) / (bounds.zw - bounds.xy) * 2.0 - 1.0;
    // highest surface nearest; kept inside (-1, 1) so the lowest one is not clipped by the far plane
    float z = 0.98 - 1.96 * (in_pos.z - zr.x) / max(zr.y - zr.x, 1e-6);
    gl_Position = vec4(xy, z, 1.0);
    v_col = in_col;
    f_col = in_col;
}
"""
_FS = """
#version 330
uniform int flat_shade;
in vec3 v_col;
flat in vec3 f_col;
out vec4 frag;
void main() { frag = vec4(flat_shade == 1 ? f_col : v_col, 1.0); }
"""


def _gl_context():
    if "ctx" not in _GL:
        import moderngl

        try:
            ctx = moderngl.create_standalone_context(backend="egl")
        except Exception:
            ctx = moderngl.create_standalone_context()
        _GL["ctx"] = ctx
        _GL["prog"] = ctx.program(vertex_shader=_VS, fragment_shader=_FS)
    return _GL["ctx"], _GL["prog"]


def ortho_frame(xyz: np.ndarray, px: int = ORTHO_PX, margin: float = 0.01) -> tuple[tuple[float, ...], int, int]:
    lo, hi = xyz[:, :2].min(0), xyz[:, :2].max(0)
    span = np.maximum(hi - lo, 1e-3)
    lo, hi = lo - span * margin, hi + span * margin
    span = hi - lo
    scale = px / span.max()
    w, h = max(1, int(round(span[0] * scale))), max(1, int(round(span[1] * scale)))
    return (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])), w, h


def render_topdown(xyz: np.ndarray, faces: np.ndarray, colors: np.ndarray, bounds, w: int, h: int,
                   flat: bool = False) -> np.ndarray:
    """An H x W x 4 uint8 top-down orthographic picture (north up; alpha 0 where there is no surface)."""
    try:
        return _render_gl(xyz, faces, colors, bounds, w, h, flat)
    except Exception as exc:  # no GL: splat vertices instead
        log.debug("report: GL rendering unavailable (%s); splatting points", exc)
        return _render_splat(xyz, faces, colors, bounds, w, h)


def _render_gl(xyz, faces, colors, bounds, w, h, flat):
    ctx, prog = _gl_context()
    zr = (float(xyz[:, 2].min()), float(xyz[:, 2].max()))
    # relative to the frame's corner keeps float32 precise for projected coordinates
    origin = np.array([bounds[0], bounds[1], 0.0])
    pos = (xyz - origin).astype("f4")
    prog["bounds"].value = (0.0, 0.0, bounds[2] - bounds[0], bounds[3] - bounds[1])
    prog["zr"].value = zr
    prog["flat_shade"].value = 1 if flat else 0
    col = (np.asarray(colors, np.float32) / 255.0).astype("f4")
    vbo = ctx.buffer(np.hstack([pos, col]).astype("f4").tobytes())
    ibo = ctx.buffer(np.ascontiguousarray(faces, dtype="u4").tobytes())
    vao = ctx.vertex_array(prog, [(vbo, "3f 3f", "in_pos", "in_col")], index_buffer=ibo)
    fbo = ctx.simple_framebuffer((w, h), components=4)
    fbo.use()
    ctx.enable(ctx.DEPTH_TEST)
    ctx.disable(ctx.CULL_FACE)
    fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
    vao.render()
    img = np.frombuffer(fbo.read(components=4, alignment=1), np.uint8).reshape(h, w, 4)[::-1].copy()
    for o in (vao, vbo, ibo, fbo):
        o.release()
    return img


def _render_splat(xyz, faces, colors, bounds, w, h):
    cols = np.asarray(colors, np.uint8)
    pts = xyz
    if len(faces):
        cen = xyz[faces].mean(1)
        pts = np.vstack([xyz, cen])
        cols = np.vstack([cols, cols[faces[:, 0]]])
    order = np.argsort(pts[:, 2])
    pts, cols = pts[order], cols[order]
    ix = ((pts[:, 0] - bounds[0]) / (bounds[2] - bounds[0]) * w).astype(int).clip(0, w - 1)
    iy = ((bounds[3] - pts[:, 1]) / (bounds[3] - bounds[1]) * h).astype(int).clip(0, h - 1)
    img = np.zeros((h, w, 4), np.uint8)
    img[iy, ix, :3] = cols
    img[iy, ix, 3] = 255
    return img


def _save_png(img: np.ndarray, path: Path) -> None:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.png")
    Image.fromarray(img).save(tmp, optimize=False, compress_level=3)
    tmp.replace(path)


# =========================================================================== vendored three.js

def find_node_modules(start: Path | None = None) -> Path | None:
    """``node_modules`` with three.js: $TWINKIT_NODE_MODULES, else the repository root's."""
    env = os.environ.get("TWINKIT_NODE_MODULES")
    cands = [Path(env)] if env else []
    cands.append(Path(__file__).resolve().parents[1] / "node_modules")
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
    version = (_read_json(root / "package.json") or {}).get("version", "?")
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
        _touch(cached)
        _link_or_copy(cached, dest / "three-bundle.js")
    else:
        text = bundle_three(nm)
        out = cached or dest / "three-bundle.js"
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(out.name + f".{os.getpid()}.tmp")
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(out)
        if cached is not None:
            _link_or_copy(cached, dest / "three-bundle.js")
    lic = nm / "three" / "LICENSE"
    if lic.is_file():
        shutil.copyfile(lic, dest / "three-LICENSE.txt")
    return True


# =========================================================================== GLB (3D view)

def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    c = np.asarray(c, np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def write_glb(path: Path, xyz: np.ndarray, faces: np.ndarray, colors: np.ndarray | None,
              seg_colors: np.ndarray | None) -> None:
    """A GLB of one triangle mesh in glTF's frame (y up: site x, z, -y).

    ``COLOR_0`` holds the segmentation colours when given (the convention of twinkit's exported GLBs),
    else the texture colours; with both, the texture colours go to the application attribute
    ``_TEXCOLOR``. Colours are stored linear (glTF), as normalised uint16 RGBA."""
    centre = (xyz.min(0) + xyz.max(0)) / 2
    centre[2] = xyz[:, 2].min()
    p = xyz - centre
    pos = np.column_stack([p[:, 0], p[:, 2], -p[:, 1]]).astype("<f4")
    attrs: list[tuple[str, np.ndarray, int, str, bool]] = [("POSITION", pos, 5126, "VEC3", False)]

    def col(c):
        lin = _srgb_to_linear(c[:, :3])
        rgba = np.ones((len(c), 4))
        rgba[:, :3] = lin
        return np.round(rgba * 65535).astype("<u2")

    if seg_colors is not None:
        attrs.append(("COLOR_0", col(seg_colors), 5123, "VEC4", True))
        if colors is not None:
            attrs.append(("_TEXCOLOR", col(colors), 5123, "VEC4", True))
    elif colors is not None:
        attrs.append(("COLOR_0", col(colors), 5123, "VEC4", True))
    idx = np.ascontiguousarray(faces, dtype="<u4").ravel()
    blobs, views, accessors = [], [], []
    offset = 0

    def add(arr: np.ndarray, target: int) -> int:
        nonlocal offset
        b = arr.tobytes()
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(b), "target": target})
        pad = (-len(b)) % 4
        blobs.append(b + b"\0" * pad)
        offset += len(b) + pad
        return len(views) - 1

    prim_attrs = {}
    for name, arr, ctype, atype, norm in attrs:
        acc = {"bufferView": add(arr, 34962), "componentType": ctype, "count": int(len(arr)), "type": atype}
        if norm:
            acc["normalized"] = True
        if name == "POSITION":
            acc["min"] = [float(x) for x in arr.min(0)]
            acc["max"] = [float(x) for x in arr.max(0)]
        accessors.append(acc)
        prim_attrs[name] = len(accessors) - 1
    accessors.append({"bufferView": add(idx, 34963), "componentType": 5125, "count": int(len(idx)),
                      "type": "SCALAR"})
    gltf = {
        "asset": {"version": "2.0", "generator": "twinkit.report"},
        "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "twin", "extras": {"site_origin_m": [float(x) for x in centre]}}],
        "meshes": [{"primitives": [{"attributes": prim_attrs, "indices": len(accessors) - 1, "material": 0}]}],
        "materials": [{"name": "twin", "doubleSided": True,
                       "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0.0,
                                                "roughnessFactor": 1.0}}],
        "buffers": [{"byteLength": offset}], "bufferViews": views, "accessors": accessors,
    }
    js = json.dumps(gltf, separators=(",", ":")).encode()
    js += b" " * ((-len(js)) % 4)
    binary = b"".join(blobs)
    total = 12 + 8 + len(js) + 8 + len(binary)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
    with open(tmp, "wb") as f:
        f.write(struct.pack("<4sII", b"glTF", 2, total))
        f.write(struct.pack("<I4s", len(js), b"JSON") + js)
        f.write(struct.pack("<I4s", len(binary), b"BIN\0") + binary)
    tmp.replace(path)


def decimate(xyz: np.ndarray, faces: np.ndarray, max_faces: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, faces, index of the nearest original vertex for each new vertex)."""
    if len(faces) <= max_faces:
        return xyz, faces, np.arange(len(xyz))
    try:
        import fast_simplification

        nv, nf = fast_simplification.simplify(xyz.astype(np.float32), faces.astype(np.int32),
                                              target_reduction=1 - max_faces / len(faces))
        nv = np.asarray(nv, np.float64)
        from scipy.spatial import cKDTree

        _, near = cKDTree(xyz).query(nv, k=1)
        return nv, np.asarray(nf, np.int64), near
    except ImportError:  # keep a random subset of faces
        rng = np.random.default_rng(0)
        keep = np.sort(rng.choice(len(faces), max_faces, replace=False))
        f = faces[keep]
        used, inv = np.unique(f, return_inverse=True)
        return xyz[used], inv.reshape(-1, 3), used


def write_glb_js(glb: Path, js: Path) -> None:
    """The GLB as a classic script (``window.TWINKIT_GLB``, base64): pages opened from file:// may not
    fetch() their neighbours, but they may load scripts."""
    import base64

    b64 = base64.b64encode(glb.read_bytes()).decode("ascii")
    tmp = js.with_name(js.name + f".{os.getpid()}.tmp")
    tmp.write_text(f'window.TWINKIT_GLB = "{b64}";\n', encoding="ascii")
    tmp.replace(js)


# =========================================================================== roads

def _sample_geometry(g: ET.Element, step: float = 0.5) -> list[tuple[float, float]]:
    x0, y0 = float(g.get("x", 0)), float(g.get("y", 0))
    hdg, length = float(g.get("hdg", 0)), float(g.get("length", 0))
    n = max(2, int(math.ceil(length / step)) + 1)
    kind = next(iter(g), None)
    tag = kind.tag if kind is not None else "line"
    ch, sh = math.cos(hdg), math.sin(hdg)
    if tag == "paramPoly3":
        c = {k: float(kind.get(k, 0)) for k in ("aU", "bU", "cU", "dU", "aV", "bV", "cV", "dV")}
        pmax = 1.0 if kind.get("pRange", "normalized") == "normalized" else length
        pts = []
        for p in np.linspace(0, pmax, n):
            u = c["aU"] + c["bU"] * p + c["cU"] * p * p + c["dU"] * p ** 3
            v = c["aV"] + c["bV"] * p + c["cV"] * p * p + c["dV"] * p ** 3
            pts.append((x0 + u * ch - v * sh, y0 + u * sh + v * ch))
        return pts
    if tag == "poly3":
        c = [float(kind.get(k, 0)) for k in ("a", "b", "c", "d")]
        return [(x0 + u * ch - (c[0] + c[1] * u + c[2] * u * u + c[3] * u ** 3) * sh,
                 y0 + u * sh + (c[0] + c[1] * u + c[2] * u * u + c[3] * u ** 3) * ch)
                for u in np.linspace(0, length, n)]
    k0 = k1 = 0.0
    if tag == "arc":
        k0 = k1 = float(kind.get("curvature", 0))
    elif tag == "spiral":
        k0, k1 = float(kind.get("curvStart", 0)), float(kind.get("curvEnd", 0))
    pts = [(x0, y0)]
    x, y, h = x0, y0, hdg
    ds = length / (n - 1)
    for i in range(n - 1):
        s_mid = (i + 0.5) * ds
        k = k0 + (k1 - k0) * s_mid / max(length, 1e-9)
        hm = h + k * ds / 2
        x, y = x + ds * math.cos(hm), y + ds * math.sin(hm)
        h += k * ds
        pts.append((x, y))
    return pts


def read_opendrive(path: Path) -> list[dict]:
    """Each road's reference line (sampled) and its paved width at s = 0 (sum of lane widths)."""
    root = ET.parse(path).getroot()
    off = root.find("header/offset")
    ox = float(off.get("x", 0)) if off is not None else 0.0
    oy = float(off.get("y", 0)) if off is not None else 0.0
    roads = []
    for road in root.iter("road"):
        pts: list[tuple[float, float]] = []
        for g in road.findall("planView/geometry"):
            seg = _sample_geometry(g)
            pts.extend(seg if not pts else seg[1:])
        widths = {"left": 0.0, "right": 0.0}
        ls = road.find("lanes/laneSection")
        if ls is not None:
            for side in widths:
                for lane in ls.findall(f"{side}/lane"):
                    w = lane.find("width")
                    if w is not None and lane.get("type", "driving") in _PAVED:
                        widths[side] += float(w.get("a", 0))
        lo = road.find("lanes/laneOffset")
        offset = float(lo.get("a", 0)) if lo is not None else 0.0
        roads.append({"id": road.get("id"), "junction": road.get("junction", "-1"),
                      "points": [(x + ox, y + oy) for x, y in pts], "width": widths["left"] + widths["right"],
                      "left": widths["left"], "right": widths["right"], "offset": offset})
    return roads


_PAVED = ("driving", "bidirectional", "parking", "shoulder", "biking", "entry", "exit", "onRamp", "offRamp")


def offset_polyline(pts: list[tuple[float, float]], d: float) -> list[tuple[float, float]]:
    """The polyline moved sideways by ``d`` metres (positive: to the left of its direction)."""
    a = np.asarray(pts, float)
    if len(a) < 2 or d == 0:
        return [tuple(p) for p in a]
    t = np.gradient(a, axis=0)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    n = np.column_stack([-t[:, 1], t[:, 0]])
    return [tuple(p) for p in a + n * d]


# =========================================================================== the page

CSS_FILE = "report.css"
VIEWER_FILE = "viewer.js"


class _Page:
    def __init__(self, out: Path):
        self.out = out
        self.sections: list[tuple[str, str, str]] = []  # id, title, html
        self.notes: list[str] = []

    def add(self, sid: str, title: str, body: str | None) -> None:
        if body:
            self.sections.append((sid, title, body))


def _table(headers: list[str], rows: list[list[Any]], cls: str = "") -> str:
    h = "".join(f"<th>{_esc(x)}</th>" for x in headers)
    body = []
    for r in rows:
        cells = []
        for x in r:
            if isinstance(x, tuple) and len(x) == 2 and x[0] == "html":
                cells.append(f"<td>{x[1]}</td>")
            else:
                num = isinstance(x, (int, float)) and not isinstance(x, bool)
                cells.append(f"<td class=\"num\">{_esc(_fmt(x))}</td>" if num else f"<td>{_esc(_fmt(x))}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table class=\"{cls}\"><thead><tr>{h}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def _figure(src: str, caption: str, extra: str = "") -> str:
    return (f"<figure><a href=\"{src}\"><img src=\"{src}\" alt=\"{_esc(caption)}\" loading=\"lazy\"></a>"
            f"<figcaption>{caption}{extra}</figcaption></figure>")


def _status_badge(status: str) -> str:
    return f"<span class=\"badge st-{_esc(status)}\">{_esc(status)}</span>"


# --------------------------------------------------------------------------- sections

def _sec_summary(run: RunView, out: Path) -> str:
    m = run.manifest
    cfg = m.get("config") or {}
    recipe = (cfg.get("recipe") or {}).get("name", "?")
    site = m.get("site") or {}
    git = m.get("git") or {}
    counts: dict[str, int] = {}
    for s in run.steps:
        counts[s.get("status", "?")] = counts.get(s.get("status", "?"), 0) + 1
    rows = [
        ["status", m.get("status", "?")], ["recipe", recipe], ["site", site.get("name", "?")],
        ["started", m.get("started", "?")], ["finished", m.get("finished", "?")],
        ["duration", f"{m.get('duration_s', 0):.1f} s"],
        ["steps", ", ".join(f"{v} {k}" for k, v in counts.items())],
        ["overrides", " ".join(m.get("overrides") or []) or "(none)"],
        ["git", f"{(git.get('commit') or '?')[:12]}{' (uncommitted changes)' if git.get('dirty') else ''}"],
        ["workspace", ("html", f"<a href=\"{_rel(run.workspace, out)}\">{_esc(run.workspace)}</a>")],
        ["manifest", ("html", f"<a href=\"{_rel(run.run_dir / 'manifest.json', out)}\">manifest.json</a> · "
                              f"<a href=\"{_rel(run.run_dir / 'run.log', out)}\">run.log</a>")],
    ]
    return _table(["", ""], rows, "kv")


def _sec_timeline(run: RunView) -> str:
    if not run.steps:
        return ""
    total = sum(float(s.get("duration_s") or 0) for s in run.steps) or 1.0
    rows = []
    for i, s in enumerate(run.steps, 1):
        d = float(s.get("duration_s") or 0)
        bar = (f"<div class=\"bar st-{_esc(s.get('status'))}\" style=\"width:{max(0.5, 100 * d / total):.1f}%\""
               f" title=\"{d:.1f} s\"></div>")
        rows.append("<tr>" + "".join([
            f"<td class=\"num\">{i}</td>",
            f"<td><a href=\"#step-{_esc(s.get('folder'))}\">{_esc(s.get('folder'))}</a></td>",
            f"<td>{_esc(s.get('plugin', ''))}</td>",
            f"<td>{_status_badge(str(s.get('status', '?')))}</td>",
            f"<td>{_esc(s.get('why', ''))}</td>",
            f"<td class=\"num\">{d:.1f} s</td>",
            f"<td class=\"num\">{_esc(_fmt(s.get('peak_rss_mb')) if s.get('peak_rss_mb') else '')}</td>",
            f"<td class=\"barcell\">{bar}</td>",
        ]) + "</tr>")
    head = "".join(f"<th>{h}</th>" for h in ("#", "folder", "plugin", "status", "why", "time", "peak MB", ""))
    legend = ("<p class=\"legend\">ran: computed now · cached: linked from an earlier result · reused: "
              "unchanged in place · edited: a hand edit was kept · manual: a file you provided</p>")
    return f"<table class=\"timeline\"><thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>{legend}"


def _sec_provenance(run: RunView, out: Path) -> str:
    m = run.manifest
    site = m.get("site") or {}
    py = m.get("python") or {}
    parts = []
    rows = [["CRS", site.get("crs", "")], ["base point", json.dumps(site.get("base_point", ""))],
            ["command", " ".join(m.get("argv") or [])], ["python", f"{py.get('version', '?')} on {py.get('platform', '?')}"],
            ["schema", m.get("schema_version", "?")]]
    parts.append(_table(["", ""], rows, "kv"))
    plugins = m.get("plugins") or []
    if plugins:
        parts.append("<h3>Plugins</h3>" + _table(["kind", "name", "version", "distribution"],
                                                  [[p.get("kind"), p.get("name"), p.get("version"),
                                                    p.get("distribution")] for p in plugins]))
    libs = m.get("libraries") or {}
    if libs:
        parts.append("<h3>Libraries</h3><p class=\"libs\">" +
                     " · ".join(f"{_esc(k)} {_esc(v)}" for k, v in sorted(libs.items())) + "</p>")
    inputs = m.get("inputs") or []
    if inputs:
        parts.append("<h3>Inputs</h3>" + _table(["file", "size", "sha256"], [
            [("html", _file_link(Path(e["path"]), out)), _size(int(e.get("size", 0))), (e.get("sha256") or "")[:16]]
            for e in inputs]))
    cfg = m.get("config")
    if cfg:
        parts.append("<details><summary>Composed configuration</summary><pre>" +
                     _esc(json.dumps(cfg, indent=2, sort_keys=True, default=str)) + "</pre></details>")
    return "".join(parts)


def _file_link(p: Path, out: Path) -> str:
    return f"<a href=\"{_rel(p, out)}\">{_esc(p.name)}</a>"


def _sec_files(run: RunView, out: Path) -> str:
    blocks = []
    for s in run.steps:
        if not s["files"]:
            continue
        rows = []
        for f in s["files"]:
            rel = f.relative_to(s["dir"])
            try:
                size = f.stat().st_size
            except OSError:
                size = 0
            rows.append([("html", f"<a href=\"{_rel(f, out)}\">{_esc(rel)}</a>"), _size(size),
                         (s["hashes"].get(str(rel)) or "")[:16]])
        shown = rows[:MAX_FILES_LISTED]
        more = f"<p>and {len(rows) - len(shown)} more in <a href=\"{_rel(s['dir'], out)}\">the folder</a></p>" \
            if len(rows) > len(shown) else ""
        metrics = s.get("metrics") or {}
        mt = ""
        if metrics:
            flat = _flatten(metrics)
            mt = "<details><summary>step metrics</summary>" + _table(
                ["metric", "value"], [[k, v] for k, v in flat.items()], "kv small") + "</details>"
        blocks.append(
            f"<details class=\"stepfiles\" id=\"step-{_esc(s.get('folder'))}\"><summary><b>{_esc(s.get('folder'))}</b> "
            f"{_status_badge(str(s.get('status', '?')))} {len(rows)} file(s) · "
            f"<a href=\"{_rel(s['dir'], out)}\">folder</a></summary>"
            + _table(["file", "size", "sha256"], shown, "files") + more + mt + "</details>")
    return "".join(blocks)


# --------------------------------------------------------------------------- pictures

def _mesh_for_ortho(run: RunView) -> tuple[dict, Path] | None:
    for pattern in ("textured_mesh.ply", "*textured*.ply", "*mesh*.ply"):
        for s, f in run.find(pattern):
            if f.name.startswith("gt_") or "dense" in f.name:
                continue
            return s, f
    return None


def _labels_for(run: RunView, n_vertices: int, mesh_path: Path) -> tuple[np.ndarray, str, str] | None:
    """Per-vertex trainIds for the mesh: a labels.npy of matching length, else a labelled PLY's property."""
    hits = run.find("labels.npy") + [h for h in run.find("*labels*.npy") if h[1].name != "labels.npy"]
    for s, f in hits:
        try:
            a = np.load(f, mmap_mode="r")
        except (OSError, ValueError):
            continue
        if a.ndim == 1 and len(a) == n_vertices:
            return (np.asarray(a).astype(np.int64).clip(0, 255).astype(np.uint8), run.key_of(s, f),
                    f"{s.get('folder')}/{f.name}")
    return None


class _Pictures:
    """Orthophotos: rendered once per input content, cached in <site>/.cache/report/."""

    def __init__(self, run: RunView, out: Path):
        self.run, self.out = run, out
        self.img = out / "img"
        self.frame: dict | None = None
        self.mesh: Mesh | None = None
        self.mesh_key = ""
        self.timings: dict[str, float] = {}

    def _mesh(self) -> Mesh | None:
        if self.mesh is None:
            hit = _mesh_for_ortho(self.run)
            if hit is None:
                return None
            s, f = hit
            t = time.perf_counter()
            self.mesh = read_ply(f)
            self.mesh_src = f
            self.mesh_key = self.run.key_of(s, f)
            self.timings["read_mesh_s"] = round(time.perf_counter() - t, 3)
        return self.mesh

    def ortho(self) -> dict | None:
        """{'texture': png, 'segmentation': png | None, 'bounds': (...), 'size': (w, h)}."""
        hit = _mesh_for_ortho(self.run)
        if hit is None:
            return None
        s, f = hit
        key = self.run.key_of(s, f)
        lab_hit = None
        labels_key = ""
        # labels.npy is matched by vertex count, which the header tells without reading the mesh
        nverts = _ply_vertex_count(f)
        lab = _labels_for(self.run, nverts, f) if nverts else None
        labels_name = ""
        if lab is not None:
            lab_hit, labels_key, labels_name = lab
        tag = hashlib.sha256(f"{RENDER_VERSION}|{ORTHO_PX}|{key}|{labels_key}".encode()).hexdigest()[:20]
        cache = self.run.cache_dir
        tex_c, seg_c, meta_c = cache / f"ortho-{tag}.png", cache / f"ortho-seg-{tag}.png", cache / f"ortho-{tag}.json"
        t0 = time.perf_counter()
        if not (tex_c.is_file() and meta_c.is_file()):
            mesh = self._mesh()
            if mesh is None or mesh.colors is None or not len(mesh.faces):
                return None
            bounds, w, h = ortho_frame(mesh.xyz)
            t = time.perf_counter()
            img = render_topdown(mesh.xyz, mesh.faces, mesh.colors, bounds, w, h)
            self.timings["ortho_render_s"] = round(time.perf_counter() - t, 3)
            _save_png(img, tex_c)
            labels = lab_hit if lab_hit is not None else mesh.labels
            labels_name = labels_name or (f.name + " (vertex labels)")
            if labels is not None:
                seg = render_topdown(mesh.xyz, mesh.faces, palette()[labels], bounds, w, h, flat=True)
                _save_png(seg, seg_c)
            _write_text(meta_c, json.dumps({"bounds": bounds, "size": [w, h], "mesh": str(f),
                                            "segmentation": labels is not None, "labels": labels_name}))
            self.timings["ortho_total_s"] = round(time.perf_counter() - t0, 3)
        else:
            self.timings["ortho_cached"] = 1
            for p in (tex_c, seg_c, meta_c):
                _touch(p)
        meta = json.loads(meta_c.read_text())
        _link_or_copy(tex_c, self.img / "ortho.png")
        res = {"texture": "img/ortho.png", "segmentation": None, "bounds": meta["bounds"], "size": meta["size"],
               "mesh": f, "step": s}
        if meta.get("segmentation") and seg_c.is_file():
            _link_or_copy(seg_c, self.img / "ortho_seg.png")
            res["segmentation"] = "img/ortho_seg.png"
            res["labels"] = meta.get("labels") or ""
        self.frame = res
        return res


def _ply_vertex_count(p: Path) -> int:
    try:
        with open(p, "rb") as f:
            for _ in range(200):
                line = f.readline()
                if not line or line.startswith(b"end_header"):
                    break
                t = line.split()
                if len(t) == 3 and t[0] == b"element" and t[1] == b"vertex":
                    return int(t[2])
    except OSError:
        pass
    return 0


def _sec_pictures(run: RunView, out: Path, pics: _Pictures) -> str:
    figs = []
    try:
        o = pics.ortho()
    except Exception as exc:
        log.warning("twinkit: report: no orthophoto (%s)", exc)
        log.debug("orthophoto", exc_info=True)
        o = None
    if o:
        b = o["bounds"]
        ext = f" <span class=\"dim\">{b[2] - b[0]:.1f} × {b[3] - b[1]:.1f} m, north up, from {_esc(o['mesh'].name)}</span>"
        figs.append(_figure(o["texture"], "Top-down orthophoto of the textured mesh", ext))
        if o["segmentation"]:
            src = f" <span class=\"dim\">from {_esc(o.get('labels'))}</span>" if o.get("labels") else ""
            figs.append(_figure(o["segmentation"], "The same in segmentation colours", src + _legend_html()))
    for pattern, caption in (("recon_metrics.png", "Distance from the cloud to the mesh (heat map)"),
                             ("*distance*.png", "Distance heat map"), ("*heat*.png", "Heat map"),
                             ("clean_report.png", "Mesh cleaning: what was removed"),
                             ("tile_seams.png", "Tile seams: open edges on the seams circled (red: facing surface, "
                                                "orange: the surface ends on the seam)")):
        for s, f in run.find(pattern)[:1]:
            name = f"{s.get('folder')}_{f.name}"
            if any(name in x for x in figs):
                continue
            _link_or_copy(f, out / "img" / name)
            figs.append(_figure(f"img/{name}", _esc(caption), f" <span class=\"dim\">{_esc(s.get('folder'))}/{_esc(f.name)}</span>"))
    return "<div class=\"figs\">" + "".join(figs) + "</div>" if figs else ""


def _legend_html(present: Iterable[int] | None = None) -> str:
    items = [(i, n, c) for i, (n, c) in enumerate(CITYSCAPES) if present is None or i in present]
    return "<div class=\"legendbox\">" + "".join(
        f"<span><i style=\"background:rgb{c}\"></i>{_esc(n)}</span>" for _, n, c in items) + "</div>"


def _sec_roads(run: RunView, out: Path, pics: _Pictures) -> str:
    layers = []  # (class, list of (points, width))
    sources = []
    for s, f in run.find("*.xodr"):
        try:
            roads = read_opendrive(f)
        except Exception as exc:
            log.warning("twinkit: report: cannot read %s (%s)", f, exc)
            continue
        shift = _projected_shift(run, roads)
        items = []
        for r in roads:
            ref = [(x - shift[0], y - shift[1]) for x, y in r["points"]]
            if r["junction"] in ("-1", "", None):  # paved bands of the normal roads, each side of the lane offset
                for side, sign in (("left", 1), ("right", -1)):
                    if r[side] > 0:
                        items.append((offset_polyline(ref, r["offset"] + sign * r[side] / 2), r[side], "band"))
                items.append((ref, 0.0, "xodr"))
            else:
                items.append((ref, 0.0, "xodr junction"))
        layers.append(("xodr", items))
        sources.append(f"{s.get('folder')}/{f.name} ({len(roads)} roads)")
        break
    for s, f in run.find("roads_truth.json")[:1]:
        d = _read_json(f) or {}
        lanes = [([tuple(p[:2]) for p in ln.get("points", [])], 0.0, "truth") for ln in d.get("lanes", [])
                 if ln.get("points")]
        if lanes:
            layers.append(("truth", lanes))
            sources.append(f"{s.get('folder')}/{f.name} ({len(lanes)} lane centre lines, reference)")
    qa = []
    for s, f in run.find("*road*.png") + run.find("*xodr*.png"):
        name = f"{s.get('folder')}_{f.name}"
        if (out / "img" / name).exists():
            continue
        _link_or_copy(f, out / "img" / name)
        qa.append(_figure(f"img/{name}", f"Road QA: {_esc(f.name)}"))
    parts = []
    frame = pics.frame
    if layers and frame:
        b, (w, h) = frame["bounds"], frame["size"]
        sx, sy = w / (b[2] - b[0]), h / (b[3] - b[1])
        svg = [f"<svg class=\"roads\" viewBox=\"0 0 {w} {h}\" xmlns=\"http://www.w3.org/2000/svg\">",
               f"<image href=\"{frame['texture']}\" x=\"0\" y=\"0\" width=\"{w}\" height=\"{h}\" opacity=\"0.85\"/>"]
        drawn = sorted((it for _, items in layers for it in items), key=lambda it: 0 if it[2] == "band" else 1)
        for pts, width, cls in drawn:  # bands first, lines over them
            if len(pts) < 2:
                continue
            d = " ".join(f"{(x - b[0]) * sx:.1f},{(b[3] - y) * sy:.1f}" for x, y in pts)
            sw = f" stroke-width=\"{width * sx:.1f}\"" if cls == "band" else ""
            svg.append(f"<polyline class=\"{cls}\" points=\"{d}\"{sw}/>")
        svg.append("</svg>")
        keys = "<span class=\"key xodr\">OpenDRIVE reference lines (band: paved lanes; thin: junctions)</span>" if any(
            c == "xodr" for c, _ in layers) else ""
        keys += "<span class=\"key truth\">site's reference lanes</span>" if any(c == "truth" for c, _ in layers) else ""
        parts.append(f"<figure class=\"wide\">{''.join(svg)}<figcaption>Road network over the orthophoto. "
                     f"{keys}<br><span class=\"dim\">{_esc('; '.join(sources))}</span></figcaption></figure>")
    if qa:
        parts.append("<div class=\"figs\">" + "".join(qa) + "</div>")
    return "".join(parts)


def _projected_shift(run: RunView, roads: list[dict]) -> tuple[float, float]:
    """OpenDRIVE in projected coordinates -> site frame, using the site's base point."""
    xs = [abs(x) for r in roads for x, _ in r["points"][:1]]
    if not xs or max(xs) < 1e4:
        return (0.0, 0.0)
    hit = run.first("site.json")
    bp = ((_read_json(hit[1]) or {}).get("base_point_projected") or {}) if hit else {}
    return (float(bp.get("x", 0)), float(bp.get("y", 0)))


_IMG_EXT = (".png", ".jpg", ".jpeg", ".webp")


def _colourise(im):
    """A label image (mode L/P/I of trainIds) in CityScapes colours; other images unchanged."""
    from PIL import Image

    if im.mode in ("L", "I", "I;16", "P"):
        a = np.asarray(im if im.mode != "P" else im.convert("L"))
        if a.max() < 256 and (np.isin(np.unique(a), list(range(19)) + [255]).all()):
            return Image.fromarray(palette()[a.astype(np.int64).clip(0, 255)])
    return im.convert("RGB")


def _sec_contact(run: RunView, out: Path) -> str:
    """Sample views next to their 2D predictions (and ground truth), paired by file stem."""
    dirs: dict[Path, dict[str, Path]] = {}
    owner: dict[Path, dict] = {}
    for s, f in run.all_files():
        if f.suffix.lower() in _IMG_EXT and f.parent != s["dir"]:
            dirs.setdefault(f.parent, {})[f.stem] = f
            owner[f.parent] = s

    def role(d: Path) -> int:
        n = d.name.lower()
        if any(k in n for k in ("pred", "seg", "mask", "label", "gt", "truth")):
            return 1
        return 0

    views = [d for d in dirs if role(d) == 0]
    if not views:
        return ""
    # prefer rendered views when they have predictions; else the photos
    def score(d):
        matches = sum(1 for o in dirs if o != d and role(o) == 1 and set(dirs[o]) & set(dirs[d]))
        return (matches, "render" in d.name.lower() or "view" in d.name.lower(), len(dirs[d]))

    vdir = max(views, key=score)
    others = [d for d in dirs if d != vdir and role(d) == 1 and set(dirs[d]) & set(dirs[vdir])]
    others.sort(key=lambda d: (0 if "pred" in d.name.lower() else 1, str(d)))
    if not others:
        return ""
    stems = sorted(set(dirs[vdir]) & set().union(*(set(dirs[o]) for o in others)))
    if len(stems) > CONTACT_ROWS:
        idx = np.linspace(0, len(stems) - 1, CONTACT_ROWS).round().astype(int)
        stems = [stems[i] for i in idx]
    from PIL import Image, ImageDraw

    cols = [vdir] + others
    parts = [f"{RENDER_VERSION}|contact"] + [f"{d}|{st}|{_file_key(dirs[d][st])}" for st in stems for d in cols
                                              if st in dirs[d]]
    cached = run.cache_dir / f"contact-{hashlib.sha256(chr(10).join(parts).encode()).hexdigest()[:20]}.jpg"
    cap = (f"{len(stems)} sample views ({_esc(owner[vdir].get('folder'))}/{_esc(vdir.name)}) with "
           + ", ".join(f"{_esc(owner[o].get('folder'))}/{_esc(o.name)}" for o in others))
    html_out = "<div class=\"figs\">" + _figure("img/contact_sheet.jpg", cap, _legend_html()) + "</div>"
    if cached.is_file():
        _touch(cached)
        _link_or_copy(cached, out / "img" / "contact_sheet.jpg")
        return html_out
    tw = 320
    cells = []
    th = 0
    for st in stems:
        row = []
        for d in cols:
            f = dirs[d].get(st)
            if f is None:
                row.append(None)
                continue
            with Image.open(f) as im:
                im = _colourise(im) if role(d) == 1 else im.convert("RGB")
                im = im.resize((tw, max(1, round(im.height * tw / im.width))), Image.NEAREST if role(d) else Image.BILINEAR)
            th = max(th, im.height)
            row.append(im)
        cells.append(row)
    pad, head = 6, 22
    sheet = Image.new("RGB", (len(cols) * (tw + pad) + pad, head + len(stems) * (th + pad + 16) + pad), "white")
    draw = ImageDraw.Draw(sheet)
    for j, d in enumerate(cols):
        draw.text((pad + j * (tw + pad), 5), f"{owner[d].get('folder')}/{d.name}", fill=(0, 0, 0))
    for i, row in enumerate(cells):
        y = head + i * (th + pad + 16)
        draw.text((pad, y), stems[i], fill=(60, 60, 60))
        for j, im in enumerate(row):
            if im is not None:
                sheet.paste(im, (pad + j * (tw + pad), y + 14))
    cached.parent.mkdir(parents=True, exist_ok=True)
    tmp = cached.with_name(f".{cached.stem}.{os.getpid()}.tmp.jpg")
    sheet.save(tmp, quality=88)
    tmp.replace(cached)
    _link_or_copy(cached, out / "img" / "contact_sheet.jpg")
    return html_out


# --------------------------------------------------------------------------- metrics

def _stats_table(title: str, d: dict) -> str:
    rows, cols = [], []
    for k, v in d.items():
        if isinstance(v, dict) and v and all(isinstance(x, (int, float)) for x in v.values()):
            for c in v:
                if c not in cols:
                    cols.append(c)
    for k, v in d.items():
        if isinstance(v, dict) and v and all(isinstance(x, (int, float)) for x in v.values()):
            rows.append([k] + [v.get(c, "") for c in cols])
    if not rows:
        return ""
    return f"<h3>{_esc(title)}</h3>" + _table(["distance (m)"] + cols, rows)


_STAT_KEYS = {"min", "max", "mean", "median", "p5", "p50", "p90", "p95", "p99", "rms", "std", "count"}


def _sec_recon_metrics(run: RunView) -> str:
    hit = run.first("recon_metrics.json")
    if not hit:
        return ""
    s, f = hit
    d = _read_json(f) or {}
    parts = []
    def is_stats(v):
        return isinstance(v, dict) and bool(v) and set(v) <= _STAT_KEYS

    dist = {k: v for k, v in d.items() if is_stats(v)}
    gt = d.get("gt") if isinstance(d.get("gt"), dict) else {}
    dist.update({f"gt: {k}": v for k, v in gt.items() if is_stats(v)})
    parts.append(_stats_table("Distances", dist))
    scal = [[f"gt: {k}", v] for k, v in gt.items() if isinstance(v, (int, float)) and not isinstance(v, bool)]
    within = d.get("cloud_within_m")
    if isinstance(within, dict):
        parts.append("<h3>Cloud points within a distance of the mesh</h3>" + _table(
            ["within (m)", "fraction"], [[k, v] for k, v in within.items()]))
    if isinstance(d.get("counts"), dict):
        parts.append("<h3>Counts</h3>" + _table(["", "count"], [[k, v] for k, v in d["counts"].items()]))
    if scal:
        parts.append("<h3>Against ground truth</h3>" + _table(["metric", "value"], scal))
    parts.append(f"<p class=\"dim\">from {_esc(s.get('folder'))}/{_esc(f.name)}</p>")
    return "".join(p for p in parts if p)


_SCORE_KEY = re.compile(r"(^|[_\-. ])(iou|f1)($|[_\-. ])", re.I)


def _is_score(k: Any) -> bool:
    return bool(_SCORE_KEY.search(str(k)))


def _per_class_tables(d: Any, path: str = "", parent: Any = None) -> list[tuple[str, dict, dict]]:
    """Every table of class -> {iou, f1, ...} (a dict of dicts, or a list of rows) inside a JSON document,
    as (where, the numbers next to it (mIoU, accuracy...), the table)."""
    def scalars(x):
        return {k: v for k, v in x.items() if isinstance(v, (int, float)) and not isinstance(v, bool)} \
            if isinstance(x, dict) else {}

    if isinstance(d, dict):
        vals = list(d.values())
        if vals and all(isinstance(v, dict) for v in vals) and sum(
                any(_is_score(k) for k in v) for v in vals) >= max(1, len(vals) // 2):
            return [(path, scalars(parent), d)]
        out = []
        for k, v in d.items():
            out += _per_class_tables(v, f"{path}.{k}" if path else str(k), d)
        return out
    if isinstance(d, list) and d and all(isinstance(x, dict) for x in d) and any(
            any(_is_score(k) for k in x) for x in d):
        rows = {}
        for i, x in enumerate(d):
            name = x.get("name") or x.get("class") or x.get("label") or x.get("id") or str(i)
            rows[str(name)] = {k: v for k, v in x.items() if k not in ("name", "class", "label")}
        return [(path, scalars(parent), rows)]
    return []


def _sec_seg_metrics(run: RunView) -> str:
    parts = []
    for s, f in run.find("*.json"):
        if f.name == "step.json" or f.stat().st_size > 2_000_000:
            continue
        d = _read_json(f)
        tables = _per_class_tables(d) if isinstance(d, (dict, list)) else []
        for where, summary, per in tables:
            cols: list[str] = []
            for v in per.values():
                for k in v:
                    if isinstance(v[k], (int, float)) and not isinstance(v[k], bool) and k not in cols:
                        cols.append(k)
            cols.sort(key=lambda k: (0 if _is_score(k) else 1))
            rows = []
            for name, v in per.items():
                label = str(name)
                if label.isdigit() and int(label) < len(CITYSCAPES):
                    label = f"{label} {CITYSCAPES[int(label)][0]}"
                col = next((c for i, (n, c) in enumerate(CITYSCAPES) if n == str(name).lower() or str(i) == str(name)),
                           None)
                sw = f"<i class=\"sw\" style=\"background:rgb{col}\"></i>" if col else ""
                rows.append([("html", sw + _esc(label))] + [v.get(c, "") for c in cols])
            parent = where.rsplit(".", 1)[0] if "." in where else ""
            title = f"{s.get('folder')}/{f.name}" + (f" · {parent}" if parent else "")
            parts.append(f"<h3>{_esc(title)}</h3>")
            if summary:
                parts.append(_table(["", ""], [[k, v] for k, v in summary.items()], "kv"))
            parts.append(_table(["class"] + cols, rows))
        md = f.with_suffix(".md")
        if tables and md.is_file():
            parts.append(f"<p class=\"dim\">also as text: <a href=\"{_rel(md, run.report_dir)}\">"
                         f"{_esc(s.get('folder'))}/{_esc(md.name)}</a></p>")
    return "".join(parts)


def _sec_alignment(run: RunView) -> str:
    parts = []
    for s, f in run.find("*align*.json") + run.find("*residual*.json") + run.find("*roads_check*.json"):
        d = _read_json(f)
        if not isinstance(d, dict):
            continue
        flat = [[k, v] for k, v in _flatten(d).items() if isinstance(v, (int, float, str, bool)) or
                (isinstance(v, list) and len(v) <= 6 and all(isinstance(x, (int, float)) for x in v))]
        flat.sort(key=lambda r: (0 if "resid" in r[0].lower() or "rms" in r[0].lower() else 1))
        flat = [[k, f"{v:.10g}" if isinstance(v, float) else v] for k, v in flat]  # coordinates keep their digits
        parts.append(f"<h3>{_esc(s.get('folder'))}/{_esc(f.name)}</h3>" + _table(["", ""], flat, "kv"))
    return "".join(parts)


# --------------------------------------------------------------------------- 3D view

def _sec_viewer(run: RunView, out: Path, pics: _Pictures) -> str:
    vdir = out / "viewer"
    glbs = [(s, f) for s, f in run.find("*.glb") if not f.name.startswith("gt_")]
    source = None
    cache = run.cache_dir
    note = ""
    if glbs and glbs[0][1].stat().st_size > MAX_GLB_BYTES:
        s, f = glbs[0]
        note = (f" {_esc(s.get('folder'))}/{_esc(f.name)} ({_size(f.stat().st_size)}) is too heavy for the page; "
                f"<a href=\"{_rel(f, out)}\">download it</a>.")
        glbs = []
    if glbs:
        s, f = glbs[0]
        _link_or_copy(f, vdir / "model.glb")
        source = f"{s.get('folder')}/{f.name}"
    else:
        hit = _mesh_for_ortho(run)
        if hit is None:
            return f"<p>{note}</p>" if note else ""
        s, f = hit
        nverts = _ply_vertex_count(f)
        lab = _labels_for(run, nverts, f)
        tag = hashlib.sha256(f"{RENDER_VERSION}|glb|{VIEWER_MAX_FACES}|{run.key_of(s, f)}|"
                             f"{lab[1] if lab else ''}".encode()).hexdigest()[:20]
        cached = cache / f"view-{tag}.glb"
        if not cached.is_file():
            t = time.perf_counter()
            mesh = pics._mesh()
            if mesh is None or not len(mesh.faces):
                return ""
            labels = lab[0] if lab else mesh.labels
            xyz, faces, near = decimate(mesh.xyz, mesh.faces, VIEWER_MAX_FACES)
            cols = mesh.colors[near] if mesh.colors is not None else None
            seg = palette()[labels[near]] if labels is not None else None
            write_glb(cached, xyz, faces, cols, seg)
            pics.timings["glb_s"] = round(time.perf_counter() - t, 3)
        else:
            _touch(cached)
        _link_or_copy(cached, vdir / "model.glb")
        source = f"{s.get('folder')}/{f.name} (decimated to at most {VIEWER_MAX_FACES:,} faces for the page)"
    if not vendor_three(vdir, cache):
        return ("<p class=\"warn\">The 3D view needs three.js, which is not installed: run <code>npm ci</code> "
                "in the twinkit repository and run again. "
                f"The model is here: <a href=\"viewer/model.glb\">viewer/model.glb</a></p>")
    glb_stat = (vdir / "model.glb").stat()
    js_cached = cache / f"model-{glb_stat.st_ino}-{glb_stat.st_size}-{glb_stat.st_mtime_ns}.glb.js"
    if not js_cached.is_file():
        write_glb_js(vdir / "model.glb", js_cached)
    else:
        _touch(js_cached)
    _link_or_copy(js_cached, vdir / "model.glb.js")
    shutil.copyfile(ASSETS / VIEWER_FILE, vdir / VIEWER_FILE)
    return (
        "<div id=\"viewer\" class=\"viewer\"><canvas id=\"viewer-canvas\"></canvas>"
        "<div class=\"viewer-ui\">"
        "<label><input type=\"radio\" name=\"colours\" id=\"mode-texture\" value=\"texture\" checked> texture</label>"
        "<label><input type=\"radio\" name=\"colours\" id=\"mode-segmentation\" value=\"segmentation\"> segmentation"
        "</label><button id=\"view-reset\" type=\"button\">reset view</button>"
        "<span id=\"viewer-status\">loading…</span></div></div>"
        f"<p class=\"dim\">From {_esc(source)}: <a href=\"viewer/model.glb\">model.glb</a> "
        f"({_size((vdir / 'model.glb').stat().st_size)}).{note} Drag to orbit, right-drag to pan, wheel to zoom.</p>"
        "<script src=\"viewer/three-bundle.js\"></script><script src=\"viewer/model.glb.js\"></script>"
        "<script src=\"viewer/viewer.js\"></script>"
    )


# --------------------------------------------------------------------------- assembling

def _render_page(title: str, page: _Page, subtitle: str = "") -> str:
    nav = "".join(f"<a href=\"#{sid}\">{_esc(t)}</a>" for sid, t, _ in page.sections)
    body = "".join(f"<section id=\"{sid}\"><h2>{_esc(t)}</h2>{h}</section>" for sid, t, h in page.sections)
    notes = "".join(f"<p class=\"warn\">{_esc(n)}</p>" for n in page.notes)
    gen = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    return (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
        f"<title>{_esc(title)}</title><link rel=\"stylesheet\" href=\"{CSS_FILE}\"></head><body>"
        f"<header><h1>{_esc(title)}</h1><p>{subtitle}</p><nav>{nav}</nav></header>{notes}<main>{body}</main>"
        f"<footer>written by twinkit.report at {gen}</footer></body></html>\n"
    )


def build_report(run_dir: Path, manifest: dict, engine=None) -> Path:
    """Write ``<run_dir>/report/report.html`` (raises on problems; ``write_report`` is the safe entry)."""
    t0 = time.perf_counter()
    run = RunView(run_dir, manifest, engine)
    out = Path(run_dir) / REPORT_DIR
    for stale in list(Path(run_dir).glob(f".{REPORT_DIR}.tmp-*")) + list(Path(run_dir).glob(f".{REPORT_DIR}.old-*")):
        shutil.rmtree(stale, ignore_errors=True)  # left by an interrupted report
    tmp = Path(run_dir) / f".{REPORT_DIR}.tmp-{os.getpid()}"
    tmp.mkdir(parents=True)
    # links in the page are computed from the final folder; files are written into the temporary one
    page = _Page(tmp)
    pics = _Pictures(run, tmp)
    timings: dict[str, float] = {}

    def section(sid: str, title: str, fn, *args) -> None:
        t = time.perf_counter()
        try:
            page.add(sid, title, fn(*args))
        except Exception as exc:
            log.warning("twinkit: report: section '%s' left out (%s: %s)", title, type(exc).__name__, exc)
            log.debug("report section %s", sid, exc_info=True)
            page.notes.append(f"The section '{title}' could not be written ({type(exc).__name__}: {exc}); "
                              "see run.log.")
        timings[sid] = round(time.perf_counter() - t, 3)

    section("summary", "Run", _sec_summary, run, out)
    section("timeline", "Step timeline", _sec_timeline, run)
    section("view3d", "3D view", _sec_viewer, run, tmp, pics)
    section("pictures", "Pictures", _sec_pictures, run, tmp, pics)
    section("roads", "Road network", _sec_roads, run, tmp, pics)
    section("samples", "Sample views and 2D predictions", _sec_contact, run, tmp)
    section("recon", "Reconstruction metrics", _sec_recon_metrics, run)
    section("segmetrics", "Segmentation metrics", _sec_seg_metrics, run)
    section("alignment", "Alignment", _sec_alignment, run)
    section("provenance", "Provenance", _sec_provenance, run, out)
    section("files", "Files", _sec_files, run, out)
    cfg = manifest.get("config") or {}
    title = f"twinkit report: {(manifest.get('site') or {}).get('name', '?')} · " \
            f"{(cfg.get('recipe') or {}).get('name', '?')}"
    sub = (f"{_status_badge(str(manifest.get('status', '?')))} run {_esc(Path(run_dir).name)} · "
           f"{_esc(manifest.get('finished', ''))}")
    shutil.copyfile(ASSETS / CSS_FILE, tmp / CSS_FILE)
    (tmp / "report.html").write_text(_render_page(title, page, sub), encoding="utf-8")
    timings.update(pics.timings)
    timings["total_s"] = round(time.perf_counter() - t0, 3)
    prune_cache(run.cache_dir)
    (tmp / "report.json").write_text(json.dumps({"sections": [s for s, _, _ in page.sections],
                                                 "timings_s": timings}, indent=1) + "\n")
    old = Path(run_dir) / f".{REPORT_DIR}.old-{os.getpid()}"
    if out.exists():
        out.rename(old)
    tmp.rename(out)
    if old.exists():
        shutil.rmtree(old, ignore_errors=True)
    log.debug("report written in %.2f s: %s", timings["total_s"], timings)
    return out / "report.html"


def write_report(run_dir: Path, manifest: dict, engine=None) -> Path | None:
    """The report of one run; None (and one warning) if it could not be written. Never raises."""
    try:
        return build_report(Path(run_dir), manifest, engine)
    except Exception as exc:
        log.warning("twinkit: no report for this run (%s: %s)", type(exc).__name__, exc)
        log.debug("report", exc_info=True)
        return None


# =========================================================================== multirun sweeps

def _parse_override(o: str) -> tuple[str, str] | None:
    if "=" not in o:
        return None
    k, v = o.split("=", 1)
    return k.lstrip("+~"), v


def _num(v: Any) -> float | None:
    if isinstance(v, bool):
        return None
    if isinstance(v, (int, float)):
        return float(v)
    try:
        return float(str(v))
    except ValueError:
        return None


_SKIP_METRIC = re.compile(r"(peak|rss|delta_peak|seconds|timings|substeps|shift_m)", re.I)


def sweep_rows(sweep_dir: Path) -> tuple[list[str], list[str], list[dict]]:
    """(swept keys, metric names, one row per job: {'job', 'status', 'duration_s', 'params', 'metrics'})."""
    rows = []
    for mf in sorted(Path(sweep_dir).glob("job*/manifest.json"), key=lambda p: _job_num(p.parent.name)):
        m = _read_json(mf, limit=50_000_000)
        if not isinstance(m, dict):
            continue
        params = dict(x for x in (_parse_override(o) for o in m.get("overrides") or []) if x)
        metrics: dict[str, Any] = {}
        for s in m.get("steps") or []:
            for k, v in _flatten(s.get("metrics") or {}).items():
                if _SKIP_METRIC.search(k) or _num(v) is None:
                    continue
                metrics[f"{s.get('id')}.{k}"] = v
        rows.append({"job": mf.parent.name, "status": m.get("status"), "duration_s": m.get("duration_s"),
                     "params": params, "metrics": metrics, "dir": mf.parent})
    keys: list[str] = []
    for r in rows:
        for k in r["params"]:
            if k not in keys:
                keys.append(k)
    swept = [k for k in keys if len({r["params"].get(k) for r in rows}) > 1] or keys
    names: list[str] = []
    for r in rows:
        for k in r["metrics"]:
            if k not in names:
                names.append(k)
    varying = [k for k in names if len({json.dumps(r["metrics"].get(k)) for r in rows}) > 1]
    return swept, varying + [k for k in names if k not in varying], rows


def _job_num(name: str) -> int:
    m = re.search(r"\d+", name)
    return int(m.group()) if m else 0


def _nice_ticks(lo: float, hi: float, n: int = 4) -> list[float]:
    """Round tick values (1, 2, 5 x 10^k steps) covering [lo, hi]."""
    raw = (hi - lo) / n
    mag = 10 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1, 2, 2.5, 5, 10) if m * mag >= raw)
    start = math.floor(lo / step) * step
    ticks = []
    v = start
    while v < hi + step * 0.999:
        ticks.append(round(v, 12))
        v += step
    return ticks


def _svg_plot(xs: list[float], ys: list[float], xlabel: str, ylabel: str, w: int = 360, h: int = 240,
              labels: list[str] | None = None) -> str:
    """A small line plot with axes and ticks, as inline SVG."""
    ml, mr, mt, mb = 58, 12, 22, 40
    pw, ph = w - ml - mr, h - mt - mb
    x0, x1 = min(xs), max(xs)
    y0, y1 = min(ys), max(ys)
    if x1 == x0:
        x0, x1 = x0 - 1, x1 + 1
    if y1 == y0:
        y0, y1 = y0 - (abs(y0) * 0.1 or 1), y1 + (abs(y1) * 0.1 or 1)
    ticks = _nice_ticks(y0, y1)
    y0, y1 = min(y0, ticks[0]), max(y1, ticks[-1])

    def X(v):
        return ml + (v - x0) / (x1 - x0) * pw

    def Y(v):
        return mt + ph - (v - y0) / (y1 - y0) * ph

    out = [f"<svg class=\"plot\" viewBox=\"0 0 {w} {h}\" width=\"{w}\" height=\"{h}\" xmlns=\"http://www.w3.org/2000/svg\">",
           f"<text x=\"{ml}\" y=\"14\" class=\"t\">{_esc(ylabel)}</text>",
           f"<rect x=\"{ml}\" y=\"{mt}\" width=\"{pw}\" height=\"{ph}\" class=\"frame\"/>"]
    for yv in ticks:
        out.append(f"<line x1=\"{ml}\" x2=\"{ml + pw}\" y1=\"{Y(yv):.1f}\" y2=\"{Y(yv):.1f}\" class=\"grid\"/>"
                   f"<text x=\"{ml - 4}\" y=\"{Y(yv) + 4:.1f}\" class=\"tick\" text-anchor=\"end\">{_esc(_fmt(yv))}</text>")
    for xv in sorted(set(xs)):
        out.append(f"<text x=\"{X(xv):.1f}\" y=\"{mt + ph + 14}\" class=\"tick\" text-anchor=\"middle\">{_esc(_fmt(xv))}</text>")
    out.append(f"<text x=\"{ml + pw / 2}\" y=\"{h - 6}\" class=\"t\" text-anchor=\"middle\">{_esc(xlabel)}</text>")
    order = sorted(range(len(xs)), key=lambda i: xs[i])
    out.append("<polyline class=\"line\" points=\"" + " ".join(f"{X(xs[i]):.1f},{Y(ys[i]):.1f}" for i in order) + "\"/>")
    for i in order:
        tip = f"{labels[i]}: " if labels else ""
        out.append(f"<circle cx=\"{X(xs[i]):.1f}\" cy=\"{Y(ys[i]):.1f}\" r=\"3.5\" class=\"pt\">"
                   f"<title>{_esc(tip)}{_esc(xlabel)}={_esc(_fmt(xs[i]))}, {_esc(ylabel)}={_esc(_fmt(ys[i]))}</title></circle>")
    out.append("</svg>")
    return "".join(out)


#: metrics plotted first when a sweep varies them (substrings, in order of interest).
PRIMARY_METRICS = ("miou", "mean_iou", "iou", "f1", "residual", "chamfer", "cloud_to_mesh_mean", "mean")
MAX_PLOTS = 8


def write_sweep_summary(sweep_dir: Path) -> Path:
    """``<sweep_dir>/report/sweep.html``: the sweep table (swept overrides vs. metrics) and plots."""
    sweep_dir = Path(sweep_dir)
    swept, names, rows = sweep_rows(sweep_dir)
    out = sweep_dir / REPORT_DIR
    out.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(ASSETS / CSS_FILE, out / CSS_FILE)
    page = _Page(out)
    varying = [k for k in names if len({json.dumps(r["metrics"].get(k)) for r in rows}) > 1]
    shown = varying[:30] if varying else names[:12]
    head = ["job", "status"] + swept + ["time (s)"] + shown
    trs = []
    for r in rows:
        rep = r["dir"] / REPORT_DIR / "report.html"
        job = ("html", f"<a href=\"{_rel(rep, out)}\">{_esc(r['job'])}</a>") if rep.is_file() else r["job"]
        trs.append([job, r["status"] or "?"] + [_num(r["params"].get(k)) if _num(r["params"].get(k)) is not None
                                                 else r["params"].get(k, "") for k in swept]
                   + [r["duration_s"] or 0] + [r["metrics"].get(k, "") for k in shown])
    page.add("table", "Sweep", "<div class=\"scroll\">" + _table(head, trs, "sweep") + "</div>" + (
        f"<p class=\"dim\">{len(names) - len(shown)} metric(s) that did not change are left out; "
        "each job's manifest has them all.</p>" if len(names) > len(shown) else ""))
    plots = []
    numeric = [k for k in swept if all(_num(r["params"].get(k)) is not None for r in rows)]

    def interest(name: str) -> tuple:
        low = name.lower()
        return (next((i for i, p in enumerate(PRIMARY_METRICS) if p in low), len(PRIMARY_METRICS)), name)

    for k in numeric:
        same = [m for m in varying if all(_num(r["metrics"].get(m)) == _num(r["params"][k]) for r in rows)]
        for metric in sorted((m for m in varying if m not in same), key=interest)[:MAX_PLOTS]:
            pts = [(_num(r["params"][k]), _num(r["metrics"].get(metric)), r["job"]) for r in rows]
            pts = [p for p in pts if p[1] is not None]
            if len(pts) >= 2:
                plots.append(_svg_plot([p[0] for p in pts], [p[1] for p in pts], k, metric,
                                       labels=[p[2] for p in pts]))
    if plots:
        page.add("plots", "Metrics against the swept parameter", "<div class=\"plots\">" + "".join(plots) + "</div>")
    elif rows and not numeric:
        page.notes.append("No swept parameter is numeric, so there is no plot; the table has every job.")
    title = f"twinkit sweep: {sweep_dir.name}"
    (out / "sweep.html").write_text(_render_page(title, page, f"{len(rows)} job(s) in {_esc(sweep_dir)}"),
                                    encoding="utf-8")
    return out / "sweep.html"


try:  # a Hydra callback: conf/config.yaml -> hydra.callbacks.report._target_: twinkit.report.SweepSummaryCallback
    from hydra.experimental.callback import Callback as _HydraCallback
except Exception:  # pragma: no cover - Hydra is a dependency; this keeps the module importable without it
    _HydraCallback = object


class SweepSummaryCallback(_HydraCallback):  # type: ignore[misc, valid-type]
    """Writes the sweep summary when a multirun ends (never fails the sweep)."""

    _done: set = set()

    def on_multirun_end(self, config, **kwargs) -> None:
        sweep = Path(str(config.hydra.sweep.dir)).resolve()
        if sweep in SweepSummaryCallback._done:  # Hydra may call a callback twice; write and say it once
            return
        SweepSummaryCallback._done.add(sweep)
        try:
            path = write_sweep_summary(sweep)
            print(f"twinkit: sweep summary file://{path.resolve()}")
        except Exception as exc:
            log.warning("twinkit: no sweep summary (%s: %s)", type(exc).__name__, exc)

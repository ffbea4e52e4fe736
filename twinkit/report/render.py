"""The top-down renderer (GL, else numpy splats) and the orthophotos of a run, cached by input content.

Core conventions (the engine's shared file names, not any one plugin's): the report pictures the latest
mesh named like ``MESH_PATTERNS`` (``textured_mesh.ply`` first; names starting with ``gt_`` or holding
``dense`` are skipped) and colours it by the latest ``labels.npy`` (else another ``*labels*.npy``) whose
length is the mesh's vertex count: one CityScapes trainId per vertex, as the segmenters write it and the
exporters and road alignment read it. A PLY vertex property ``label`` works too.
"""
from __future__ import annotations

import hashlib
import json
import logging
import os
import time
from pathlib import Path

import numpy as np

from twinkit.mesh import Mesh, ply_vertex_count, read_ply
from twinkit.report.page import palette
from twinkit.report.run import RunView, link_or_copy, touch, write_text

log = logging.getLogger("twinkit.report")

#: bump when a cached picture or model would come out differently for the same inputs.
RENDER_VERSION = "4"
ORTHO_PX = 2048            # long side of the orthophotos
#: the mesh the orthophotos and the light 3D model show (first pattern that matches, latest step first)
MESH_PATTERNS = ("textured_mesh.ply", "*textured*.ply", "*mesh*.ply")
#: per-vertex CityScapes trainIds of that mesh (matched by length)
LABELS_FILE = "labels.npy"
LABELS_PATTERN = "*labels*.npy"

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



def read_view_mesh(path: Path) -> Mesh:
    """The mesh the pictures and the 3D view show (twinkit.mesh.read_ply): ``faces`` (m, 3), empty (0, 3) for a
    cloud; a vertex ``label`` property as ``attrs["label"]`` (n,) uint8 trainIds; ``colors`` (n, 3) uint8 or None."""
    m = read_ply(path)
    if m.faces is None:
        m.faces = np.zeros((0, 3), np.int64)
    if "label" in m.attrs:
        m.attrs["label"] = np.asarray(m.attrs["label"]).astype(np.uint8)
    return m

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


def save_png(img: np.ndarray, path: Path) -> None:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.png")
    Image.fromarray(img).save(tmp, optimize=False, compress_level=3)
    tmp.replace(path)


def mesh_for_ortho(run: RunView) -> tuple[dict, Path] | None:
    for pattern in MESH_PATTERNS:
        for s, f in run.find(pattern):
            if f.name.startswith("gt_") or "dense" in f.name:
                continue
            return s, f
    return None


def labels_for(run: RunView, n_vertices: int, mesh_path: Path) -> tuple[np.ndarray, str, str] | None:
    """Per-vertex trainIds for the mesh: a labels.npy of matching length, else a labelled PLY's property."""
    hits = run.find(LABELS_FILE) + [h for h in run.find(LABELS_PATTERN) if h[1].name != LABELS_FILE]
    for s, f in hits:
        try:
            a = np.load(f, mmap_mode="r")
        except (OSError, ValueError):
            continue
        if a.ndim == 1 and len(a) == n_vertices:
            return (np.asarray(a).astype(np.int64).clip(0, 255).astype(np.uint8), run.key_of(s, f),
                    f"{s.get('folder')}/{f.name}")
    return None


class TopDown:
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
            hit = mesh_for_ortho(self.run)
            if hit is None:
                return None
            s, f = hit
            t = time.perf_counter()
            self.mesh = read_view_mesh(f)
            self.mesh_src = f
            self.mesh_key = self.run.key_of(s, f)
            self.timings["read_mesh_s"] = round(time.perf_counter() - t, 3)
        return self.mesh

    def ortho(self) -> dict | None:
        """{'texture': png, 'segmentation': png | None, 'bounds': (...), 'size': (w, h)}."""
        hit = mesh_for_ortho(self.run)
        if hit is None:
            return None
        s, f = hit
        key = self.run.key_of(s, f)
        lab_hit = None
        labels_key = ""
        # labels.npy is matched by vertex count, which the header tells without reading the mesh
        nverts = ply_vertex_count(f)
        lab = labels_for(self.run, nverts, f) if nverts else None
        labels_name = ""
        if lab is not None:
            lab_hit, labels_key, labels_name = lab
        tag = hashlib.sha256(f"{RENDER_VERSION}|{ORTHO_PX}|{key}|{labels_key}".encode()).hexdigest()[:20]
        cache = self.run.cache_dir
        tex_c, seg_c, meta_c = cache / f"ortho-{tag}.png", cache / f"ortho-seg-{tag}.png", cache / f"ortho-{tag}.json"
        t0 = time.perf_counter()
        if not (tex_c.is_file() and meta_c.is_file()):
            mesh = self._mesh()
            if mesh is None or mesh.colors is None or mesh.faces is None or not len(mesh.faces):
                return None
            bounds, w, h = ortho_frame(mesh.vertices)
            t = time.perf_counter()
            img = render_topdown(mesh.vertices, mesh.faces, mesh.colors, bounds, w, h)
            self.timings["ortho_render_s"] = round(time.perf_counter() - t, 3)
            save_png(img, tex_c)
            labels = lab_hit if lab_hit is not None else mesh.attrs.get("label")
            labels_name = labels_name or (f.name + " (vertex labels)")
            if labels is not None:
                seg = render_topdown(mesh.vertices, mesh.faces, palette()[labels], bounds, w, h, flat=True)
                save_png(seg, seg_c)
            write_text(meta_c, json.dumps({"bounds": bounds, "size": [w, h], "mesh": str(f),
                                            "segmentation": labels is not None, "labels": labels_name}))
            self.timings["ortho_total_s"] = round(time.perf_counter() - t0, 3)
        else:
            self.timings["ortho_cached"] = 1
            for p in (tex_c, seg_c, meta_c):
                touch(p)
        meta = json.loads(meta_c.read_text())
        link_or_copy(tex_c, self.img / "ortho.png")
        res = {"texture": "img/ortho.png", "segmentation": None, "bounds": meta["bounds"], "size": meta["size"],
               "mesh": f, "step": s}
        if meta.get("segmentation") and seg_c.is_file():
            link_or_copy(seg_c, self.img / "ortho_seg.png")
            res["segmentation"] = "img/ortho_seg.png"
            res["labels"] = meta.get("labels") or ""
        self.frame = res
        return res

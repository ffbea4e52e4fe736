"""Unlit textured rendering of a mesh plus a per-pixel map to the nearest vertex (moderngl, headless EGL).

One draw call per view writes two images: the texture colour (sky-blue background) and,
per pixel, ``3 * face + corner + 1`` where ``corner`` (0..2) is the triangle corner with
the largest (perspective-correct) barycentric coordinate, i.e. the nearest vertex of the
hit triangle. ``vertex = faces[face, corner]``; 0 = background. No geometry shader is
needed: each face has its own three vertices in the vertex buffer (``3 * face + corner``), so
``gl_VertexID`` gives both the corner and the face.

Only the faces of the grid cells (on the ground plan) whose box reaches into the view frustum are
drawn, through an index buffer: faces outside the frustum add no pixel, so the images are the same as
drawing every face, at a quarter of the cost on a street view. The cells are drawn nearest first (the
mesh's face order within a cell), so the depth test discards most hidden fragments before they are
shaded; only faces at exactly equal depth in different cells can then show the other one (23 of 179 M
vertex-map pixels on the demo's views).

Cameras (see :mod:`twinkit_segmentation.views`): pinhole, ``hfov_deg`` horizontal field of view,
position and heading/pitch in the site frame (z up).
"""
from __future__ import annotations

import numpy as np

from twinkit.surface.compiled import ahead, compiled

from .viewholes import fill_from_nearest, ground_holes

SKY_RGB = (135, 206, 235)  # "sky blue" background
CELLS = 1024  # about this many grid cells for the frustum test

_VS = """
#version 330
uniform mat4 mvp;
in vec3 in_pos;
in vec2 in_uv;
out vec2 v_uv;
out vec3 v_bary;
flat out uint v_face;
void main() {
    int c = gl_VertexID % 3;
    v_bary = vec3(c == 0 ? 1.0 : 0.0, c == 1 ? 1.0 : 0.0, c == 2 ? 1.0 : 0.0);
    v_uv = in_uv;
    v_face = uint(gl_VertexID / 3);
    gl_Position = mvp * vec4(in_pos, 1.0);
}
"""

_FS = """
#version 330
uniform sampler2D tex;
uniform bool textured;
in vec2 v_uv;
in vec3 v_bary;
flat in uint v_face;
layout(location = 0) out vec4 f_color;
layout(location = 1) out uint f_id;
void main() {
    f_color = textured ? vec4(texture(tex, v_uv).rgb, 1.0) : vec4(0.6, 0.6, 0.6, 1.0);
    uint corner = (v_bary.x >= v_bary.y && v_bary.x >= v_bary.z) ? 0u : (v_bary.y >= v_bary.z ? 1u : 2u);
    f_id = v_face * 3u + corner + 1u;
}
"""


def look_matrix(position, heading_deg: float, pitch_deg: float) -> np.ndarray:
    """World -> camera (OpenGL: x right, y up, looking down -z). Heading: degrees counter-clockwise
    from +x (east); pitch: degrees above the horizon."""
    h, p = np.radians(heading_deg), np.radians(pitch_deg)
    f = np.array([np.cos(h) * np.cos(p), np.sin(h) * np.cos(p), np.sin(p)])
    up = np.array([0.0, 0.0, 1.0])
    r = np.cross(f, up)
    if np.linalg.norm(r) < 1e-6:  # looking straight up or down
        r = np.array([-np.sin(h), np.cos(h), 0.0]) if p < 0 else np.array([np.sin(h), -np.cos(h), 0.0])
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = r, u, -f
    m[:3, 3] = -m[:3, :3] @ np.asarray(position, dtype=np.float64)
    return m


def projection_matrix(hfov_deg: float, width: int, height: int, near: float = 0.05, far: float = 1000.0) -> np.ndarray:
    fx = 1.0 / np.tan(np.radians(hfov_deg) / 2)
    fy = fx * width / height
    m = np.zeros((4, 4))
    m[0, 0], m[1, 1] = fx, fy
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def below_horizon(view_matrix: np.ndarray, proj_matrix: np.ndarray, width: int, height: int) -> np.ndarray:
    """(height, width) bool: the pixel's viewing ray points downwards in the world (z up). Row 0 is the
    top of the image."""
    col = (np.arange(width) + 0.5) / width * 2.0 - 1.0
    row = 1.0 - (np.arange(height) + 0.5) / height * 2.0
    r = np.asarray(view_matrix, dtype=np.float64)[:3, :3]  # world -> camera rotation
    # camera-space ray (x / fx, y / fy, -1); its world z is the third column of r applied to it
    zx = r[0, 2] * col / proj_matrix[0, 0]
    zy = r[1, 2] * row / proj_matrix[1, 1]
    return (zy[:, None] + zx[None, :] - r[2, 2]) < 0.0


def face_cells(vertices: np.ndarray, faces: np.ndarray, cells: int = CELLS):
    """Faces grouped by a grid on the ground plan (about ``cells`` square cells over the mesh's extent):
    (the cell of each face (n,) int32, each cell's box corners (lo, hi), (c, 3) float64). A box holds all
    its faces' corners, grown by a margin that covers float32 rounding in the renderer."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    tri = v[f]  # (n, 3 corners, 3)
    fmin, fmax = tri.min(axis=1), tri.max(axis=1)
    lo0, hi0 = v.min(axis=0), v.max(axis=0)
    side = max(float(np.max(hi0[:2] - lo0[:2])), 1e-9) / max(np.sqrt(cells), 1.0)
    cxy = np.floor((tri[:, :, :2].mean(axis=1) - lo0[:2]) / side).astype(np.int64)
    key = cxy[:, 0] * (int(cxy[:, 1].max(initial=0)) + 1) + cxy[:, 1]
    uniq, cell = np.unique(key, return_inverse=True)
    order = np.argsort(cell, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(cell[order]) != 0])
    margin = 1e-3 * (1.0 + float(np.linalg.norm(hi0 - lo0)))
    lo = np.minimum.reduceat(fmin[order], starts, axis=0) - margin
    hi = np.maximum.reduceat(fmax[order], starts, axis=0) + margin
    return cell.astype(np.int32).reshape(-1), lo, hi


def visible_cells(lo: np.ndarray, hi: np.ndarray, mvp: np.ndarray) -> np.ndarray:
    """(c,) bool: the box reaches into the view frustum of ``mvp`` (world -> clip). A box is out when its
    eight corners lie beyond one clip plane; the test is linear in clip space, so it holds for boxes
    behind the camera too."""
    corners = np.stack([np.where([(k >> a) & 1 for a in range(3)], hi, lo) for k in range(8)], axis=1)
    h = corners @ mvp[:3, :3].T + mvp[:3, 3]  # (c, 8, 3): x, y, z in clip space
    w = corners @ mvp[3, :3] + mvp[3, 3]  # (c, 8)
    out = np.zeros(len(lo), dtype=bool)
    for a in range(3):
        out |= (h[..., a] > w).all(axis=1) | (h[..., a] < -w).all(axis=1)
    return ~out


@ahead("(int32[::1], Array(uint32, 2, 'C', readonly=True), int32[:, ::1])",
       "(int32[::1], uint32[:, ::1], int32[:, ::1])")
def _ids_to_vertices(lut, ids, out):
    """``out`` = ``lut[ids]`` upside down (GL's row 0 is the image's bottom): ``np.take(lut, ids[::-1])``
    in one pass, without the index array numpy makes of the uint32 ids."""
    h, w = ids.shape
    for y in range(h):
        for x in range(w):
            out[h - 1 - y, x] = lut[ids[y, x]]


class Renderer:
    """Keeps the mesh on the (software) GPU; :meth:`render` returns ``(rgb (h,w,3) uint8, vertex (h,w) int32)``
    with ``vertex = -1`` where no geometry was hit; :meth:`vertex_map` draws and returns the vertex map
    only, :meth:`colour` then reads that draw's colours (skipped for a view that is dropped)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, face_uv: np.ndarray | None = None,
                 texture: np.ndarray | None = None, width: int = 1024, height: int = 512,
                 background=SKY_RGB, origin: np.ndarray | None = None, front_to_back: bool = True):
        import moderngl

        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self.width, self.height = int(width), int(height)
        self.background = tuple(c / 255.0 for c in background) + (1.0,)
        # render relative to an origin near the data so float32 keeps millimetres
        self.origin = np.asarray(origin if origin is not None else vertices.mean(axis=0), dtype=np.float64)
        self._lut = np.concatenate([[-1], self.faces.reshape(-1)]).astype(np.int32)  # id -> vertex
        self._cell, self._lo, self._hi = face_cells(vertices, self.faces)
        self._corners = np.arange(3 * len(self.faces), dtype=np.int32).reshape(-1, 3)
        self.front_to_back = bool(front_to_back)
        # the corners grouped by cell (mesh order within a cell): a view draws its cells' runs nearest first
        self._by_cell = self._corners[np.argsort(self._cell, kind="stable")]
        self._cell_start = np.r_[0, np.cumsum(np.bincount(self._cell, minlength=len(self._lo)))]
        self.ctx = moderngl.create_context(standalone=True, backend="egl")
        pos = (vertices[self.faces.reshape(-1)] - self.origin).astype(np.float32)
        textured = face_uv is not None and texture is not None
        uv = face_uv.reshape(-1, 2).astype(np.float32) if textured else np.zeros((len(pos), 2), np.float32)
        self.prog = self.ctx.program(vertex_shader=_VS, fragment_shader=_FS)
        self.prog["textured"].value = bool(textured)
        buf = np.empty(len(pos), dtype=[("p", "f4", 3), ("t", "f4", 2)])
        buf["p"], buf["t"] = pos, uv
        self.vbo = self.ctx.buffer(buf.tobytes())
        self.ibo = self.ctx.buffer(reserve=max(self._corners.nbytes, 4))
        self.vao = self.ctx.vertex_array(self.prog, [(self.vbo, "3f 2f", "in_pos", "in_uv")],
                                         index_buffer=self.ibo, index_element_size=4)
        if textured:
            tex = np.ascontiguousarray(np.flipud(texture[..., :3]))  # image row 0 = v 1
            self.tex = self.ctx.texture((tex.shape[1], tex.shape[0]), 3, tex.tobytes())
            self.tex.build_mipmaps()
            self.tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
            self.tex.anisotropy = 1.0  # anisotropic filtering doubles the cost on llvmpipe
            self.tex.use(0)
            self.prog["tex"].value = 0
        self.color_rb = self.ctx.renderbuffer((self.width, self.height), 4)
        self.id_rb = self.ctx.renderbuffer((self.width, self.height), 1, dtype="u4")
        self.depth_rb = self.ctx.depth_renderbuffer((self.width, self.height))
        self.fbo = self.ctx.framebuffer([self.color_rb, self.id_rb], self.depth_rb)
        self._fbo_colour = self.ctx.framebuffer([self.color_rb])  # cleared to the background colour
        self._fbo_ids = self.ctx.framebuffer([self.id_rb], self.depth_rb)  # cleared to 0 and far depth
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.drawn_faces = 0  # faces drawn by the last draw (those of the cells in its frustum)

    def vertex_map(self, view_matrix: np.ndarray, proj_matrix: np.ndarray) -> np.ndarray:
        """Draw the view; (h, w) int32, per pixel the nearest vertex of the hit face, -1 = background."""
        world_mvp = proj_matrix @ view_matrix
        shift = np.eye(4)
        shift[:3, 3] = self.origin
        self.prog["mvp"].write((world_mvp @ shift).astype(np.float32).T.tobytes())  # column-major
        self._fbo_colour.clear(*self.background)
        self._fbo_ids.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self.fbo.use()
        idx = self._draw_order(visible_cells(self._lo, self._hi, world_mvp), view_matrix)
        self.drawn_faces = len(idx)
        if len(idx):
            self.ibo.write(idx)
            self.vao.render(vertices=idx.size)
        w, h = self.width, self.height
        ids = np.frombuffer(self.fbo.read(attachment=1, components=1, dtype="u4"), dtype=np.uint32).reshape(h, w)
        lookup = compiled(_ids_to_vertices)
        if lookup is None:
            return np.take(self._lut, ids[::-1])
        out = np.empty((h, w), np.int32)
        lookup(self._lut, ids, out)
        return out

    def _draw_order(self, visible: np.ndarray, view_matrix: np.ndarray) -> np.ndarray:
        """(k, 3) int32 corner indices of the visible cells' faces: with ``front_to_back`` cell by cell, the
        cell whose box centre is nearest the camera first (fragments hidden by nearer faces are then not
        shaded), else in the mesh's face order."""
        if not self.front_to_back:
            return np.compress(visible.take(self._cell), self._corners, axis=0)
        cells = np.flatnonzero(visible)
        if not len(cells):
            return self._corners[:0]
        eye = np.linalg.inv(view_matrix)[:3, 3]
        centre = (self._lo[cells] + self._hi[cells]) / 2 - eye
        cells = cells[np.argsort(np.einsum("ij,ij->i", centre, centre), kind="stable")]
        s, e = self._cell_start[cells], self._cell_start[cells + 1]
        return np.concatenate([self._by_cell[a:b] for a, b in zip(s.tolist(), e.tolist())])

    def colour(self) -> np.ndarray:
        """(h, w, 3) uint8: the colours of the last draw (the background colour where nothing was hit)."""
        w, h = self.width, self.height
        return np.frombuffer(self.fbo.read(attachment=0, components=3), dtype=np.uint8).reshape(h, w, 3)[::-1].copy()

    def render(self, view_matrix: np.ndarray, proj_matrix: np.ndarray):
        """(rgb, vertex) of one view (see :meth:`vertex_map` and :meth:`colour`)."""
        vertex = self.vertex_map(view_matrix, proj_matrix)
        return self.colour(), vertex

    def release(self):
        try:
            self.ctx.release()
        except Exception:
            pass


def load_texture(path) -> np.ndarray:
    from PIL import Image

    Image.MAX_IMAGE_PIXELS = None
    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"))


def write_vertex_map(path, vertex: np.ndarray) -> None:
    """``<view>_vertex.npz``: the (h, w) int32 vertex map as the array ``vertex`` of an npz file
    (``np.load(path)["vertex"]``), deflated at level 1 by :func:`twinkit.deflate.write_npz` (with ISA-L 2 ms a
    view against 6 ms with zipfile's zlib and 19 ms with ``np.savez_compressed``; a sixth of the raw size)."""
    from twinkit.deflate import write_npz

    write_npz(path, 1, vertex=np.asarray(vertex, dtype=np.int32))


def write_view(out_dir, view_id: str, rgb: np.ndarray, vertex: np.ndarray) -> None:
    """A view's two files in ``out_dir``: ``<id>.png`` (zlib level 1, PNG filter Sub, run-length matches:
    :func:`twinkit.surface.texture.write_png`) and ``<id>_vertex.npz``."""
    from pathlib import Path

    from twinkit.surface.texture import write_png

    write_png(Path(out_dir) / f"{view_id}.png", rgb, row_filter="sub", rle=True)
    write_vertex_map(Path(out_dir) / f"{view_id}_vertex.npz", vertex)


class ViewWriter:
    """Writes views' files on one background thread (PNG and deflate encoders release the GIL, so they run
    while the next view is drawn); at most ``depth`` views wait. Use as a context manager: leaving it
    waits for every write and raises the first error."""

    def __init__(self, out_dir, depth: int = 2):
        from concurrent.futures import ThreadPoolExecutor

        self.out_dir, self.depth = out_dir, depth
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="view-writer")
        self._pending: list = []

    def put(self, view_id: str, rgb: np.ndarray, vertex: np.ndarray) -> None:
        """Queue a view's files (the arrays must not change afterwards)."""
        while len(self._pending) >= self.depth:
            self._pending.pop(0).result()
        self._pending.append(self._pool.submit(write_view, self.out_dir, view_id, rgb, vertex))

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        try:
            for f in self._pending:
                f.result()
        finally:
            self._pool.shutdown(wait=True)
        return False


def signal_std(rgb: np.ndarray, on: np.ndarray) -> float:
    """Standard deviation of the grey level (mean of R, G, B, float32) over the ``on`` pixels; 0 if none."""
    if not on.any():
        return 0.0
    total = rgb[..., 0].astype(np.uint16)
    total += rgb[..., 1]
    total += rgb[..., 2]
    grey = total[on].astype(np.float32) / np.float32(3)
    return float(grey.std())


def render_view_set(mesh, tex, views: list, out_dir, max_empty_fraction: float, ctx,
                    fill_holes: bool = True, max_hole_px: float = 16.0):
    """Render sampled views (views.json records) into ``out_dir``, holes in the ground filled (see
    ``RenderParams``); (kept, dropped, render seconds, hole pixels of the kept views). A view is dropped
    on its vertex map alone (more than ``max_empty_fraction`` background), before its colours are read."""
    import time

    from twinkit_segmentation.views import view_matrices

    renderers: dict = {}
    kept, dropped = [], []
    t_render = 0.0
    hole_px = 0
    try:
        with ViewWriter(out_dir) as writer:
            for v in ctx.progress(views, total=len(views), desc="render"):
                size = (int(v["width"]), int(v["height"]))
                if size not in renderers:
                    renderers[size] = Renderer(mesh.vertices, mesh.faces, mesh.corner_uv, tex, *size)
                r = renderers[size]
                vm, pm = view_matrices(v)
                t1 = time.perf_counter()
                vertex = r.vertex_map(vm, pm)
                hit = vertex >= 0
                empty = (hit.size - int(np.count_nonzero(hit))) / hit.size
                if empty > max_empty_fraction:
                    t_render += time.perf_counter() - t1
                    dropped.append({"id": v["id"], "empty_fraction": round(empty, 4)})
                    continue
                rgb = r.colour()
                t_render += time.perf_counter() - t1
                hole_mask = ground_holes(hit, below_horizon(vm, pm, *size), max_hole_px)
                holes = int(np.count_nonzero(hole_mask))
                hole_px += holes
                if fill_holes:
                    fill_from_nearest(rgb, hole_mask, hit)
                writer.put(v["id"], rgb, vertex)
                kept.append(dict(v, empty_fraction=round(empty, 4), hole_fraction=round(holes / vertex.size, 4),
                                 signal_std=round(signal_std(rgb, hit), 2)))
    finally:
        for r in renderers.values():
            r.release()
    return kept, dropped, t_render, hole_px


def view_signal(kept: list, min_std: float, max_blank_share: float, ctx) -> dict:
    """How much the kept views show (their ``signal_std``); too many blank views: degraded, with a hint."""
    stds = np.array([float(v.get("signal_std", 0.0)) for v in kept])
    if not len(stds):
        return {}
    blank = float((stds < min_std).mean())
    out = {"signal_std_median": round(float(np.median(stds)), 2), "blank_views": int((stds < min_std).sum()),
           "blank_share": round(blank, 4)}
    if blank > max_blank_share:
        ctx.degraded(f"{100 * blank:.0f} % of the {len(stds)} views are blank (grey level varies by less than "
                     f"{min_std:g} over the mesh; median {out['signal_std_median']:g}): the 2D labels cannot be trusted",
                     "a cloud without colours: keep bake_texture colourless at auto (intensity or shaded), "
                     "not grey; else check the texture (docs/pointcloud.md 'Clouds without colour')")
    elif blank > 0.2:
        ctx.log.warning("%.0f %% of the %d views are nearly blank (grey level std < %g)", 100 * blank, len(stds),
                        min_std)
    return out


def per_sampler(kept: list) -> dict:
    """The kept views counted per sampler ({sampler: views})."""
    per: dict = {}
    for v in kept:
        per[v["sampler"]] = per.get(v["sampler"], 0) + 1
    return per

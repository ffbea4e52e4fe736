"""Unlit textured rendering of a mesh plus a per-pixel map to the nearest vertex (moderngl, headless EGL).

One draw call per view writes two images: the texture colour (sky-blue background) and,
per pixel, ``4 * (face + 1) + corner`` where ``corner`` (0..2) is the triangle corner with
the largest (perspective-correct) barycentric coordinate, i.e. the nearest vertex of the
hit triangle. ``vertex = faces[face, corner]``; 0 = background. No geometry shader is
needed: the mesh is drawn unindexed (3 vertices per face), the corner index comes from
``gl_VertexID % 3`` and the face from ``gl_PrimitiveID``.

Cameras (see :mod:`twinkit_segmentation.views`): pinhole, ``hfov_deg`` horizontal field of view,
position and heading/pitch in the site frame (z up).
"""
from __future__ import annotations

import numpy as np

SKY_RGB = (135, 206, 235)  # "sky blue" background

_VS = """
#version 330
uniform mat4 mvp;
in vec3 in_pos;
in vec2 in_uv;
out vec2 v_uv;
out vec3 v_bary;
void main() {
    int c = gl_VertexID % 3;
    v_bary = vec3(c == 0 ? 1.0 : 0.0, c == 1 ? 1.0 : 0.0, c == 2 ? 1.0 : 0.0);
    v_uv = in_uv;
    gl_Position = mvp * vec4(in_pos, 1.0);
}
"""

_FS = """
#version 330
uniform sampler2D tex;
uniform bool textured;
in vec2 v_uv;
in vec3 v_bary;
layout(location = 0) out vec4 f_color;
layout(location = 1) out uint f_id;
void main() {
    f_color = textured ? vec4(texture(tex, v_uv).rgb, 1.0) : vec4(0.6, 0.6, 0.6, 1.0);
    uint corner = (v_bary.x >= v_bary.y && v_bary.x >= v_bary.z) ? 0u : (v_bary.y >= v_bary.z ? 1u : 2u);
    f_id = uint(gl_PrimitiveID + 1) * 4u + corner;
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


def ground_holes(hit: np.ndarray, below: np.ndarray, max_gap_px: float) -> np.ndarray:
    """Background pixels that are holes in the mesh: below the horizon (a street has ground under every
    downward ray, so it is never sky there) and inside a gap of the surface at most ``2 * max_gap_px``
    wide in some direction (a morphological closing of the hit mask). Wider background below the
    horizon is the world past the capture's edge and is left alone."""
    from scipy.ndimage import distance_transform_edt

    if hit.all() or not hit.any():
        return np.zeros_like(hit)
    grown = distance_transform_edt(~hit) <= max_gap_px
    closed = distance_transform_edt(grown) > max_gap_px  # erode the grown mask back
    return closed & ~hit & below


def fill_from_nearest(rgb: np.ndarray, holes: np.ndarray, hit: np.ndarray) -> int:
    """Paint ``holes`` pixels (in place) with the colour of the nearest ``hit`` pixel; returns how many."""
    n = int(holes.sum())
    if n == 0 or not hit.any():
        return 0
    from scipy.ndimage import distance_transform_edt

    _, (iy, ix) = distance_transform_edt(~hit, return_indices=True)
    rgb[holes] = rgb[iy[holes], ix[holes]]
    return n


class Renderer:
    """Keeps the mesh on the (software) GPU; :meth:`render` returns ``(rgb (h,w,3) uint8, vertex (h,w) int32)``
    with ``vertex = -1`` where no geometry was hit."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, face_uv: np.ndarray | None = None,
                 texture: np.ndarray | None = None, width: int = 1024, height: int = 512,
                 background=SKY_RGB, origin: np.ndarray | None = None):
        import moderngl

        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self.width, self.height = int(width), int(height)
        self.background = tuple(c / 255.0 for c in background) + (1.0,)
        # render relative to an origin near the data so float32 keeps millimetres
        self.origin = np.asarray(origin if origin is not None else vertices.mean(axis=0), dtype=np.float64)
        self.ctx = moderngl.create_context(standalone=True, backend="egl")
        pos = (vertices[self.faces.reshape(-1)] - self.origin).astype(np.float32)
        textured = face_uv is not None and texture is not None
        uv = face_uv.reshape(-1, 2).astype(np.float32) if textured else np.zeros((len(pos), 2), np.float32)
        self.prog = self.ctx.program(vertex_shader=_VS, fragment_shader=_FS)
        self.prog["textured"].value = bool(textured)
        buf = np.empty(len(pos), dtype=[("p", "f4", 3), ("t", "f4", 2)])
        buf["p"], buf["t"] = pos, uv
        self.vbo = self.ctx.buffer(buf.tobytes())
        self.vao = self.ctx.vertex_array(self.prog, [(self.vbo, "3f 2f", "in_pos", "in_uv")])
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
        self.ctx.enable(moderngl.DEPTH_TEST)

    def render(self, view_matrix: np.ndarray, proj_matrix: np.ndarray):
        shift = np.eye(4)
        shift[:3, 3] = self.origin
        mvp = (proj_matrix @ view_matrix @ shift).astype(np.float32)
        self.prog["mvp"].write(mvp.T.tobytes())  # column-major
        self.fbo.use()
        # clears every attachment (the id image to 0); the background colour is painted on the CPU
        self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self.vao.render()
        w, h = self.width, self.height
        ids = np.frombuffer(self.fbo.read(attachment=1, components=1, dtype="u4"), dtype=np.uint32).reshape(h, w)
        rgb = np.frombuffer(self.fbo.read(attachment=0, components=3), dtype=np.uint8).reshape(h, w, 3)
        ids = np.flipud(ids)
        rgb = np.flipud(rgb).copy()
        hit = ids > 0
        face = (ids.astype(np.int64) >> 2) - 1
        corner = ids & 3
        vertex = np.full((h, w), -1, dtype=np.int32)
        vertex[hit] = self.faces[face[hit], corner[hit]]
        rgb[~hit] = np.array([int(round(c * 255)) for c in self.background[:3]], dtype=np.uint8)
        return rgb, vertex

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


def render_view_set(mesh, tex, views: list, out_dir, max_empty_fraction: float, ctx,
                     fill_holes: bool = True, max_hole_px: float = 16.0):
    """Render sampled views (views.json records) into ``out_dir``, holes in the ground filled (see
    ``RenderParams``); (kept, dropped, render seconds, hole pixels of the kept views)."""
    import time
    from pathlib import Path

    from PIL import Image

    from twinkit_segmentation.views import view_matrices

    out_dir = Path(out_dir)

    renderers: dict = {}
    kept, dropped = [], []
    t_render = 0.0
    hole_px = 0
    try:
        for v in ctx.progress(views, total=len(views), desc="render"):
            size = (int(v["width"]), int(v["height"]))
            if size not in renderers:
                renderers[size] = Renderer(mesh.vertices, mesh.faces, mesh.corner_uv, tex, *size)
            r = renderers[size]
            vm, pm = view_matrices(v)
            t1 = time.perf_counter()
            rgb, vertex = r.render(vm, pm)
            t_render += time.perf_counter() - t1
            empty = float((vertex < 0).mean())
            if empty > max_empty_fraction:
                dropped.append({"id": v["id"], "empty_fraction": round(empty, 4)})
                continue
            hole_mask = ground_holes(vertex >= 0, below_horizon(vm, pm, *size), max_hole_px)
            holes = int(hole_mask.sum())
            hole_px += holes
            if fill_holes:
                fill_from_nearest(rgb, hole_mask, vertex >= 0)
            Image.fromarray(rgb).save(out_dir / f"{v['id']}.png", compress_level=1)
            np.savez_compressed(out_dir / f"{v['id']}_vertex.npz", vertex=vertex)
            on = vertex >= 0
            signal = float(rgb[on].astype(np.float32).mean(axis=1).std()) if on.any() else 0.0
            kept.append(dict(v, empty_fraction=round(empty, 4), hole_fraction=round(holes / vertex.size, 4),
                             signal_std=round(signal, 2)))
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

"""A small triangle-mesh builder: textured, labelled primitives in the site frame.

Every primitive owns its vertices (no vertex is shared between two primitives),
so a vertex's label is the label of all its faces. UVs are atlas coordinates
(OBJ convention: v up) produced by :meth:`textures.Atlas.uv`.

The finished mesh is a :class:`twinkit.mesh.Mesh` (site frame, metres, z up): ``vertices`` (n, 3) float64,
``faces`` (m, 3) int64, ``attrs["uv"]`` (n, 2) float64 atlas UV, ``attrs["label"]`` (n,) uint8 and
``face_attrs["label"]`` (m,) uint8 CityScapes trainIds.
"""
from __future__ import annotations

import math

import numpy as np

from twinkit.mesh import Mesh
from twinkit_demo_site.textures import Atlas


MAX_ASPECT = 6.0


def _unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


def _splits(length: float, period: float, phase: float) -> np.ndarray:
    """Cut positions in [0, length] at every multiple of ``period`` (shifted by ``phase``)."""
    k0 = math.floor((0 + phase) / period) + 1
    k1 = math.ceil((length + phase) / period) - 1
    cuts = [k * period - phase for k in range(k0, k1 + 1)]
    cuts = [c for c in cuts if 1e-6 < c < length - 1e-6]
    return np.array([0.0] + cuts + [length])


class MeshBuilder:
    def __init__(self, atlas: Atlas):
        self.atlas = atlas
        self._v: list[np.ndarray] = []
        self._uv: list[np.ndarray] = []
        self._f: list[np.ndarray] = []
        self._l: list[np.ndarray] = []
        self._n = 0

    # ------------------------------------------------------------ raw
    def add(self, verts, st, faces, material: str, label: int) -> None:
        """Add triangles; ``st`` are tile-local texture coordinates in [0, 1]."""
        verts = np.asarray(verts, np.float64).reshape(-1, 3)
        faces = np.asarray(faces, np.int64).reshape(-1, 3)
        self._v.append(verts)
        self._uv.append(self.atlas.uv(material, np.asarray(st, np.float64).reshape(-1, 2)))
        self._f.append(faces + self._n)
        self._l.append(np.full(len(faces), label, np.uint8))
        self._n += len(verts)

    def finish(self) -> Mesh:
        v = np.concatenate(self._v)
        f = np.concatenate(self._f)
        fl = np.concatenate(self._l)
        vl = np.zeros(len(v), np.uint8)
        vl[f.ravel()] = np.repeat(fl, 3)
        return Mesh(vertices=v, faces=f, attrs={"uv": np.concatenate(self._uv), "label": vl}, face_attrs={"label": fl})

    # ------------------------------------------------------------ quads
    def quad(self, p0, eu, ev, lu: float, lv: float, material: str, label: int,
             st0=(0.0, 0.0), st1=(1.0, 1.0)) -> None:
        """One rectangle p0 + a*eu + b*ev (a in [0, lu], b in [0, lv]); front side is eu x ev.

        Long thin rectangles are cut into pieces of aspect <= MAX_ASPECT (sliver triangles make
        float32 closest-point queries imprecise by centimetres).
        """
        p0, eu, ev = (np.asarray(a, np.float64) for a in (p0, eu, ev))
        nu = int(min(64, max(1, math.ceil(lu / (MAX_ASPECT * lv))))) if lv > 0 else 1
        nv = int(min(64, max(1, math.ceil(lv / (MAX_ASPECT * lu))))) if lu > 0 else 1
        a = np.linspace(0, 1, nu + 1)
        b = np.linspace(0, 1, nv + 1)
        A, B = np.meshgrid(a, b)  # (nv+1, nu+1)
        verts = p0 + (A * lu)[..., None] * eu + (B * lv)[..., None] * ev
        st = np.stack([st0[0] + A * (st1[0] - st0[0]), st0[1] + B * (st1[1] - st0[1])], -1)
        idx = np.arange((nu + 1) * (nv + 1)).reshape(nv + 1, nu + 1)
        q0, q1, q2, q3 = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
        faces = np.concatenate([np.stack([q0, q1, q2], 1), np.stack([q0, q2, q3], 1)])
        self.add(verts.reshape(-1, 3), st.reshape(-1, 2), faces, material, label)

    def tiled_rect(self, p0, eu, ev, lu: float, lv: float, material: str, label: int,
                   period_u: float, period_v: float, phase_u: float = 0.0, phase_v: float = 0.0,
                   material_fn=None) -> None:
        """Rectangle cut into cells at texture-period boundaries, each cell mapped into the tile.

        ``phase_*`` is the texture coordinate (metres) at ``p0``, so neighbouring
        rectangles with consistent phases show a continuous texture.
        ``material_fn(i, j) -> str`` may choose the tile per cell (facade floors).
        """
        p0, eu, ev = (np.asarray(a, np.float64) for a in (p0, eu, ev))
        cu = _splits(lu, period_u, phase_u)
        cv = _splits(lv, period_v, phase_v)
        for j in range(len(cv) - 1):
            for i in range(len(cu) - 1):
                a0, a1, b0, b1 = cu[i], cu[i + 1], cv[j], cv[j + 1]
                ku = math.floor((a0 + a1) / 2 / period_u + phase_u / period_u)
                kv = math.floor((b0 + b1) / 2 / period_v + phase_v / period_v)
                s0 = (a0 + phase_u) / period_u - ku
                s1 = (a1 + phase_u) / period_u - ku
                t0 = (b0 + phase_v) / period_v - kv
                t1 = (b1 + phase_v) / period_v - kv
                mat = material_fn(i, j) if material_fn else material
                self.quad(p0 + eu * a0 + ev * b0, eu, ev, a1 - a0, b1 - b0, mat, label, (s0, t0), (s1, t1))

    def box(self, lo, hi, label: int, material, period: float | None = None, bottom: bool = False) -> None:
        """Axis-aligned box; ``material`` is a name or a dict face->name (faces: +x -x +y -y top bottom).

        With ``period`` the sides tile the texture every ``period`` metres; else each face maps the whole tile.
        """
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        d = hi - lo

        def m(k):
            return material.get(k, material.get("side")) if isinstance(material, dict) else material

        X, Y, Z = np.eye(3)
        faces = [
            ("+x", [hi[0], lo[1], lo[2]], Y, Z, d[1], d[2]),
            ("-x", [lo[0], hi[1], lo[2]], -Y, Z, d[1], d[2]),
            ("+y", [hi[0], hi[1], lo[2]], -X, Z, d[0], d[2]),
            ("-y", [lo[0], lo[1], lo[2]], X, Z, d[0], d[2]),
            ("top", [lo[0], lo[1], hi[2]], X, Y, d[0], d[1]),
        ]
        if bottom:
            faces.append(("bottom", [lo[0], hi[1], lo[2]], X, -Y, d[0], d[1]))
        for k, p0, eu, ev, lu, lv in faces:
            if lu <= 0 or lv <= 0:
                continue
            if period:
                self.tiled_rect(p0, eu, ev, lu, lv, m(k), label, period, period)
            else:
                self.quad(p0, eu, ev, lu, lv, m(k), label)

    def oriented_box(self, center, size, yaw: float, label: int, material, z0: float = 0.0,
                     top_scale: float = 1.0) -> None:
        """Box (or frustum with ``top_scale`` < 1) of ``size`` (length, width, height) rotated by ``yaw`` about z.

        ``material``: dict with keys front (+length), rear, left (+width), right, top, or one name.
        Each face maps the whole tile (s along the face's horizontal direction, t up).
        """
        L, W, Hh = size
        c, s = math.cos(yaw), math.sin(yaw)
        fx, fy = np.array([c, s, 0.0]), np.array([-s, c, 0.0])
        base = np.array([center[0], center[1], z0])
        corners = []
        for zz, sc in ((0.0, 1.0), (Hh, top_scale)):
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                la = L / 2 * (sc if zz else 1.0)
                corners.append(base + fx * a * la + fy * b * W / 2 * sc + np.array([0, 0, zz]))
        C = np.array(corners)
        mats = material if isinstance(material, dict) else {k: material for k in ("front", "rear", "left", "right", "top")}
        quads = {  # (bottom-left, bottom-right, top-right, top-left) seen from outside
            "right": (0, 1, 5, 4), "front": (1, 2, 6, 5), "left": (2, 3, 7, 6), "rear": (3, 0, 4, 7), "top": (4, 5, 6, 7),
        }
        for k, (a, b, cc, dd) in quads.items():
            self.add(C[[a, b, cc, dd]], [(0, 0), (1, 0), (1, 1), (0, 1)], [[0, 1, 2], [0, 2, 3]], mats[k], label)

    # ------------------------------------------------------------ round things
    def cylinder(self, p0, p1, r0: float, r1: float, label: int, material: str, segments: int = 12,
                 cap: bool = True, v_period: float | None = None) -> None:
        """Truncated cone from p0 (radius r0) to p1 (radius r1); texture s around, t along."""
        p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
        ax = p1 - p0
        h = np.linalg.norm(ax)
        a = ax / h
        ref = np.array([0, 0, 1.0]) if abs(a[2]) < 0.9 else np.array([1.0, 0, 0])
        e1 = _unit(np.cross(a, ref))
        e2 = np.cross(a, e1)
        ang = np.linspace(0, 2 * np.pi, segments + 1)
        ring = np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2
        tmax = min(h / v_period, 1.0) if v_period else 1.0
        seg_w = 2 * np.pi * max(r0, r1) / segments
        nh = int(min(200, max(1, math.ceil(h / (MAX_ASPECT * seg_w)))))
        n = segments + 1
        verts, st, f = [], [], []
        for k in range(nh + 1):
            a_ = k / nh
            verts.append(p0 + ax * a_ + (r0 + (r1 - r0) * a_) * ring)
            st.append(np.stack([ang / (2 * np.pi), np.full_like(ang, a_ * tmax)], 1))
        for k in range(nh):
            b0 = k * n
            f += [[b0 + i, b0 + i + 1, b0 + n + i + 1] for i in range(segments)]
            f += [[b0 + i, b0 + n + i + 1, b0 + n + i] for i in range(segments)]
        self.add(np.concatenate(verts), np.concatenate(st), f, material, label)
        if cap:
            for p, r, flip in ((p1, r1, False), (p0, r0, True)):
                if r <= 0:
                    continue
                rv = p + r * ring[:-1]
                verts = np.concatenate([p[None], rv])
                st = np.concatenate([[[0.5, 0.5]], 0.5 + 0.5 * np.stack([np.cos(ang[:-1]), np.sin(ang[:-1])], 1)])
                f = [[0, 1 + i, 1 + (i + 1) % segments] for i in range(segments)]
                if flip:
                    f = [[a_, c_, b_] for a_, b_, c_ in f]
                self.add(verts, st, f, material, label)

    def ring(self, center, axis, radius: float, tube: float, label: int, material: str,
             segments: int = 20, tube_segments: int = 6) -> None:
        """Torus (wheel tyre) around ``axis``."""
        c = np.asarray(center, float)
        a = _unit(axis)
        ref = np.array([0, 0, 1.0]) if abs(a[2]) < 0.9 else np.array([1.0, 0, 0])
        e1 = _unit(np.cross(a, ref))
        e2 = np.cross(a, e1)
        verts, st = [], []
        for i in range(segments):
            th = 2 * np.pi * i / segments
            rad = math.cos(th) * e1 + math.sin(th) * e2
            for j in range(tube_segments):
                ph = 2 * np.pi * j / tube_segments
                verts.append(c + rad * (radius + tube * math.cos(ph)) + a * tube * math.sin(ph))
                st.append((0.05 + 0.1 * j / tube_segments, 0.05 + 0.1 * i / segments))
        f = []
        for i in range(segments):
            for j in range(tube_segments):
                p = i * tube_segments + j
                q = ((i + 1) % segments) * tube_segments + j
                p2 = i * tube_segments + (j + 1) % tube_segments
                q2 = ((i + 1) % segments) * tube_segments + (j + 1) % tube_segments
                f += [[p, q, q2], [p, q2, p2]]
        self.add(verts, st, f, material, label)

    def blob(self, center, radii, rng: np.random.Generator, label: int, material: str,
             subdiv: int = 2, roughness: float = 0.18, tex_size_m: float = 2.0) -> None:
        """Irregular closed blob (tree crown, bush): a noisy ellipsoid from a subdivided icosahedron.

        Each triangle gets its own planar patch of the tile (foliage hides the seams).
        """
        v, f = _icosphere(subdiv)
        # smooth random displacement: a few random low-frequency bumps
        disp = np.zeros(len(v))
        for _ in range(6):
            d = _unit(rng.standard_normal(3))
            disp += rng.uniform(0.3, 1.0) * np.exp(-((1 - v @ d) / 0.35) ** 2)
        disp += 0.3 * rng.standard_normal(len(v))
        disp = 1 + roughness * (disp - disp.mean()) / (disp.std() + 1e-9)
        P = np.asarray(center, float) + v * disp[:, None] * np.asarray(radii, float)
        tri = P[f]  # (m, 3, 3)
        e1 = tri[:, 1] - tri[:, 0]
        e2 = tri[:, 2] - tri[:, 0]
        nrm = np.cross(e1, e2)
        nrm /= np.linalg.norm(nrm, axis=1, keepdims=True) + 1e-12
        ax = e1 / (np.linalg.norm(e1, axis=1, keepdims=True) + 1e-12)
        ay = np.cross(nrm, ax)
        rel = tri - tri[:, :1]
        s = np.einsum("mkd,md->mk", rel, ax) / tex_size_m
        t = np.einsum("mkd,md->mk", rel, ay) / tex_size_m
        s -= s.min(1, keepdims=True)
        t -= t.min(1, keepdims=True)
        span = np.maximum(s.max(1), t.max(1))
        scale = np.where(span > 0.98, 0.98 / np.maximum(span, 1e-9), 1.0)
        s *= scale[:, None]
        t *= scale[:, None]
        off = rng.random((len(f), 2)) * (1 - np.maximum(s.max(1), t.max(1)))[:, None]
        st = np.stack([s + off[:, :1], t + off[:, 1:]], -1).reshape(-1, 2)
        self.add(tri.reshape(-1, 3), st, np.arange(len(f) * 3).reshape(-1, 3), material, label)

    def prism(self, outline2d, origin, eu, ev, thickness: float, label: int, front: str, back: str) -> None:
        """A thin plate: convex polygon ``outline2d`` (k, 2) in [0, 1]^2 of the plate plane
        (p = origin + x*eu + y*ev, eu/ev scaled to the plate size), extruded by ``thickness``
        along eu x ev. Front shows the tile mapped by the outline coordinates."""
        o = np.asarray(origin, float)
        eu, ev = np.asarray(eu, float), np.asarray(ev, float)
        nrm = _unit(np.cross(eu, ev))
        q = np.asarray(outline2d, float)
        k = len(q)
        pf = o + q[:, :1] * eu + q[:, 1:] * ev + nrm * thickness / 2
        pb = pf - nrm * thickness
        fan = [[0, i, i + 1] for i in range(1, k - 1)]
        self.add(pf, q, fan, front, label)
        self.add(pb, q, [[a, c, b] for a, b, c in fan], back, label)
        sv, sst, sf = [], [], []
        for i in range(k):
            j = (i + 1) % k
            base = len(sv)
            sv += [pf[i], pf[j], pb[j], pb[i]]
            sst += [(0.1, 0.1), (0.2, 0.1), (0.2, 0.2), (0.1, 0.2)]
            sf += [[base, base + 2, base + 1], [base, base + 3, base + 2]]
        self.add(sv, sst, sf, back, label)


def _icosphere(subdiv: int):
    t = (1 + 5 ** 0.5) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6),
         (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10),
         (8, 6, 7), (9, 8, 1)]
    v = [np.array(p, float) / np.linalg.norm(p) for p in v]
    for _ in range(subdiv):
        cache = {}
        nf = []

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = v[a] + v[b]
                v.append(m / np.linalg.norm(m))
                cache[key] = len(v) - 1
            return cache[key]

        for a, b, c in f:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            nf += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        f = nf
    return np.array(v), np.array(f)

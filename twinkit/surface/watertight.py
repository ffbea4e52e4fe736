"""How whole is the ground: open border inside the scanned site, and a drop test the way a simulator sees it.

- :class:`Footprint`: the area the scan covers, seen from above. Cells of ``cell_m`` that hold a point,
  closed over gaps up to ``fill_limit_m`` wide (the ground fill's limit: a hole narrower than that is
  inside the site, a wider one is where the scan ends) and shrunk by ``margin_m`` so that the scan's own
  edge is outside.
- :func:`ground_border`: the mesh's open border (edges with one face) at ground level, split into the
  part inside the footprint (cracks and holes) and the part on the site's edge, with lengths, loop
  sizes and the edges themselves for a picture (:func:`draw_border`).
- :func:`drop_test`: vertical rays at given sample points (x, y, expected height); a ray passes when
  the mesh crosses its vertical line within ``tol_m`` of the expected height.
- :class:`OpenGround`: ground the scan never measured, seen from above (uncovered and open to the mesh's
  border, or wider than a hole later steps close): a lane there has nothing under it by the capture's nature.

Units: metres, site frame (z up).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .compiled import ahead


@dataclass
class Footprint:
    mask: np.ndarray  # (ny, nx) bool, True inside the site
    lo: np.ndarray  # (2,) lower-left corner of cell (0, 0)
    cell_m: float

    @classmethod
    def from_points(cls, xy: np.ndarray, fill_limit_m: float = 8.0, cell_m: float = 0.5,
                    margin_m: float = 1.0) -> "Footprint":
        from scipy import ndimage as ndi

        xy = np.asarray(xy, np.float64)[:, :2]
        if len(xy) == 0:
            return cls(np.zeros((1, 1), bool), np.zeros(2), cell_m)
        pad = fill_limit_m + 2 * cell_m
        lo = xy.min(axis=0) - pad
        ij = np.floor((xy - lo) / cell_m).astype(np.int64)
        shape = (int(ij[:, 1].max()) + int(pad / cell_m) + 2, int(ij[:, 0].max()) + int(pad / cell_m) + 2)
        occ = np.zeros(shape, bool)
        occ[ij[:, 1], ij[:, 0]] = True
        r = max(1, int(round(fill_limit_m / 2 / cell_m)))
        box = np.ones((3, 3), bool)
        fp = ndi.binary_closing(occ, structure=box, iterations=r)
        fp = ndi.binary_fill_holes(fp)
        k = int(round(margin_m / cell_m))
        if k > 0:
            fp = ndi.binary_erosion(fp, structure=box, iterations=k)
        return cls(fp, lo, float(cell_m))

    def inside(self, xy: np.ndarray) -> np.ndarray:
        ij = np.floor((np.asarray(xy)[:, :2] - self.lo) / self.cell_m).astype(np.int64)
        ny, nx = self.mask.shape
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < nx) & (ij[:, 1] >= 0) & (ij[:, 1] < ny)
        out = np.zeros(len(ij), bool)
        out[ok] = self.mask[ij[ok, 1], ij[ok, 0]]
        return out

    def area_m2(self) -> float:
        return float(self.mask.sum() * self.cell_m ** 2)


#: seen from above, a channel of uncovered ground narrower than this (a slit along a sweep's ring, a crack at a
#: kerb's foot) does not join an enclosed hole to the land outside the scan (:class:`OpenGround`), m
OPEN_CHANNEL_M = 0.5


@dataclass
class OpenGround:
    """Ground the scan never measured, seen from above, that no later step will cover: the pixels no face
    covers whose uncovered patch reaches the mesh's outer border or spans more than ``open_gap_m`` (the far
    range between a sweep's rings, land beyond the scan's edge, a shadow open to it). An enclosed patch up to
    ``open_gap_m`` (a parked car's shadow, a slit along a ring) is a hole of the mesh, which ``lift_movables``
    closes. Patches are told apart with their channels narrower than :data:`OPEN_CHANNEL_M` shut. Grid:
    :mod:`twinkit.mesh.raster`'s (``x0, y0`` the top-left corner, ``res`` metres per pixel)."""

    mask: np.ndarray  # (h, w) bool, True where the ground was never measured
    x0: float
    y0: float
    res: float

    @classmethod
    def of_mesh(cls, vertices: np.ndarray, faces: np.ndarray, open_gap_m: float = 8.0, cell_m: float = 0.1,
                max_px: int = 4000) -> "OpenGround":
        """Of a mesh's ``faces`` (those that stay: leave out what a later step removes) on a ``cell_m`` grid,
        coarser where the mesh is more than ``max_px`` cells across."""
        from scipy import ndimage

        from twinkit.mesh.raster import face_mask

        xy = np.asarray(vertices, np.float64)[:, :2]
        faces = np.asarray(faces, np.int64).reshape(-1, 3)
        if len(xy) == 0:
            return cls(np.zeros((1, 1), bool), 0.0, 0.0, cell_m)
        lo, hi = xy.min(axis=0) - 1.0, xy.max(axis=0) + 1.0
        res = max(cell_m, float(np.max(hi - lo)) / max_px)
        shape = (int(np.ceil((hi[1] - lo[1]) / res)), int(np.ceil((hi[0] - lo[0]) / res)))
        bare = ~face_mask(xy, faces, float(lo[0]), float(hi[1]), res, shape, rule="scanline")
        k = max(1, int(round(OPEN_CHANNEL_M / res / 2)))
        box = np.ones((2 * k + 1, 2 * k + 1), bool)
        lab, n = ndimage.label(ndimage.binary_opening(bare, box))
        wide = np.zeros(n + 1, bool)
        for i, sl in enumerate(ndimage.find_objects(lab), start=1):
            span_m = max(sl[0].stop - sl[0].start, sl[1].stop - sl[1].start) * res
            wide[i] = (span_m > open_gap_m or sl[0].start == 0 or sl[1].start == 0 or sl[0].stop == shape[0]
                       or sl[1].stop == shape[1])
        return cls(bare & ndimage.binary_dilation(wide[lab], box), float(lo[0]), float(hi[1]), res)

    def at(self, xy: np.ndarray) -> np.ndarray:
        """(k,) bool: the points (k, 2+) lie on ground the scan never measured (outside the grid: True)."""
        xy = np.atleast_2d(np.asarray(xy, np.float64))
        col = np.floor((xy[:, 0] - self.x0) / self.res).astype(np.int64)
        row = np.floor((self.y0 - xy[:, 1]) / self.res).astype(np.int64)
        h, w = self.mask.shape
        ok = (col >= 0) & (col < w) & (row >= 0) & (row < h)
        out = np.ones(len(xy), bool)
        out[ok] = self.mask[row[ok], col[ok]]
        return out


def open_edges(faces: np.ndarray) -> np.ndarray:
    """Edges used by exactly one face, (e, 2) vertex ids."""
    from twinkit.mesh.topology import edge_face_incidence

    if len(faces) == 0:
        return np.zeros((0, 2), np.int64)
    edges, _, counts = edge_face_incidence(np.asarray(faces, np.int64))
    return edges[counts == 1]


def chains_of(edges: np.ndarray) -> np.ndarray:
    """Connected chain id per edge (edges sharing a vertex belong to one chain)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if len(edges) == 0:
        return np.zeros(0, np.int64)
    ids, inv = np.unique(edges, return_inverse=True)
    inv = inv.reshape(-1, 2)
    g = coo_matrix((np.ones(len(inv)), (inv[:, 0], inv[:, 1])), shape=(len(ids), len(ids)))
    _, lab = connected_components(g, directed=False)
    return lab[inv[:, 0]]


def ground_border(vertices: np.ndarray, faces: np.ndarray, footprint: Footprint, ground_vertex: np.ndarray,
                  ground_area_m2: float | None = None) -> dict:
    """Open border of the ground: edges with one face whose two vertices are ground (``ground_vertex``,
    (n,) bool: by label, or by height above the local ground), split by the footprint. Returns metrics
    (lengths in m, per m² of ground inside the site, chains by length) and, under ``"_edges"``, the
    inside and edge border as (e, 2) vertex ids for :func:`draw_border` (not JSON)."""
    v = vertices
    e = open_edges(faces)
    e = e[ground_vertex[e].all(axis=1)] if len(e) else e
    mid = v[e].mean(axis=1) if len(e) else np.zeros((0, 3))
    ins = footprint.inside(mid[:, :2]) if len(e) else np.zeros(0, bool)
    ln = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1) if len(e) else np.zeros(0)
    if ground_area_m2 is None:
        gf = ground_vertex[faces].all(axis=1)
        cen = v[faces[gf]].mean(axis=1)
        a = 0.5 * np.linalg.norm(np.cross(v[faces[gf, 1]] - v[faces[gf, 0]], v[faces[gf, 2]] - v[faces[gf, 0]]),
                                 axis=1)
        ground_area_m2 = float(a[footprint.inside(cen[:, :2])].sum())
    chain = chains_of(e[ins])
    clen = np.bincount(chain, weights=ln[ins]) if len(chain) else np.zeros(0)
    inside_m = float(ln[ins].sum())
    return {
        "inside_m": round(inside_m, 2),
        "site_edge_m": round(float(ln[~ins].sum()), 2),
        "ground_area_m2": round(float(ground_area_m2), 1),
        "inside_m_per_m2": round(inside_m / ground_area_m2, 4) if ground_area_m2 > 0 else None,
        "inside_chains": int(len(clen)),
        "inside_chains_by_length": {"under_0.5m": int((clen < 0.5).sum()),
                                    "0.5_2m": int(((clen >= 0.5) & (clen < 2)).sum()),
                                    "2_10m": int(((clen >= 2) & (clen < 10)).sum()),
                                    "over_10m": int((clen >= 10).sum())},
        "longest_inside_chain_m": round(float(clen.max()), 2) if len(clen) else 0.0,
        "footprint_area_m2": round(footprint.area_m2(), 1),
        "_edges": {"inside": e[ins], "edge": e[~ins]},
    }


def at_ground_level(vertices: np.ndarray, points: np.ndarray, normals: np.ndarray | None,
                    tol_m: float = 0.5) -> np.ndarray:
    """(n,) bool: the ``vertices`` within ``tol_m`` of the cloud's local ground, the lowest of its up-facing
    ``points`` (normal z >= 0.85; none without ``normals``) within 4 m, on a 0.5 m grid
    (:class:`twinkit.street.ground.LocalGround`'s window minimum). False where no up-facing point lies within
    the window."""
    from twinkit.street.ground import LocalGround

    up = normals[:, 2] >= 0.85 if normals is not None else np.zeros(len(points), bool)
    if not up.any():
        return np.zeros(len(vertices), bool)
    g = LocalGround(points[up], cell_m=0.5, window="min", window_m=4.0, min_window_cells=3, cover_xy=vertices[:, :2])
    return np.abs(g.height(vertices)) <= tol_m


def drop_test(vertices: np.ndarray, faces: np.ndarray, samples: np.ndarray, tol_m: float = 0.05,
              threads: int = 0, scene=None) -> np.ndarray:
    """(k,) bool: the mesh crosses the vertical line at each sample (x, y, z) within ``tol_m`` of z. ``scene``:
    the mesh's open3d RaycastingScene when the caller casts several sets of rays on one mesh."""
    import open3d as o3d

    if len(samples) == 0 or len(faces) == 0:
        return np.zeros(len(samples), bool)
    if scene is None:
        from .closest import Surface

        scene = Surface(vertices, faces, threads).scene
    out = np.zeros(len(samples), bool)
    for s in range(0, len(samples), 2_000_000):
        p = samples[s:s + 2_000_000]
        rays = np.zeros((len(p), 6), np.float32)
        rays[:, :2] = p[:, :2]
        rays[:, 2] = p[:, 2] + tol_m
        rays[:, 5] = -1.0
        t = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
        out[s:s + len(p)] = t <= 2 * tol_m
    return out


def ground_share(lane: dict) -> float | None:
    """The figure a lane type's drop-test target is on (its gate), from that lane type's record in
    ``drop_test.json`` (``lanes.<kind>``): the share of rays that find the ground off the kerb line, or over a
    continuous surface, whichever holds more; None without rays."""
    return max((x for x in (lane["hit_pct_off_kerb_line"], lane["continuous_pct"]) if x is not None), default=None)


def draw_border(path: Path, vertices: np.ndarray, faces: np.ndarray, edges: dict, *, ground_face: np.ndarray | None,
                px_per_m: float = 10.0, max_px: int = 3000, title: str = "", misses: np.ndarray | None = None) -> None:
    """Top-down picture: ground faces light grey, other faces darker, open border inside the site red (drawn
    thick), on the site's edge blue; ``misses`` (k, 2) points drawn orange (drop-test rays that fell through)."""
    from PIL import Image, ImageDraw

    from twinkit.surface.compiled import compiled

    v = vertices
    lo, hi = v[:, :2].min(axis=0) - 1.0, v[:, :2].max(axis=0) + 1.0
    s = min(px_per_m, max_px / max(float((hi - lo).max()), 1e-6))
    w, h = (np.ceil((hi - lo) * s).astype(int) + 1)
    img = Image.new("RGB", (int(w), int(h)), (255, 255, 255))
    d = ImageDraw.Draw(img)

    def px(p):
        return np.c_[(p[:, 0] - lo[0]) * s, h - 1 - (p[:, 1] - lo[1]) * s]

    # surfaces splatted at their vertices and face centres (faces are about a pixel at this scale), higher last
    gf = ground_face if ground_face is not None else np.ones(len(faces), bool)
    cen = v[faces].mean(axis=1)
    vg = np.zeros(len(v), bool)
    vg[faces[gf].ravel()] = True
    pts = np.vstack([cen, v])
    col = np.r_[gf, vg]
    arr = np.asarray(img).copy()
    light, dark = np.array([222, 222, 222], np.uint8), np.array([170, 170, 180], np.uint8)  # ground, the rest
    splat = compiled(_splat_highest)
    if splat is not None:
        splat(arr, np.floor(px(pts[:, :2])).astype(np.int64), pts[:, 2], col, light, dark)
    else:
        order = np.argsort(pts[:, 2])
        q = np.floor(px(pts[order, :2])).astype(np.int64)
        ok = (q[:, 0] >= 0) & (q[:, 0] < w) & (q[:, 1] >= 0) & (q[:, 1] < h)
        shade = np.where(col[order][ok, None], light, dark)
        for dx in (-1, 0, 1):  # 3 x 3 splats: no speckle where triangles are larger than a pixel
            for dy in (-1, 0, 1):
                arr[np.clip(q[ok, 1] + dy, 0, h - 1), np.clip(q[ok, 0] + dx, 0, w - 1)] = shade
    img = Image.fromarray(arr.astype(np.uint8))
    d = ImageDraw.Draw(img)
    lw = max(2, int(round(s * 0.15)))
    for key, col, width in (("edge", (40, 90, 230), max(1, lw // 2)), ("inside", (230, 20, 20), lw)):
        ek = np.asarray(edges.get(key, np.zeros((0, 2), np.int64)), np.int64).reshape(-1, 2)
        for a, b in px(v[ek][:, :, :2].reshape(-1, 2)).reshape(-1, 2, 2):
            d.line([tuple(a), tuple(b)], fill=col, width=width)
    if misses is not None and len(misses):
        for q in px(np.asarray(misses)[:, :2]):
            d.rectangle([q[0] - 1, q[1] - 1, q[0] + 1, q[1] + 1], fill=(255, 140, 0))
    if title:
        d.rectangle([0, 0, min(int(w), 9 * len(title) + 10), 18], fill=(255, 255, 255))
        d.text((5, 3), title, fill=(0, 0, 0))
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    img.save(path)


@ahead("(uint8[:, :, ::1], int64[:, ::1], float64[:], boolean[::1], uint8[::1], uint8[::1])",
       "(uint8[:, :, ::1], int64[:, ::1], float64[::1], boolean[::1], uint8[::1], uint8[::1])")
def _splat_highest(arr, q, z, ground, light, dark):
    """Each point (pixel ``q`` (n, 2) x, y; height ``z``) painted over the 3 x 3 pixels around it, the highest point
    over a pixel winning (``draw_border``'s splats, in one pass instead of a sort by height): ``light`` where it is
    ground, else ``dark``. ``arr`` (h, w, 3) uint8, in place."""
    h, w = arr.shape[0], arr.shape[1]
    top = np.full((h, w), -np.inf)
    who = np.full((h, w), -1, np.int64)
    for i in range(q.shape[0]):
        x, y = q[i, 0], q[i, 1]
        if x < 0 or x >= w or y < 0 or y >= h:
            continue
        for dy in range(-1, 2):
            for dx in range(-1, 2):
                yy = min(max(y + dy, 0), h - 1)
                xx = min(max(x + dx, 0), w - 1)
                if z[i] >= top[yy, xx]:
                    top[yy, xx] = z[i]
                    who[yy, xx] = i
    for yy in range(h):
        for xx in range(w):
            i = who[yy, xx]
            if i >= 0:
                c = light if ground[i] else dark
                for k in range(3):
                    arr[yy, xx, k] = c[k]


def ground_border_report(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray, normals: np.ndarray,
                         fill_limit_m: float, png: Path | None, log=None) -> dict | None:
    """A mesh's open border at ground level (within 0.5 m of the local ground, from the cloud's up-facing
    points: the road, the pavement, the foot of cars and walls), inside the scanned site and on its edge;
    with a picture at ``png``. For the steps that make a site mesh (clean_mesh, merge_tiles)."""
    if len(faces) == 0 or normals is None:
        return None
    ground_v = at_ground_level(vertices, points, normals)
    fp = Footprint.from_points(points, fill_limit_m=max(float(fill_limit_m), 1.0))
    rep = ground_border(vertices, faces, fp, ground_v)
    edges = rep.pop("_edges")
    if png is not None:
        draw_border(png, vertices, faces, edges, ground_face=ground_v[faces].all(axis=1),
                    title=f"open border at ground level: {rep['inside_m']:.0f} m inside the site (red), "
                          f"{rep['site_edge_m']:.0f} m on its edge (blue)")
        rep["picture"] = Path(png).name
    if log is not None:
        log.info("open border at ground level: %.1f m inside the site (%.3f m per m^2 of ground, %d chains, "
                 "longest %.1f m), %.1f m on the site's edge", rep["inside_m"], rep["inside_m_per_m2"] or 0.0,
                 rep["inside_chains"], rep["longest_inside_chain_m"], rep["site_edge_m"])
    return rep

"""Per-point geometric features of a scan for the 3D classifier (site frame, metres, z up).

The cloud is first thinned to one point per ``base_voxel_m`` voxel (:func:`voxel_subsample`), so the
features measure the surface, not how densely one scanner happened to sample it. Then, per base point:

- **shape at several scales** (:data:`SCALES_M`): the covariance of the base points in the 3 x 3 x 3 block
  of voxels of side ``s`` around the point's voxel (a cube of side ``3 s``), computed from per-voxel sums
  so that it costs a few sorted look-ups per scale. From its eigenvalues ``l1 >= l2 >= l3``: linearity
  ``(l1 - l2) / l1``, planarity ``(l2 - l3) / l1``, scattering ``l3 / l1``; the absolute z of the normal
  (smallest eigenvector) and of the main direction (largest); the spread ``sqrt(l1) / 3 s``; the point's
  height in the block ``(z - mean z) / 3 s``; the block's fill ``log(count / (3 s / base)^2)`` (a plane
  seen from everywhere fills it to ~0; a sparse far scan line far less); and the roughness
  ``log10 sqrt(l3)`` (metres).
- **ground**: height above the local ground (:class:`twinkit.street.ground.LocalGround`, an opening wide
  enough that car and bus roofs are not ground, over each cell's ``ground_pct``-th percentile of its
  up-facing points rather than its lowest, which range noise pulls down), the point's height above the lowest
  ground within 1.5 m and 5 m (a raised pavement stands above the road beside it), the rise of the highest
  ground within 1.5 m, and against curbs (:meth:`LocalGround.steps`, 6-35 cm): the distance to the nearest
  step's upper edge and the height against it (a pavement ~0, the road beside it ~ -0.12 m), both
  capped at :data:`CURB_REACH_M` (a curb tells nothing about ground farther away, nor does a scan without one).
- **column**: the highest point above the ground in the point's 0.5 m and 2 m ground cells, and the point's
  share of it (a facade's foot sits under 10 m of wall, a car's under 1.5 m).
- **object**: the raised points (> 0.3 m above the ground) joined into connected objects over 0.4 m voxels;
  each raised point gets its object's longer and shorter horizontal extent, top height and size.
- **intensity**: the per-capture percentile rank of the return intensity, its mean over the 3 x 3 x 3 blocks
  of :data:`INTENSITY_SCALES_M` (one return's intensity is noisy; a surface's mean tells asphalt from paving
  and grass), and a flag that the capture had one (0.5 and 0 without).

No feature uses absolute x or y or a sensor position (a real file does not give one).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: voxel sides (m) of the shape features; each looks at a cube of 3 voxels a side.
SCALES_M: tuple[float, ...] = (0.1, 0.25, 0.6, 1.2)
SHAPE_NAMES = ("linearity", "planarity", "scattering", "normal_z", "line_z", "spread", "rel_z", "fill", "rough")
GROUND_NAMES = ("height", "above_low_1m5", "above_low_5m", "ground_rise_1m5", "step_dist", "above_step")
COLUMN_NAMES = ("col_top_0m5", "col_share_0m5", "col_top_2m", "col_share_2m")
OBJECT_NAMES = ("obj_long", "obj_short", "obj_top", "obj_size", "raised")
#: voxel sides (m) of the intensity's block means
INTENSITY_SCALES_M: tuple[float, ...] = (0.25, 0.6)
INTENSITY_NAMES = ("intensity_rank", *(f"intensity_{s:g}" for s in INTENSITY_SCALES_M), "has_intensity")
#: metres: farther from a curb step than this, the curb features read "no curb near"
CURB_REACH_M = 3.0


def feature_names() -> list[str]:
    """The names of the columns of :func:`point_features`' matrix, in order."""
    names = [f"{n}_{s:g}" for s in SCALES_M for n in SHAPE_NAMES]
    return names + list(GROUND_NAMES) + list(COLUMN_NAMES) + list(OBJECT_NAMES) + list(INTENSITY_NAMES)


@dataclass
class Features:
    """Result of :func:`point_features`: ``base`` (m,) int64 index of each base point into the input cloud,
    ``inverse`` (n,) int64 each input point's base point, ``values`` (m, k) float32 features (order of
    :func:`feature_names`), ``height`` (m,) float64 height above the local ground, ``seconds`` per part."""

    base: np.ndarray
    inverse: np.ndarray
    values: np.ndarray
    height: np.ndarray
    seconds: dict


def _keys(ijk: np.ndarray) -> np.ndarray:
    """(n, 3) int64 voxel indices (any sign, |i| < 2^20) -> (n,) int64 keys, equal iff the voxels are."""
    b = ijk + (1 << 20)
    return (b[:, 0] << 42) | (b[:, 1] << 21) | b[:, 2]


def voxel_subsample(xyz: np.ndarray, voxel_m: float) -> tuple[np.ndarray, np.ndarray]:
    """One point per ``voxel_m`` voxel: the first of each voxel in input order.

    ``xyz`` (n, 3) float, metres. Returns ``(base, inverse)``: ``base`` (m,) int64 indices into ``xyz``
    of the kept points, ``inverse`` (n,) int64 the position in ``base`` of each input point's voxel."""
    p = np.asarray(xyz, np.float64)
    ijk = np.floor((p - p.min(axis=0)) / voxel_m).astype(np.int64)
    _, first, inverse = np.unique(_keys(ijk), return_index=True, return_inverse=True)
    return first.astype(np.int64), inverse.reshape(-1).astype(np.int64)


def _neighbour_voxels(uk: np.ndarray, vijk: np.ndarray):
    """For each of the 27 offsets ``off`` (3,) of the 3 x 3 x 3 block: ``(off, hit, pos)``, where ``hit`` (v,)
    bool marks the voxels (sorted keys ``uk``, integer coordinates ``vijk`` (v, 3)) whose neighbour at ``off``
    holds points and ``pos`` the index of that neighbour in ``uk`` for each hit. Offsets without any hit
    are skipped."""
    nv = len(uk)
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dz in (-1, 0, 1):
                off = np.array([dx, dy, dz])
                nk = _keys(vijk + off)
                pos = np.minimum(np.searchsorted(uk, nk), nv - 1)
                hit = uk[pos] == nk
                if hit.any():
                    yield off, hit, pos[hit]


def _block_moments(p: np.ndarray, s: float):
    """Per point, the count, mean and covariance of the points in the 3 x 3 x 3 voxels of side ``s`` around
    its own. ``p`` (m, 3) float64 (centred). Returns (count (m,), mean (m, 3), cov (m, 3, 3))."""
    ijk = np.floor(p / s).astype(np.int64)
    keys = _keys(ijk)
    uk, inv = np.unique(keys, return_inverse=True)
    inv = inv.reshape(-1)
    nv = len(uk)
    # per voxel sums: count, x, y, z, xx, xy, xz, yy, yz, zz (relative to the voxel's corner for precision)
    corner = ijk * s
    q = p - corner
    cols = [np.ones(len(p)), q[:, 0], q[:, 1], q[:, 2], q[:, 0] * q[:, 0], q[:, 0] * q[:, 1], q[:, 0] * q[:, 2],
            q[:, 1] * q[:, 1], q[:, 1] * q[:, 2], q[:, 2] * q[:, 2]]
    vs = np.stack([np.bincount(inv, weights=c, minlength=nv) for c in cols], axis=1)
    # the voxels' own integer coordinates
    vijk = np.empty((nv, 3), np.int64)
    vijk[inv] = ijk
    acc = np.zeros((nv, 10))
    for off, hit, pos in _neighbour_voxels(uk, vijk):
        src = vs[pos]
        # shift the neighbour's sums from its corner to this voxel's corner: q' = q + off * s
        d = off * s
        n = src[:, 0]
        sx, sy, sz = src[:, 1], src[:, 2], src[:, 3]
        shifted = np.stack([
            n, sx + d[0] * n, sy + d[1] * n, sz + d[2] * n,
            src[:, 4] + 2 * d[0] * sx + d[0] * d[0] * n,
            src[:, 5] + d[0] * sy + d[1] * sx + d[0] * d[1] * n,
            src[:, 6] + d[0] * sz + d[2] * sx + d[0] * d[2] * n,
            src[:, 7] + 2 * d[1] * sy + d[1] * d[1] * n,
            src[:, 8] + d[1] * sz + d[2] * sy + d[1] * d[2] * n,
            src[:, 9] + 2 * d[2] * sz + d[2] * d[2] * n], axis=1)
        acc[hit] += shifted
    n = acc[:, 0]
    mean = acc[:, 1:4] / n[:, None]
    exx = acc[:, [4, 5, 6, 5, 7, 8, 6, 8, 9]].reshape(-1, 3, 3) / n[:, None, None]
    cov = exx - mean[:, :, None] * mean[:, None, :]
    # back to the point's frame: the block mean in centred coordinates
    mean_c = mean + vijk * s
    return n[inv], mean_c[inv], cov[inv], inv, nv, (n, mean_c, cov)


def block_mean(p: np.ndarray, values: np.ndarray, s: float) -> np.ndarray:
    """Per point, the mean of ``values`` over the points in the 3 x 3 x 3 voxels of side ``s`` around its own.

    ``p`` (m, 3) float metres; ``values`` (m, k) float. Returns (m, k) float64. Costs one sort and 27 sorted
    look-ups, whatever the density (the same voxel blocks as the shape features)."""
    p = np.asarray(p, np.float64)
    v = np.asarray(values, np.float64)
    if len(p) == 0:
        return v.copy()
    ijk = np.floor((p - p.min(axis=0)) / s).astype(np.int64)
    uk, inv = np.unique(_keys(ijk), return_inverse=True)
    inv = inv.reshape(-1)
    nv = len(uk)
    sums = np.zeros((nv, v.shape[1]))
    np.add.at(sums, inv, v)
    cnt = np.bincount(inv, minlength=nv).astype(np.float64)
    vijk = np.empty((nv, 3), np.int64)
    vijk[inv] = ijk
    acc = np.zeros_like(sums)
    n = np.zeros(nv)
    for _, hit, pos in _neighbour_voxels(uk, vijk):
        acc[hit] += sums[pos]
        n[hit] += cnt[pos]
    return (acc / n[:, None])[inv]


def _shape(p: np.ndarray, s: float, base_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(m, len(SHAPE_NAMES)) float32 shape features at scale ``s``, and (m,) |normal z| (for the ground)."""
    _, _, _, inv, nv, (n, mean, cov) = _block_moments(p, s)
    w, vec = np.linalg.eigh(cov + np.eye(3) * 1e-10)  # ascending
    w = np.maximum(w, 0.0)
    l3, l2, l1 = w[:, 0], w[:, 1], w[:, 2]
    l1s = np.maximum(l1, 1e-12)
    side = 3.0 * s
    few = n < 3  # too few points for a shape: features of "nothing known"
    lin = np.where(few, 0.0, (l1 - l2) / l1s)
    pla = np.where(few, 0.0, (l2 - l3) / l1s)
    sca = np.where(few, 0.0, l3 / l1s)
    nz = np.where(few, 0.0, np.abs(vec[:, 2, 0]))
    lz = np.where(few, 0.0, np.abs(vec[:, 2, 2]))
    spread = np.sqrt(l1) / side
    fill = np.log(np.maximum(n, 1) / (side / base_m) ** 2)
    rough = np.log10(np.sqrt(l3) + 1e-3)
    vox = np.stack([lin, pla, sca, nz, lz, spread, np.zeros(nv), fill, rough], axis=1)
    out = vox[inv]
    out[:, 6] = (p[:, 2] - mean[inv, 2]) / side
    return out.astype(np.float32), nz[inv]


def _grid_max(cell_of: np.ndarray, values: np.ndarray, n_cells: int) -> np.ndarray:
    out = np.full(n_cells, -np.inf)
    np.maximum.at(out, cell_of, values)
    return out


def _columns(p: np.ndarray, h: np.ndarray, cell_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Per point the highest height above ground in its (x, y) cell of ``cell_m`` and its 8 neighbours, and
    the point's share of it."""
    ij = np.floor((p[:, :2] - p[:, :2].min(axis=0)) / cell_m).astype(np.int64)
    nx, ny = int(ij[:, 0].max()) + 1, int(ij[:, 1].max()) + 1
    flat = ij[:, 1] * nx + ij[:, 0]
    top = _grid_max(flat, np.clip(h, 0, None), nx * ny).reshape(ny, nx)
    from scipy.ndimage import maximum_filter

    top = maximum_filter(np.where(np.isfinite(top), top, 0.0), size=3, mode="nearest").ravel()[flat]
    share = np.clip(h, 0, None) / np.maximum(top, 0.3)
    return top, share


def _objects(p: np.ndarray, raised: np.ndarray, voxel_m: float = 0.4) -> np.ndarray:
    """(m, 4): per raised point its connected object's longer and shorter horizontal extent (m), top z minus
    the object's lowest z (m), and log10 of its voxel count; zeros for points not raised."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    out = np.zeros((len(p), 4))
    idx = np.flatnonzero(raised)
    if len(idx) == 0:
        return out
    q = p[idx]
    ijk = np.floor((q - q.min(axis=0)) / voxel_m).astype(np.int64)
    keys = _keys(ijk)
    uk, inv = np.unique(keys, return_inverse=True)
    inv = inv.reshape(-1)
    nv = len(uk)
    vijk = np.empty((nv, 3), np.int64)
    vijk[inv] = ijk
    rows, cols = [np.arange(nv)], [np.arange(nv)]
    for off in ((1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, -1, 0), (1, 0, 1), (1, 0, -1), (0, 1, 1),
                (0, 1, -1), (1, 1, 1), (1, 1, -1), (1, -1, 1), (1, -1, -1)):
        nk = _keys(vijk + np.array(off))
        pos = np.minimum(np.searchsorted(uk, nk), nv - 1)
        hit = uk[pos] == nk
        rows.append(np.flatnonzero(hit))
        cols.append(pos[hit])
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(len(r), np.int8), (r, c)), shape=(nv, nv))
    _, comp = connected_components(graph, directed=False)
    lab = comp[inv]
    nc = int(comp.max()) + 1
    stats = []
    for axis in range(3):
        hi = _grid_max(lab, q[:, axis], nc)
        lo = -_grid_max(lab, -q[:, axis], nc)
        stats.append(hi - lo + voxel_m)
    ext = np.stack(stats[:2], axis=1)
    size = np.bincount(comp, minlength=nc)
    out[idx, 0] = ext.max(axis=1)[lab]
    out[idx, 1] = ext.min(axis=1)[lab]
    out[idx, 2] = stats[2][lab]
    out[idx, 3] = np.log10(size[lab])
    return out


def has_intensity(intensity: np.ndarray | None) -> bool:
    """The capture has an intensity the features can read: one given, and not the same value everywhere."""
    return intensity is not None and len(intensity) > 0 and bool(np.ptp(np.asarray(intensity, np.float64)) > 0)


def intensity_rank(intensity: np.ndarray | None, n: int) -> np.ndarray:
    """(n,) float32 percentile rank (0..1) of each return's intensity within the capture; 0.5 without one
    (``None``, or a constant column, which carries nothing)."""
    if intensity is None:
        return np.full(n, 0.5, np.float32)
    v = np.asarray(intensity, np.float64).reshape(-1)
    if len(v) != n or not np.isfinite(v).all() or v.max() <= v.min():
        return np.full(n, 0.5, np.float32)
    order = np.argsort(v, kind="stable")
    ranks = np.empty(n)
    ranks[order] = np.arange(n)
    # ties share their mean rank
    _, tie, cnt = np.unique(v, return_inverse=True, return_counts=True)
    sums = np.bincount(tie.reshape(-1), weights=ranks)
    return (sums / cnt)[tie.reshape(-1)].astype(np.float32) / max(n - 1, 1)


def point_features(xyz: np.ndarray, intensity: np.ndarray | None = None, *, base_voxel_m: float = 0.1,
                   ground_window_m: float = 8.0, ground_cell_m: float = 0.5, ground_pct: float = 30.0) -> Features:
    """The features of every base point of a cloud (see the module's docstring).

    ``xyz`` (n, 3) float, site frame (z up), metres; ``intensity`` (n,) any numeric scale or None.
    Returns a :class:`Features`; ``values`` has ``len(feature_names())`` columns."""
    import time

    from twinkit.street.ground import LocalGround

    sec = {}
    t = time.perf_counter()
    xyz = np.asarray(xyz, np.float64)
    base, inverse = voxel_subsample(xyz, base_voxel_m)
    p = xyz[base]
    p = p - p.mean(axis=0)
    sec["voxel"] = time.perf_counter() - t
    t = time.perf_counter()
    shape, nzs = [], []
    for s in SCALES_M:
        f, nz = _shape(p, s, base_voxel_m)
        shape.append(f)
        nzs.append(nz)
    sec["shape"] = time.perf_counter() - t
    t = time.perf_counter()
    up = nzs[1] >= 0.85
    g = LocalGround(p, up, window="opening", window_m=ground_window_m, cell_m=ground_cell_m, pct=ground_pct,
                    if_none_up="all")
    h = g.height()
    from scipy.ndimage import grey_dilation, grey_erosion

    j, i = g.cells(p[:, :2])
    feats_g = [np.clip(h, -3, 40)]
    for r_m in (1.5, 5.0):
        k = max(1, int(round(r_m / ground_cell_m)))
        low = grey_erosion(g.z, size=(2 * k + 1, 2 * k + 1), mode="nearest")
        feats_g.append(np.clip(p[:, 2] - low[j, i], -3, 40))
    k = max(1, int(round(1.5 / ground_cell_m)))
    high = grey_dilation(g.z, size=(2 * k + 1, 2 * k + 1), mode="nearest")
    feats_g.append(np.clip(high[j, i] - g.z[j, i], 0, 5))
    # curbs: the upper edges of 6-35 cm steps in the ground's surface; how far each point is from the nearest
    # one and how high it stands against that step's top (a pavement ~0, the road beside it ~ -0.12 m)
    from scipy.ndimage import distance_transform_edt

    # (a curb says something within a few metres only: beyond CURB_REACH_M, and in a scan without any step,
    # both features read "no curb near")
    step = g.steps(min_step_m=0.06, radius_m=0.5, max_step_m=0.35)
    dist_m = np.full(len(p), CURB_REACH_M)
    above = np.zeros(len(p))
    if step.any():
        dist, (sj, si) = distance_transform_edt(~step, return_indices=True)
        dist_m = np.minimum(dist[j, i] * ground_cell_m, CURB_REACH_M)
        above = np.where(dist_m < CURB_REACH_M, np.clip(p[:, 2] - g.surface[sj[j, i], si[j, i]], -1, 1), 0.0)
    feats_g += [np.log10(0.25 + dist_m), above]
    sec["ground"] = time.perf_counter() - t
    t = time.perf_counter()
    cols = []
    for cell in (0.5, 2.0):
        top, share = _columns(p, h, cell)
        cols += [np.clip(top, 0, 40), share]
    raised = h > 0.3
    obj = _objects(p, raised)
    obj = np.column_stack([np.log10(obj[:, 0] + 0.1), np.log10(obj[:, 1] + 0.1), np.clip(obj[:, 2], 0, 40), obj[:, 3],
                           raised.astype(np.float64)])
    sec["objects"] = time.perf_counter() - t
    has = has_intensity(intensity)
    rank = intensity_rank(None if intensity is None else np.asarray(intensity)[base], len(base))
    inten = [rank] + [block_mean(p, rank[:, None], s)[:, 0] for s in INTENSITY_SCALES_M]
    values = np.column_stack(shape + [np.column_stack(feats_g), np.column_stack(cols), obj,
                                      np.column_stack(inten), np.full((len(base), 1), float(has))]).astype(np.float32)
    values[~np.isfinite(values)] = 0.0
    return Features(base=base, inverse=inverse, values=values, height=h, seconds={k: round(v, 3) for k, v in sec.items()})

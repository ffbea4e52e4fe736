"""Exact planar cut of a tile mesh to its core box.

A tile is reconstructed on its padded box (core + overlap) and then cut to its core box with
:func:`cut_to_box`: triangles crossing a cut plane are split, and every border vertex lies
exactly on the plane (its coordinate along the plane's axis is set to the plane's value).
Two neighbouring tiles therefore meet on a shared plane with two border polylines that nearly
coincide (both tiles saw the same points in the overlap); :mod:`twinkit_tiles.stitch` joins them.

Everything is numpy on :class:`twinkit.mesh.Mesh`; no extra dependency.
"""
from __future__ import annotations

import numpy as np

from twinkit.mesh import Mesh, compact

ON_PLANE_M = 5e-4  # a vertex this close to a cut plane is moved onto it (no sliver edges along the seam)


def _interp_attr(arr: np.ndarray, a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Attribute of points at parameter t on edges a->b: linear for floats/colours, nearest for labels."""
    if arr.dtype.kind == "f":
        tt = t.reshape((-1,) + (1,) * (arr.ndim - 1))
        return (arr[a] * (1 - tt) + arr[b] * tt).astype(arr.dtype)
    if arr.dtype == np.uint8 and arr.ndim == 2:  # colours
        tt = t[:, None]
        return np.clip(np.rint(arr[a] * (1 - tt) + arr[b] * tt), 0, 255).astype(np.uint8)
    return np.where((t < 0.5).reshape((-1,) + (1,) * (arr.ndim - 1)), arr[a], arr[b])


def cut_halfspace(mesh: Mesh, axis: int, value: float, keep: str) -> Mesh:
    """Keep the part of ``mesh`` with ``coord[axis] >= value`` (``keep='above'``) or ``<= value``
    (``keep='below'``). Triangles crossing the plane are split; new vertices are placed on the
    plane exactly (their ``axis`` coordinate is ``value``) and shared by the two faces of their edge.
    Attributes are interpolated (floats, colours) or taken from the nearer end (labels)."""
    if mesh.n_faces == 0:
        return mesh
    v = mesh.vertices.astype(np.float64, copy=True)
    s = v[:, axis] - value
    if keep == "below":
        s = -s
    elif keep != "above":
        raise ValueError("keep must be 'above' or 'below'")
    snap = np.abs(s) <= ON_PLANE_M
    v[snap, axis] = value
    s[snap] = 0.0
    f = mesh.faces
    sf = s[f]
    inside = (sf >= 0).all(axis=1) & ~(sf == 0).all(axis=1)
    cross = (sf > 0).any(axis=1) & (sf < 0).any(axis=1)
    keep_f = f[inside]
    keep_fa = {k: a[inside] for k, a in mesh.face_attrs.items()}
    attrs = dict(mesh.attrs)
    if cross.any():
        cf = f[cross]
        cfa = {k: a[cross] for k, a in mesh.face_attrs.items()}
        # one new vertex per crossing edge, shared by both faces of that edge
        ea = np.concatenate([cf[:, 0], cf[:, 1], cf[:, 2]])
        eb = np.concatenate([cf[:, 1], cf[:, 2], cf[:, 0]])
        straddle = (s[ea] * s[eb]) < 0
        lo, hi = np.minimum(ea, eb)[straddle], np.maximum(ea, eb)[straddle]
        pairs, inv = np.unique(np.stack([lo, hi], axis=1), axis=0, return_inverse=True)
        a, b = pairs[:, 0], pairs[:, 1]
        t = s[a] / (s[a] - s[b])
        newv = v[a] + (v[b] - v[a]) * t[:, None]
        newv[:, axis] = value
        base = len(v)
        edge_vertex = np.full(len(ea), -1, np.int64)
        edge_vertex[straddle] = base + inv.ravel()
        nc = len(cf)
        ev = edge_vertex.reshape(3, nc).T  # ev[k, i]: new vertex on edge i -> i+1 of face k (or -1)
        tris, owner = [], []
        for k in range(nc):
            poly = []
            for i in range(3):
                vi = cf[k, i]
                if s[vi] >= 0:
                    poly.append(vi)
                if ev[k, i] >= 0:
                    poly.append(ev[k, i])
            for j in range(1, len(poly) - 1):
                tris.append((poly[0], poly[j], poly[j + 1]))
                owner.append(k)
        v = np.vstack([v, newv])
        attrs = {k: np.concatenate([arr, _interp_attr(arr, a, b, t)]) for k, arr in mesh.attrs.items()}
        if tris:
            owner = np.asarray(owner, np.int64)
            keep_f = np.vstack([keep_f, np.asarray(tris, np.int64)])
            keep_fa = {k: np.concatenate([keep_fa[k], cfa[k][owner]]) for k in keep_fa}
    out = Mesh(vertices=v, faces=keep_f, attrs=attrs, face_attrs=keep_fa, comments=list(mesh.comments))
    return compact(out)


def cut_to_box(mesh: Mesh, core: list) -> Mesh:
    """Cut a tile mesh to its core box ``[xmin, ymin, xmax, ymax]`` (``None`` = unbounded side,
    i.e. the outer border of the site: nothing is cut there)."""
    xmin, ymin, xmax, ymax = core
    for axis, val, keep in ((0, xmin, "above"), (0, xmax, "below"), (1, ymin, "above"), (1, ymax, "below")):
        if val is not None and mesh.n_faces:
            mesh = cut_halfspace(mesh, axis, float(val), keep)
    return mesh

"""Open edges and planes of a triangle mesh, as numpy arrays: boundary half-edges, edge counts, the border
polylines on a plane, the interior cut planes of a tile grid and what lies near them.
"""
from __future__ import annotations

import numpy as np


def _edge_keys(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    lo, hi = np.minimum(a, b).astype(np.int64), np.maximum(a, b).astype(np.int64)
    return lo * (1 << 32) + hi


def boundary_half_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Half-edges (a, b) that belong to exactly one face, and the index of that face."""
    if len(faces) == 0:
        return np.zeros((0, 2), np.int64), np.zeros(0, np.int64)
    he = np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], axis=1).reshape(-1, 2)
    key = _edge_keys(he[:, 0], he[:, 1])
    _, inv, counts = np.unique(key, return_inverse=True, return_counts=True)
    sel = counts[inv.ravel()] == 1
    return he[sel], np.repeat(np.arange(len(faces)), 3)[sel]


def edge_counts(faces: np.ndarray) -> dict:
    """Boundary edges (1 face) and non-manifold edges (> 2 faces) of a triangle mesh."""
    if len(faces) == 0:
        return {"edges": 0, "boundary_edges": 0, "non_manifold_edges": 0}
    he = np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], axis=1).reshape(-1, 2)
    _, counts = np.unique(_edge_keys(he[:, 0], he[:, 1]), return_counts=True)
    return {"edges": int(len(counts)), "boundary_edges": int((counts == 1).sum()),
            "non_manifold_edges": int((counts > 2).sum())}


def _plane_half_edges(X: np.ndarray, faces: np.ndarray, axis: int, value: float, tol: float):
    """Boundary half-edges with both ends on the plane, and the index of their face."""
    on = np.abs(X[:, axis] - value) <= tol
    near = np.flatnonzero(on[faces].sum(axis=1) >= 2)  # every face with an edge on the plane
    he, fid = boundary_half_edges(faces[near])
    if len(he) == 0:
        return he, fid
    keep = on[he[:, 0]] & on[he[:, 1]]
    return he[keep], near[fid[keep]]


def _chains(he: np.ndarray) -> list[np.ndarray]:
    if len(he) == 0:
        return []
    nxt: dict[int, list[int]] = {}
    indeg: dict[int, int] = {}
    for a, b in he.tolist():
        nxt.setdefault(a, []).append(b)
        indeg[b] = indeg.get(b, 0) + 1
    chains = []

    def walk(start):
        chain = [start]
        cur = start
        while nxt.get(cur):
            cur = nxt[cur].pop()
            chain.append(cur)
            if cur == start:
                break
        return chain

    for s0 in [a for a in nxt if indeg.get(a, 0) == 0]:
        while nxt.get(s0):
            chains.append(np.asarray(walk(s0), np.int64))
    for s0 in list(nxt):
        while nxt.get(s0):
            chains.append(np.asarray(walk(s0), np.int64))
    return [c for c in chains if len(c) >= 2]


def _simple_loops(lp: np.ndarray) -> list[np.ndarray]:
    """Split a closed vertex loop that visits a vertex more than once into simple loops (same orientation)."""
    stack: list[int] = []
    pos: dict[int, int] = {}
    out = []
    for v in lp.tolist():
        if v in pos:
            i = pos[v]
            out.append(np.asarray(stack[i:], np.int64))
            for w in stack[i + 1:]:
                del pos[w]
            stack = stack[: i + 1]
        else:
            pos[v] = len(stack)
            stack.append(v)
    out.append(np.asarray(stack, np.int64))
    return out


def near_planes(X: np.ndarray, planes: list[tuple[int, float]], band_m: float) -> np.ndarray:
    """Bool mask of the rows of ``X`` within ``band_m`` of any of the planes."""
    m = np.zeros(len(X), bool)
    for axis, val in planes:
        m |= np.abs(X[:, axis] - val) <= band_m
    return m


def seam_planes(tiles: list[dict]) -> list[tuple[int, float]]:
    """The interior cut planes of a grid: (axis, value)."""
    planes = set()
    for t in tiles:
        xmin, ymin, _, _ = t["core"]
        if xmin is not None:
            planes.add((0, float(xmin)))
        if ymin is not None:
            planes.add((1, float(ymin)))
    return sorted(planes)

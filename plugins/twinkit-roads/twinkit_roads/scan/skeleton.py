"""The carriageway mask's skeleton and its graph: junction and end nodes, and the pixel paths between them."""
from __future__ import annotations

import numpy as np


def thin(mask: np.ndarray) -> np.ndarray:
    """Zhang-Suen thinning (vectorised): a one-pixel, 8-connected skeleton of a boolean image."""
    img = np.pad(mask.astype(np.uint8), 1)
    while True:
        changed = False
        for step in (0, 1):
            p = img
            P2, P3, P4 = p[:-2, 1:-1], p[:-2, 2:], p[1:-1, 2:]
            P5, P6, P7 = p[2:, 2:], p[2:, 1:-1], p[2:, :-2]
            P8, P9 = p[1:-1, :-2], p[:-2, :-2]
            nb = [P2, P3, P4, P5, P6, P7, P8, P9]
            B = sum(x.astype(np.int32) for x in nb)
            seq = nb + [P2]
            A = sum(((seq[i] == 0) & (seq[i + 1] == 1)).astype(np.int32) for i in range(8))
            if step == 0:
                c = (P2 * P4 * P6 == 0) & (P4 * P6 * P8 == 0)
            else:
                c = (P2 * P4 * P8 == 0) & (P2 * P6 * P8 == 0)
            rm = (p[1:-1, 1:-1] == 1) & (B >= 2) & (B <= 6) & (A == 1) & c
            if rm.any():
                img = img.copy()
                img[1:-1, 1:-1][rm] = 0
                changed = True
        if not changed:
            break
    return img[1:-1, 1:-1].astype(bool)


_NB = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


def skeleton_graph(skel: np.ndarray):
    """Nodes (clusters of pixels with != 2 neighbours) and the pixel paths between them.

    Returns (node_pixels: list of (k, 2) arrays of (row, col), edges: list of (na, nb, path (k, 2)))."""
    from scipy import ndimage

    s = skel.astype(np.uint8)
    cnt = ndimage.convolve(s, np.ones((3, 3), np.uint8), mode="constant") - s
    node = skel & (cnt != 2)
    lab, n = ndimage.label(node, np.ones((3, 3), bool))
    nodes = [np.argwhere(lab == i + 1) for i in range(n)]
    h, w = skel.shape
    visited = np.zeros_like(skel, bool)
    edges = []

    def nbrs(r, c):
        for dr, dc in _NB:
            rr, cc = r + dr, c + dc
            if 0 <= rr < h and 0 <= cc < w and skel[rr, cc]:
                yield rr, cc

    for ni, pix in enumerate(nodes):
        for r0, c0 in pix:
            for r, c in nbrs(r0, c0):
                if lab[r, c] or visited[r, c]:
                    continue
                path = [(r0, c0), (r, c)]
                visited[r, c] = True
                prev = (r0, c0)
                end = None
                while True:
                    cr, cc = path[-1]
                    nxt = None
                    for q in nbrs(cr, cc):
                        if q == prev or (q[0], q[1]) == (r0, c0) and len(path) <= 2:
                            continue
                        if lab[q]:
                            if lab[q] - 1 != ni or len(path) > 3:
                                end = lab[q] - 1
                                path.append(q)
                                break
                            continue
                        if not visited[q]:
                            nxt = q
                            break
                    if end is not None or nxt is None:
                        break
                    visited[nxt] = True
                    prev = (cr, cc)
                    path.append(nxt)
                if end is None:
                    continue  # a loop without nodes, or a dangling piece: ignored
                edges.append((ni, int(end), np.array(path)))
    # pure loops (no node) are not roads we can model: ignored
    # de-duplicate edges found from both ends
    seen, out = set(), []
    for a, b, p in edges:
        key = (min(a, b), max(a, b), tuple(p[len(p) // 2]))
        if key in seen:
            continue
        seen.add(key)
        out.append((a, b, p))
    return nodes, out

"""Points linked into groups: two points closer than a distance belong to one group, and so do the points
linked to them (single linkage), the way a gap in the ground, a cluster of failing rays or an object standing
on the street is told from the next one."""
from __future__ import annotations

import numpy as np


def linked_groups(points: np.ndarray, link_m: float) -> tuple[int, np.ndarray]:
    """(number of groups, (n,) group of each point) of ``points`` (n, 2 or 3; m) linked within ``link_m``."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    if n == 0:
        return 0, np.zeros(0, np.int64)
    pairs = cKDTree(pts).query_pairs(link_m, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs), bool), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    count, group = connected_components(graph, directed=False)
    return int(count), group.astype(np.int64)

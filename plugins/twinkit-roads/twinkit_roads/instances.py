"""Scanned traffic lights and signs in the labelled mesh.

The instances ``signals.place_signals`` places: clusters of traffic-light and traffic-sign labelled
vertices (CityScapes trainIds 6 and 7, with the pole, trainId 5, under them), and poles carrying an
unlabelled head (candidates for lights the labels miss).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from twinkit.cityscapes import POLE
from twinkit.cityscapes import TRAFFIC_LIGHT as LIGHT
from twinkit.cityscapes import TRAFFIC_SIGN as SIGN

if TYPE_CHECKING:
    from .params import SignalParams


@dataclass
class Instance:
    kind: str  # "light" | "sign"
    centre: np.ndarray  # (3,) site frame
    size: np.ndarray  # (3,) extents along the horizontal principal axes and z
    vertices: int
    height_m: float  # centre above the local ground
    pole_vertices: int  # pole-labelled vertices under it
    label: int
    id: int = -1
    rejected: str = ""
    evidence: str = "label"  # "label": a cluster of its label; "pole_head": a pole carrying a head, unlabelled
    members: np.ndarray | None = None  # indices of its vertices in the mesh (label clusters)

    def to_json(self) -> dict:
        return {"id": self.id, "kind": self.kind, "label": self.label,
                "position": [round(float(v), 3) for v in self.centre],
                "size_m": [round(float(v), 3) for v in self.size], "vertices": self.vertices,
                "height_above_ground_m": round(self.height_m, 3), "pole_vertices": self.pole_vertices,
                "evidence": self.evidence,
                **({"rejected": self.rejected} if self.rejected else {})}


def _clusters(P: np.ndarray, link_m: float) -> list[np.ndarray]:
    from twinkit.surface.linked import linked_groups

    n, cc = linked_groups(P, link_m)
    return [np.flatnonzero(cc == k) for k in range(n)]


def find_instances(V: np.ndarray, labels: np.ndarray, *, link_m: float = 0.35, min_vertices: int = 12,
                   min_height_m: float = 1.5, max_height_m: float = 8.0, max_size_m: float = 2.0,
                   ground_radius_m: float = 3.0, pole_radius_m: float = 0.6, min_pole_vertices: int = 3,
                   plate_depth_m: float = 0.12) -> tuple[list[Instance], list[Instance]]:
    """Scanned traffic lights and signs: clusters of label-6 / label-7 vertices, checked in 3D.

    A cluster is kept when it has ``min_vertices``, floats ``min_height_m``..``max_height_m`` above the
    local ground (a low percentile of the mesh within ``ground_radius_m``), is no bigger than
    ``max_size_m`` (a head or a plate, not a facade patch) and stands on a pole (``min_pole_vertices``
    pole-labelled vertices below it within ``pole_radius_m``). A "light" cluster that is a flat
    plate (thinner than ``plate_depth_m`` across its horizontal minor axis) is a sign: light heads
    are boxes. Returns (kept, rejected).
    """
    from scipy.spatial import cKDTree

    from twinkit.street.ground import LocalGround

    labels = np.asarray(labels)
    if len(labels) != len(V):
        raise ValueError(f"{len(labels)} labels for {len(V)} vertices")
    ground_at = LocalGround(V, window="disc", window_m=2 * ground_radius_m, pct=2).at
    pole = V[labels == POLE]
    ptree = cKDTree(pole[:, :2]) if len(pole) else None
    kept, rejected = [], []
    for lab, kind in ((LIGHT, "light"), (SIGN, "sign")):
        idx = np.flatnonzero(labels == lab)
        for comp in _clusters(V[idx], link_m):
            P = V[idx[comp]]
            c = P.mean(0)
            xy = P[:, :2] - c[:2]
            if len(P) >= 2:
                w, vec = np.linalg.eigh(np.cov(xy.T) + 1e-12 * np.eye(2))
                proj = xy @ vec
                ext = proj.max(0) - proj.min(0)  # (minor, major)
            else:
                ext = np.zeros(2)
            size = np.array([ext[1], ext[0], P[:, 2].max() - P[:, 2].min()])
            ground = float(ground_at(c[:2])[0])
            if np.isnan(ground):
                ground = float(P[:, 2].min())
            n_pole = 0
            if ptree is not None:
                cand = ptree.query_ball_point(c[:2], pole_radius_m)
                if cand:
                    z = pole[cand, 2]
                    n_pole = int(((z > ground + 0.2) & (z < P[:, 2].min() + 0.2)).sum())
            k = kind
            if kind == "light" and len(P) >= min_vertices and ext[0] < plate_depth_m:
                k = "sign"
            inst = Instance(k, c, size, int(len(P)), float(c[2] - ground), n_pole, lab, members=idx[comp])
            why = []
            if len(P) < min_vertices:
                why.append(f"{len(P)} vertices < {min_vertices}")
            if not (min_height_m <= inst.height_m <= max_height_m):
                why.append(f"{inst.height_m:.2f} m above ground, outside {min_height_m}..{max_height_m}")
            if max(size) > max_size_m:
                why.append(f"{max(size):.2f} m across > {max_size_m}")
            if n_pole < min_pole_vertices:
                why.append(f"{n_pole} pole vertices under it < {min_pole_vertices}")
            if why:
                inst.rejected = "; ".join(why)
                rejected.append(inst)
            else:
                kept.append(inst)
    kept.sort(key=lambda i: (i.kind, round(float(i.centre[0]), 1), round(float(i.centre[1]), 1)))
    for i, inst in enumerate(kept):
        inst.id = i
    return kept, rejected


def find_pole_heads(V: np.ndarray, labels: np.ndarray, known: list[Instance], *, link_m: float = 0.35,
                    min_pole_vertices: int = 10, head_z_m: tuple[float, float] = (1.8, 4.5),
                    axis_radius_m: float = 0.6, head_width_m: tuple[float, float] = (0.3, 1.0),
                    clear_ring_m: tuple[float, float] = (0.8, 1.5), ground_radius_m: float = 3.0,
                    known_m: float = 1.0) -> list[Instance]:
    """Poles that carry a head, whatever the head is labelled: candidates for lights the labels miss.

    A pole is a cluster of pole-labelled vertices (``min_pole_vertices``). Its *head* is every mesh
    vertex within ``axis_radius_m`` of the pole's axis at ``head_z_m`` above the local ground. It counts
    when the head is bulky (narrowest horizontal extent ``head_width_m[0]`` or more: a bare pole or a
    sign plate is thinner; lamps carry theirs higher), small (widest extent at most ``head_width_m[1]``)
    and free-standing (no vertex at head height ``clear_ring_m`` from the axis: not a tree crown, not a
    facade). Poles within ``known_m`` of a light found by its label are left out. The head's
    position is the centroid of its vertices not labelled as sign.
    """
    from twinkit.street.ground import LocalGround

    labels = np.asarray(labels)
    local = LocalGround(V, window="disc", window_m=2 * ground_radius_m, pct=2)
    tree2 = local.tree
    idx = np.flatnonzero(labels == POLE)
    out = []
    for comp in _clusters(V[idx], link_m):
        if len(comp) < min_pole_vertices:
            continue
        c = np.median(V[idx[comp], :2], 0)
        ground = float(local.at(c)[0])
        if any(k.kind == "light" and np.hypot(*(k.centre[:2] - c)) <= known_m for k in known):
            continue
        ring = np.asarray(tree2.query_ball_point(c, clear_ring_m[1]), int)
        h = V[ring, 2] - ground
        r = np.hypot(V[ring, 0] - c[0], V[ring, 1] - c[1])
        band = (h >= head_z_m[0]) & (h <= head_z_m[1])
        if np.any(band & (r > clear_ring_m[0])):
            continue
        head = ring[band & (r <= axis_radius_m)]
        if len(head) < 3:
            continue
        xy = V[head, :2] - V[head, :2].mean(0)
        w, vec = np.linalg.eigh(np.cov(xy.T) + 1e-12 * np.eye(2))
        proj = xy @ vec
        ext = proj.max(0) - proj.min(0)  # (minor, major)
        if not (head_width_m[0] <= ext[0] and ext[1] <= head_width_m[1]):
            continue
        body = head[labels[head] != SIGN]
        P = V[body if len(body) >= 3 else head]
        ctr = P.mean(0)
        size = np.array([ext[1], ext[0], P[:, 2].max() - P[:, 2].min()])
        out.append(Instance("light", ctr, size, int(len(P)), float(ctr[2] - ground), int(len(comp)), POLE,
                            evidence="pole_head"))
    return out


def scanned_instances(V: np.ndarray, labels: np.ndarray, params: SignalParams) -> tuple[list[Instance], list[Instance]]:
    """The place_signals step's instances: ``find_instances`` with ``params``, then (``params.pole_heads``)
    ``find_pole_heads`` numbered after them. ``V`` (n, 3) float vertices (site frame, m), ``labels`` (n,)
    CityScapes trainIds. Returns (kept, rejected)."""
    kept, rejected = find_instances(
        V, labels, link_m=params.link_m, min_vertices=params.min_vertices, min_height_m=params.min_height_m,
        max_height_m=params.max_height_m, max_size_m=params.max_size_m, ground_radius_m=params.ground_radius_m,
        pole_radius_m=params.pole_radius_m, min_pole_vertices=params.min_pole_vertices,
        plate_depth_m=params.plate_depth_m)
    if params.pole_heads:
        heads = find_pole_heads(V, labels, kept, link_m=params.link_m,
                                head_z_m=(params.head_min_m, params.head_max_m),
                                head_width_m=(params.head_min_width_m, params.head_max_width_m),
                                clear_ring_m=(params.head_clear_m, max(params.head_clear_m + 0.2, 1.5)),
                                ground_radius_m=params.ground_radius_m)
        for i, h in enumerate(heads):
            h.id = len(kept) + i
        kept = kept + heads
    return kept, rejected

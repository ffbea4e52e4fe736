"""Simplification to a target face count.

- ``quadric``: fast-simplification (Fast-Quadric-Mesh-Simplification), open boundaries kept
  (their vertices never collapse) so the mesh edge does not shrink;
- ``clustering``: open3d vertex clustering with a cell size chosen from the surface area for
  roughly the target count; the fallback above ``cluster_above_faces`` (thesis: quadric did
  not finish on 60 M vertices in 12 h, clustering took 20 min).

Colours are re-sampled afterwards from the dense mesh at the closest surface point.
"""
from __future__ import annotations

import math

import numpy as np

from twinkit.mesh import Mesh, compact, face_areas


def simplify_quadric(mesh: Mesh, target_faces: int, *, preserve_border: bool = True, aggressiveness: float = 7.0) -> Mesh:
    assert mesh.faces is not None  # a mesh, not a cloud
    import fast_simplification

    if mesh.n_faces <= target_faces:
        return Mesh(mesh.vertices.copy(), mesh.faces.copy())
    v, f = fast_simplification.simplify(np.ascontiguousarray(mesh.vertices, np.float64),
                                        np.ascontiguousarray(mesh.faces, np.int32),
                                        target_count=int(target_faces), agg=float(aggressiveness),
                                        preserve_border=bool(preserve_border))
    out = Mesh(vertices=np.asarray(v, np.float64), faces=np.asarray(f, np.int64))
    return _drop_degenerate(out)


def simplify_clustering(mesh: Mesh, target_faces: int) -> Mesh:
    assert mesh.faces is not None  # a mesh, not a cloud
    import open3d as o3d

    from twinkit.mesh import to_o3d_mesh

    area = float(face_areas(mesh.vertices, mesh.faces).sum())
    # a regular triangulation with spacing h has about 2 * area / h^2 faces
    h = math.sqrt(2.0 * area / max(1, target_faces))
    m = to_o3d_mesh(Mesh(mesh.vertices, mesh.faces))
    s = m.simplify_vertex_clustering(voxel_size=h, contraction=o3d.geometry.SimplificationContraction.Quadric)
    out = Mesh(vertices=np.asarray(s.vertices, np.float64), faces=np.asarray(s.triangles, np.int64))
    return _drop_degenerate(out)


def _drop_degenerate(mesh: Mesh) -> Mesh:
    assert mesh.faces is not None  # a mesh, not a cloud
    f = mesh.faces
    ok = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
    ok &= face_areas(mesh.vertices, f) > 0
    return compact(mesh, ok)


def resample_attributes(simple: Mesh, dense: Mesh, threads: int = 0, names=("colors",), surface=None) -> Mesh:
    """Copy per-vertex attributes from ``dense`` to ``simple`` at the closest dense surface point
    (``surface``: ``dense``'s :class:`~twinkit.surface.closest.Surface` when the caller has one)."""
    assert simple.faces is not None  # a mesh, not a cloud
    assert dense.faces is not None  # a mesh, not a cloud
    from twinkit.mesh import vertex_normals
    from .closest import Surface

    surf = surface if surface is not None else Surface(dense.vertices, dense.faces, threads)
    fid, bary, dist = surf.closest(simple.vertices)
    simple.attrs["dist_to_dense_m"] = dist
    for name in names:
        if name in dense.attrs:
            a = dense.attrs[name]
            vals = surf.interpolate(a.reshape(len(a), -1), fid, bary)
            if a.dtype == np.uint8:
                vals = np.clip(np.rint(vals), 0, 255).astype(np.uint8)
            else:
                vals = vals.astype(a.dtype)
            simple.attrs[name] = vals.reshape((-1,) + a.shape[1:])
    simple.attrs["normals"] = vertex_normals(simple.vertices, simple.faces)
    return simple


def simplify_mesh(mesh: Mesh, target_faces: int = 500_000, *, method: str = "auto", cluster_above_faces: int = 20_000_000,
                  preserve_border: bool = True, aggressiveness: float = 7.0, threads: int = 0,
                  close_holes_edges: int = 12) -> tuple[Mesh, str]:
    """Return (simplified mesh with re-sampled colours and normals, method used)."""
    if method == "auto":
        method = "clustering" if mesh.n_faces > cluster_above_faces else "quadric"
    if method == "quadric":
        out = simplify_quadric(mesh, target_faces, preserve_border=preserve_border, aggressiveness=aggressiveness)
    elif method == "clustering":
        out = simplify_clustering(mesh, target_faces)
        if out.n_faces > 1.2 * target_faces:  # finish with quadric (now affordable)
            out = simplify_quadric(out, target_faces, preserve_border=preserve_border, aggressiveness=aggressiveness)
    else:
        raise ValueError(f"unknown simplification method '{method}' (auto, quadric, clustering)")
    out, closed = close_collapse_holes(out, max_edges=close_holes_edges)
    out = resample_attributes(out, mesh, threads)
    out.comments = [f"holes closed after simplification: {closed}"]
    return out, method


def close_collapse_holes(mesh: Mesh, max_edges: int = 12) -> tuple[Mesh, int]:
    """Close the pin-holes edge collapses leave (a face dropped as degenerate, a collapse the border rule
    refused next to another): boundary loops of at most ``max_edges`` edges, by a fan. The clean-up before
    closed every hole up to 60 edges, so a loop this small here is the simplifier's, not the scan's."""
    assert mesh.faces is not None  # a mesh, not a cloud
    from twinkit.mesh.topology import boundary_loops
    from twinkit.street.holes import fan_fill

    if max_edges < 3 or mesh.n_faces == 0:
        return mesh, 0
    loops = [lp for lp in boundary_loops(mesh.faces) if len(lp) <= max_edges]
    return (fan_fill(mesh, loops) if loops else mesh), len(loops)

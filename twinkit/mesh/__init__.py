"""twinkit.mesh: the one mesh and point-cloud type, its I/O and its operations.

Modules, by concept:

- :mod:`twinkit.mesh.core`: the :class:`Mesh` dataclass (vertices, faces, per-vertex ``attrs``
  such as colours and normals, per-face ``face_attrs`` such as UVs, comments, texture) and
  ``compact``, ``face_areas``, ``face_normals``, ``vertex_normals``, ``edges``;
- :mod:`twinkit.mesh.ply`: the one PLY path (``read_ply``, ``write_ply``, ``read_mesh`` with the
  checks of a pipeline step, ``write_colored_ply``);
- :mod:`twinkit.mesh.obj`: textured OBJ + MTL (``read_obj``, ``write_obj``);
- :mod:`twinkit.mesh.glb`: the one GLB writer (``write_textured_glb``, ``write_colored_glb``);
- :mod:`twinkit.mesh.topology`: ``components``, ``edge_face_incidence``, ``boundary_loops``,
  ``remove_vertices``, ``bad_faces`` / ``drop_bad_faces`` (duplicate and degenerate faces);
  closing a boundary loop is :mod:`twinkit.street.holes` (``fan_fill`` for holes anywhere on a surface);
- :mod:`twinkit.mesh.raster`: ``face_raster`` / ``face_mask``, the one top-down raster of a mesh (the face
  each pixel sees from above, painter's order by a key; edge rules ``centre`` and ``scanline``);
- :mod:`twinkit.mesh.o3d`: ``to_o3d_mesh`` / ``to_o3d_cloud`` (open3d imported when called).

Only numpy is imported with this package (PLY is read and written with numpy alone); scipy, open3d
and Pillow are imported by the
functions that need them (install them with the ``twinkit[mesh]`` extra). ``import twinkit``
does not import this package.
"""
from __future__ import annotations

from .core import Mesh, compact, edges, face_areas, face_normals, vertex_normals
from .o3d import to_o3d_cloud, to_o3d_mesh
from .obj import read_obj, write_obj
from .ply import ply_vertex_count, read_mesh, read_ply, write_colored_ply, write_ply
from .topology import bad_faces, boundary_loops, components, drop_bad_faces, edge_face_incidence, remove_vertices

__all__ = [
    "Mesh", "compact", "edges", "face_areas", "face_normals", "vertex_normals",
    "to_o3d_cloud", "to_o3d_mesh", "read_obj", "write_obj", "ply_vertex_count",
    "read_mesh", "read_ply", "write_colored_ply", "write_ply",
    "bad_faces", "boundary_loops", "components", "drop_bad_faces", "edge_face_incidence",
    "remove_vertices",
]

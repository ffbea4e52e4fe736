"""twinkit-pointcloud: the point-cloud reconstruction branch of twinkit.

Modules (each usable without twinkit's engine):

- :mod:`readers`  E57 / LAS / LAZ / PLY -> :class:`readers.Cloud` in the site frame (rules: twinkit.geo.crs)
- :mod:`normals`  estimation and orientation of normals
- :mod:`poisson`  screened Poisson (open3d, optionally pymeshlab)
- :mod:`cleanup`  density / distance trimming, components, non-manifold repair, hole filling
- :mod:`simplify` quadric decimation (fast-simplification) and clustering fallback
- :mod:`uv`, :mod:`texture`  UV atlas and colour baking from the dense mesh
- :mod:`metrics`  distances and diagnostics
- :mod:`plugin`   the twinkit step functions and their parameter dataclasses

Nothing heavy is imported at package import time.
"""
__version__ = "0.1.0"

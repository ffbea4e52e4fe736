"""twinkit-export: per-class sub-meshes of the labelled textured mesh, and FBX (bpy), USD (usd-core),
glTF/GLB and CARLA 0.9.16 import-package exporters. See docs/export.md; plugins in ``plugin.py``."""

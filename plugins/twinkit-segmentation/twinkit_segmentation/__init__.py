"""View-based 3D semantic segmentation of meshes for twinkit."""

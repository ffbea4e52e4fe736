"""twinkit.surface: the surface algorithms that several plugins share, with a documented API.

Modules (import the one you need; each imports its heavy library only inside its functions):

- :mod:`twinkit.surface.poisson`: screened Poisson reconstruction (open3d, or pymeshlab),
  ``poisson_open3d``, ``poisson_pymeshlab``, ``depth_for_voxel``, ``voxel_for_depth``;
- :mod:`twinkit.surface.cleanup`: the clean-up of a Poisson mesh against its cloud (density and
  distance trim with the gap rule, small components, non-manifold edges, small holes, ground
  fill, distance to the cloud): ``CleanOptions``, ``clean_mesh`` and its parts;
- :mod:`twinkit.surface.simplify`: quadric / clustering simplification to a face budget with
  attributes re-sampled from the dense mesh: ``simplify_mesh``;
- :mod:`twinkit.surface.groundfill`: filling the ground's occlusion shadows: ``fill_ground_holes``;
- :mod:`twinkit.surface.closest`: closest points on a triangle surface: ``Surface``; values at
  barycentric points: ``barycentric_mix``;
- :mod:`twinkit.surface.metrics`: ``cloud_to_mesh`` distances;
- :mod:`twinkit.surface.texture`: texture-atlas rasterising (``rasterize``), texel writes
  (``put_texels``), gap filling (``fill_empty_texels``) and ``write_png``;
- :mod:`twinkit.surface.compiled`: loops compiled by numba when it is installed (``compiled``), each
  with numpy code that gives the same numbers; the argument types a run uses compiled at set-up (``ahead``,
  ``compile_ahead``);
- :mod:`twinkit.surface.measure`: wall time and peak memory of a block (``Measure``; a step times its parts with ``ctx.substep``).

Meshes are :class:`twinkit.mesh.Mesh` (metres, site frame). Heavy dependencies come with the
``twinkit[mesh]`` extra (scipy, open3d, fast-simplification, Pillow, numba).
"""

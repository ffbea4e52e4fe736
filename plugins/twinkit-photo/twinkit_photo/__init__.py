"""twinkit-photo: the photo branch of twinkit (thesis 3.3.1, 3.4.1, 4.3.2 with open tools).

Modules (each usable without twinkit's engine):

- :mod:`images`  photo folders, validation, EXIF GPS and focal length
- :mod:`sfm`     pycolmap features, matching (exhaustive / sequential / spatial), incremental or global mapping
- :mod:`georef`  levelling, GPS similarity (twinkit.geo's RANSAC), ground-control points (Umeyama)
- :mod:`patchmatch` CPU PatchMatch stereo (slanted planes, propagation, best-of-neighbours NCC)
- :mod:`dense`   views, neighbours, the plane sweep, multi-view consistency fusion
- :mod:`georef_fit` the georeference step's route: which fit, the fits, outlier cameras, what is written
- :mod:`roi`     the region of interest: ground plane and box
- :mod:`dense_cloud` the dense step's pipeline: backend, fusion tolerance, depth-map passes, points.ply
- :mod:`projtex` texture from the photos (projection, photo-consistency, blending)
- :mod:`report`  this plugin's section of the run report
- :mod:`params`  the steps' parameters (range and help per field)
- :mod:`files`   JSON reads with a clear error, PLY point clouds
- :mod:`plugin`  the twinkit steps ``sfm``, ``georeference``, ``roi``, ``dense``, ``photo_texture`` (every
  step body, each thin)
"""
__version__ = "0.1.0"

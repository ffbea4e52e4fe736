"""twinkit-photo: the photo branch of twinkit (thesis 3.3.1, 3.4.1, 4.3.2 with open tools).

Modules (each usable without twinkit's engine):

- :mod:`images`  photo folders, validation, EXIF GPS and focal length
- :mod:`sfm`     pycolmap features, matching (exhaustive / sequential / spatial), incremental or global mapping
- :mod:`georef`  levelling, GPS similarity (twinkit.geo's RANSAC), ground-control points (Umeyama)
- :mod:`patchmatch` CPU PatchMatch stereo (slanted planes, propagation, best-of-neighbours NCC)
- :mod:`dense`   views, neighbours, the plane sweep, multi-view consistency fusion
- :mod:`plugin`  the twinkit steps ``sfm``, ``georeference``, ``roi``, ``dense``
"""
__version__ = "0.1.0"

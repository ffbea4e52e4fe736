"""OpenDRIVE under a similarity: moved to the shared library (:mod:`twinkit.geo.xodr`), where the road
source ``opendrive`` (twinkit-roads) uses it too; the names stay importable from here."""
from twinkit.geo.xodr import LENGTHS, POLYS, XodrFrameError, transform_xodr  # noqa: F401

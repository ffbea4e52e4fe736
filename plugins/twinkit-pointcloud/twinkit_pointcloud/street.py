"""Whether a capture can be a street at all: the one check that refuses a cloud before any long step.

A street twin needs at least a carriageway and its sidewalks: two 3.25 m lanes and two 2 m pavements are
about 10 m across, and a street capture is longer along the street than across it. A cloud whose box is
smaller than ``min_extent_m`` on its longer horizontal side is an object or a room (the shared indoor E57
scan of a pump is 4.6 x 4.5 m), not a street: meshing, labelling and road building would run for minutes
and end in a twin no simulator can drive on. ``read_cloud``'s preflight checks the box from the file's
header before the first step; ``read_cloud`` checks the points (files whose header gives no box).
"""
from __future__ import annotations

#: the default smallest longer horizontal side of a street capture, metres (see the module text)
MIN_STREET_EXTENT_M = 10.0


def not_a_street(name: str, size, min_extent_m: float) -> str | None:
    """A one-line refusal when the box ``size`` (x, y, z metres in the site frame) is too small for a street;
    None when it is big enough or the check is off (``min_extent_m`` 0)."""
    if not min_extent_m or min_extent_m <= 0:
        return None
    sx, sy = float(size[0]), float(size[1])
    if max(sx, sy) >= min_extent_m:
        return None
    return (f"{name}: the capture spans only {sx:.1f} x {sy:.1f} m horizontally ({float(size[2]):.1f} m high): "
            f"not a street (a street capture is at least {min_extent_m:g} m long: a carriageway and its sidewalks). "
            f"This looks like an object or indoor scan; twinkit builds street twins from street captures. "
            f"If it is a street in the wrong units, set site.crs or site.cloud_frame; to go on anyway, "
            f"steps.read_cloud.min_street_extent_m=0")


#: a capture thinner than this (metres) across its flattest direction is flat: a 2D capture, not a street
FLAT_M = 1e-3


def flat_capture(name: str, size, points=None) -> str | None:
    """A one-line refusal when the capture is flat (2D): its box ``size`` (x, y, z metres) is thinner than
    :data:`FLAT_M` on an axis (all z equal: a ground plan, a single slice; all x or y equal: a profile), or,
    given ``points`` (n, 3), they lie in one tilted plane (the smallest principal spread, on a fixed sample
    of at most 200,000 points). None for a 3D capture. Meshing a flat cloud builds no street (no kerbs, no
    walls); no setting turns this check off."""
    import numpy as np

    size = np.asarray(size, dtype=np.float64)
    thin = [i for i in range(3) if size[i] < FLAT_M]
    how = None
    if thin:
        ax = "xyz"[thin[-1]]
        what = ("height (all z equal: a ground plan or a horizontal slice)" if ax == "z" else
                f"{ax} (all {ax} equal: a single vertical profile)")
        how = f"it spans {size[0]:.2f} x {size[1]:.2f} x {size[2]:.2f} m, only {size[thin[-1]]:.4f} m in {what}"
    elif points is not None and len(points) >= 3:
        pts = np.asarray(points, dtype=np.float64)
        if len(pts) > 200_000:
            pts = pts[np.random.default_rng(0).choice(len(pts), 200_000, replace=False)]
        q = pts - pts.mean(axis=0)
        thickness = float(np.sqrt(max(np.linalg.eigvalsh(q.T @ q / len(q))[0], 0.0)))
        if thickness < FLAT_M:
            how = f"all its points lie in one plane (spread {thickness:.5f} m across it)"
    if how is None:
        return None
    return (f"{name}: the cloud is flat (2D): {how}; a street twin needs a 3D capture with heights - "
            f"export the cloud with its z values (or check site.cloud_frame)")

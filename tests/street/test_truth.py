"""Ground truth moved onto other points (twinkit.street.truth): the nearest face's label."""
import numpy as np
import pytest

pytest.importorskip("open3d")

from twinkit.cityscapes import CAR, ROAD, SIDEWALK  # noqa: E402
from twinkit.street.truth import transfer_labels  # noqa: E402


def _two_faces():
    # a unit square of two triangles: face 0 (lower right) road, face 1 (upper left) sidewalk;
    # vertex labels: road at (0,0) and (1,0), sidewalk at (1,1), car at (0,1)
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    return v, f, np.array([ROAD, SIDEWALK], np.uint8), np.array([ROAD, ROAD, SIDEWALK, CAR], np.uint8)


def test_face_labels_win_and_the_distance_is_to_the_surface():
    v, f, fl, vl = _two_faces()
    q = np.array([[0.9, 0.1, 0.5], [0.1, 0.9, -0.25], [0.2, 0.75, 0.0]])
    lab, dist = transfer_labels(v, f, q, face_labels=fl, vertex_labels=vl)
    assert lab.dtype == np.uint8 and dist.dtype == np.float32
    assert lab.tolist() == [ROAD, SIDEWALK, SIDEWALK]
    np.testing.assert_allclose(dist, [0.5, 0.25, 0.0], atol=1e-6)


def test_vertex_labels_take_the_corner_nearest_the_closest_point():
    v, f, _, vl = _two_faces()
    q = np.array([[0.05, 0.9, 3.0], [0.95, 0.05, 0.1], [0.9, 0.8, 0.0]])
    lab, _ = transfer_labels(v, f, q, vertex_labels=vl)
    assert lab.tolist() == [CAR, ROAD, SIDEWALK]
    with pytest.raises(ValueError):
        transfer_labels(v, f, q)

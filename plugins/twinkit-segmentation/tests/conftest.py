"""Fixtures of the segmentation tests (scenes come from twinkit_segmentation.synthetic)."""
from __future__ import annotations

import pytest

from twinkit_segmentation.synthetic import write_scene


@pytest.fixture(scope="session")
def scene_files(tmp_path_factory):
    return write_scene(tmp_path_factory.mktemp("scene"))

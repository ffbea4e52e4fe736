from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[3]
SHARED_PHOTOS = REPO.parent / "shared" / "data" / "photos"


def shared_photos(name: str) -> Path:
    p = SHARED_PHOTOS / name
    if not p.exists():
        pytest.skip(f"needs ../shared/data/photos/{name} (shared sample data not present)")
    return p


@pytest.fixture
def ctx(tmp_path):
    from twinkit.testing import make_context

    return make_context(tmp_path / "work", site={"name": "test"})

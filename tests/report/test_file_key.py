"""The report's cache key of a file (twinkit.report.run.file_key): pictures are cached under it."""
from __future__ import annotations

import os

from twinkit.report.run import file_key


def test_recorded_hash_is_the_key(tmp_path):
    p = tmp_path / "a.png"
    p.write_bytes(b"x")
    assert file_key(p, {"a.png": "abc123"}) == "abc123"


def test_unrecorded_file_gets_a_stamp_that_changes_with_the_file(tmp_path):
    p = tmp_path / "a.png"
    p.write_bytes(b"x")
    k1 = file_key(p)
    assert isinstance(k1, str) and k1 == file_key(p, {"other.png": "h"})
    p.write_bytes(b"xy")  # other size
    os.utime(p, ns=(1, 1))
    k2 = file_key(p)
    assert isinstance(k2, str) and k2 != k1

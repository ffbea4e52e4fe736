"""twinkit.deflate: npz files any zip reader opens, on ISA-L and on zlib."""
from __future__ import annotations

import zipfile

import numpy as np
import pytest


@pytest.mark.parametrize("deflate", ["isal", "zlib"])
def test_write_npz_reads_back_as_numpy_writes_it(tmp_path, monkeypatch, deflate):
    from twinkit import deflate as D

    if deflate == "isal":
        pytest.importorskip("isal")
    monkeypatch.setenv("TWINKIT_DEFLATE", deflate)
    rng = np.random.default_rng(5)
    # a vertex map's kind of content: runs of one id, and a background of -1
    vertex = np.repeat(rng.integers(-1, 200_000, (512, 128)), 8, axis=1).astype(np.int32)
    extra = rng.normal(size=(7, 3))
    D.write_npz(tmp_path / "a.npz", 1, vertex=vertex, extra=extra)
    with np.load(tmp_path / "a.npz") as z:
        assert sorted(z.files) == ["extra", "vertex"]
        assert z["vertex"].dtype == np.int32 and np.array_equal(z["vertex"], vertex)
        assert np.array_equal(z["extra"], extra)
    with zipfile.ZipFile(tmp_path / "a.npz") as z:
        assert z.testzip() is None  # every entry's CRC-32 holds
        info = z.getinfo("vertex.npy")
        assert info.compress_type == zipfile.ZIP_DEFLATED and info.compress_size < info.file_size / 4
    # the same arrays give the same file: no time of writing in it
    D.write_npz(tmp_path / "c.npz", 1, vertex=vertex, extra=extra)
    assert (tmp_path / "c.npz").read_bytes() == (tmp_path / "a.npz").read_bytes()
    with zipfile.ZipFile(tmp_path / "a.npz") as z:
        assert {i.date_time for i in z.infolist()} == {(1980, 1, 1, 0, 0, 0)}
    # the same arrays as numpy's own writer gives
    np.savez_compressed(tmp_path / "b.npz", vertex=vertex)
    assert np.array_equal(np.load(tmp_path / "b.npz")["vertex"], np.load(tmp_path / "a.npz")["vertex"])


def test_backend_follows_the_environment(monkeypatch):
    from twinkit import deflate as D

    monkeypatch.setenv("TWINKIT_DEFLATE", "zlib")
    assert D.backend() == "zlib"
    data = bytes(range(256)) * 100
    assert D.crc32(data) == zipfile.crc32(data)
    monkeypatch.delenv("TWINKIT_DEFLATE")
    try:
        import isal  # noqa: F401
    except ImportError:
        assert D.backend() == "zlib"
    else:
        assert D.backend() == "isal"
        import zlib

        assert D.crc32(data) == zlib.crc32(data) and D.adler32(data) == zlib.adler32(data)
        z = D.compressor(1)
        assert zlib.decompress(z.compress(data) + z.flush(), -15) == data

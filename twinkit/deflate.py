"""Fast deflate for the files a run writes many of (rendered views' PNGs, vertex maps, texture atlases).

Intel's ISA-L (the ``isal`` package, a dependency of ``twinkit[mesh]``) deflates a rendered 1024 x 512 view
about 3x faster than zlib at level 1 (4.4 against 12.3 ms, ``bench_render.py``) for a file 3 % larger, and
computes CRC-32 and Adler-32 5x faster; its streams are ordinary deflate, so every PNG and zip reader reads
them. Without ``isal`` the same functions run
on Python's zlib. ``TWINKIT_DEFLATE=zlib`` forces zlib (to compare, or to get zlib's exact bytes).

Levels: zlib's 0-9; ISA-L has 0-3, so a zlib level ``n`` from 1 maps to ISA-L ``min(n, 3)``; level 0 stays
zlib's (stored, not compressed).
"""
from __future__ import annotations

import os
import struct
import zlib

import numpy as np


def _isal():
    if os.environ.get("TWINKIT_DEFLATE", "").lower() == "zlib":
        return None
    try:
        from isal import isal_zlib
    except ImportError:
        return None
    return isal_zlib


def backend() -> str:
    """``isal`` or ``zlib``: which library deflates."""
    return "isal" if _isal() is not None else "zlib"


def compressor(level: int = 1, rle: bool = False):
    """A raw-deflate compressor object (``compress`` / ``flush``, zlib's interface; wbits -15). ``rle``
    (zlib only, ISA-L ignores it): matches only runs of the byte before (zlib's Z_RLE strategy)."""
    isal = _isal()
    if isal is not None and level > 0:
        return isal.compressobj(min(int(level), 3), isal.DEFLATED, -15)
    return zlib.compressobj(int(level), zlib.DEFLATED, -15, 8, zlib.Z_RLE if rle else zlib.Z_DEFAULT_STRATEGY)


def crc32(data, value: int = 0) -> int:
    isal = _isal()
    return (isal.crc32 if isal is not None else zlib.crc32)(data, value)


def adler32(data, value: int = 1) -> int:
    isal = _isal()
    return (isal.adler32 if isal is not None else zlib.adler32)(data, value)


def write_npz(path, level: int = 1, **arrays) -> None:
    """``np.savez_compressed``'s file (one deflated ``<name>.npy`` zip entry per array, read back by
    ``np.load(path)[name]``) written with :func:`compressor` at ``level``: at level 1 a rendered view's
    (512, 1024) int32 vertex map takes 2 ms here against 6 ms with zipfile's zlib and 19 ms with
    ``np.savez_compressed``, at zlib level 1's size. The entries carry zip's epoch as their time, so the same
    arrays give the same file (a step re-run to the same result leaves the steps after it stored; zipfile stamps
    the time of writing). Zip64 is not written: each array must stay under 4 GiB."""
    import io

    dos_time, dos_date = 0, (1 << 5) | 1  # 1980-01-01 00:00
    central, offset = [], 0
    with open(path, "wb") as fh:
        for name, arr in arrays.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.asanyarray(arr), allow_pickle=False)
            raw = buf.getbuffer()
            z = compressor(level)
            body = z.compress(raw) + z.flush()
            crc, fname = crc32(raw) & 0xFFFFFFFF, f"{name}.npy".encode()
            if len(raw) >= 0xFFFFFFFF or len(body) >= 0xFFFFFFFF or offset >= 0xFFFFFFFF:
                raise ValueError(f"{path}: array {name!r} is over 4 GiB; use np.savez_compressed")
            common = struct.pack("<HHHHHIIIHH", 20, 0, 8, dos_time, dos_date, crc, len(body), len(raw),
                                 len(fname), 0)
            fh.write(b"PK\x03\x04" + common + fname)
            fh.write(body)
            central.append(b"PK\x01\x02" + struct.pack("<H", 20) + common + struct.pack("<HHHII", 0, 0, 0, 0o600 << 16,
                                                                                         offset) + fname)
            offset += 30 + len(fname) + len(body)
        cd = b"".join(central)
        fh.write(cd + b"PK\x05\x06" + struct.pack("<HHHHIIH", 0, 0, len(central), len(central), len(cd), offset, 0))


"""A step that writes a block of bytes, for the engine benchmark."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from twinkit import hookimpl


@dataclass
class BlobParams:
    index: int = 0
    size_mb: float = 5.0


def blob(params: BlobParams, ctx, *, in_blob_bin: Path | None = None, out_blob_bin: Path) -> None:
    """Write size_mb of bytes that depend on the index (and read nothing else)."""
    block = (params.index.to_bytes(4, "little") * 256) * 1024  # 1 MiB
    with open(out_blob_bin, "wb") as f:
        for _ in range(int(params.size_mb)):
            f.write(block)


@hookimpl
def twinkit_register_steps(register):
    register("blob", blob, params=BlobParams)

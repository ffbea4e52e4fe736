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


@dataclass
class MatmulParams:
    n: int = 600
    repeats: int = 40
    index: int = 0


def matmul(params: MatmulParams, ctx, *, out_timing_txt: Path) -> dict:
    """Multiply matrices with numpy's BLAS (its thread pool set to ctx.threads by the engine); seconds per product."""
    import time

    import numpy as np

    rng = np.random.default_rng(params.index)
    a = rng.random((params.n, params.n))
    t0 = time.perf_counter()
    for _ in range(params.repeats):
        a = a @ a
        a /= np.abs(a).max()
    per = (time.perf_counter() - t0) / params.repeats
    out_timing_txt.write_text(f"{per:.5f} {ctx.threads}\n")
    return {"s_per_product": per, "threads": ctx.threads}


@hookimpl
def twinkit_register_steps(register):
    register("blob", blob, params=BlobParams)
    register("matmul", matmul, params=MatmulParams)

"""A stand-in step that times its parts with ``ctx.substep`` (loaded with
TWINKIT_PLUGIN_MODULES=...,tests.support.substep_plugins)."""
from __future__ import annotations

from pathlib import Path

from twinkit import hookimpl


def timed(params, ctx, *, in_data_txt: Path, out_timed_txt: Path) -> dict:
    """Reads the number in three substeps: ``read`` (twice), ``work`` with ``work/inner`` inside it."""
    with ctx.substep("read"):
        v = int(Path(in_data_txt).read_text().splitlines()[0])
    with ctx.substep("read"):
        Path(in_data_txt).read_text()
    with ctx.substep("work"):
        with ctx.substep("inner"):
            data = bytearray(8 << 20)  # something to hold
        out_timed_txt.write_text(f"{v + len(data) // (8 << 20)}\n")
    return {"value": v}


@hookimpl
def twinkit_register_steps(register):
    register("timed", timed)

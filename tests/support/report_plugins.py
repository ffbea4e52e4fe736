"""A step that writes a GLB, for the report's tests (load with
TWINKIT_PLUGIN_MODULES=tests.support.engine_plugins,tests.support.report_plugins)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from twinkit import hookimpl
from twinkit.ranges import param


@dataclass
class GlbParams:
    faces: int = param(20_000, ge=1, help="Triangles of the model (about 60 bytes each).")
    seed: int = param(0, help="Seed of the random vertex positions and colours.")


def make_glb(params: GlbParams, ctx, *, out_twin_glb: Path) -> None:
    """A vertex-coloured GLB of random triangles (the run's own GLB, as the export's)."""
    from twinkit.mesh.glb import write_colored_glb

    rng = np.random.default_rng(params.seed)
    xyz = rng.uniform(-10, 10, (params.faces * 3, 3)).astype(np.float32)
    xyz[:, 2] *= 0.1
    faces = np.arange(params.faces * 3, dtype=np.int64).reshape(-1, 3)
    colors = rng.integers(0, 255, (len(xyz), 3), dtype=np.uint8)
    write_colored_glb(out_twin_glb, xyz, faces, colors, None)


@hookimpl
def twinkit_register_steps(register):
    register("make_glb", make_glb, params=GlbParams)

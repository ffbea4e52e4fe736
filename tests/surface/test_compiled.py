"""The loops compiled ahead at set-up (twinkit.surface.compiled ``ahead``) are the ones a run then loads."""
from __future__ import annotations

import importlib
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from twinkit.surface import compiled as comp

ROOT = Path(__file__).resolve().parents[2]

numba = pytest.importorskip("numba")

CALL = """
import json, numpy as np
from twinkit.surface.compiled import compiled
from twinkit.surface.texture import _put_loop, _raster_loop, put_texels, rasterize
fid, bary, row, col = next(iter(rasterize(np.random.default_rng(0).random((6, 3, 2)), 32)))
put_texels(np.zeros((32, 32, 3), np.uint8), np.zeros((32, 32), bool), row, col, 255 * bary)
print(json.dumps({f.__name__: [len(compiled(f).stats.cache_hits), len(compiled(f).stats.cache_misses)]
                  for f in (_raster_loop, _put_loop)}))
"""


def _python(code: str, cache: Path) -> str:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    return subprocess.run([sys.executable, "-c", code], env=env, cwd=ROOT, capture_output=True, text=True,
                          check=True).stdout


def test_a_run_loads_the_loops_compiled_ahead_instead_of_compiling_them(tmp_path):
    cold = json.loads(_python(CALL, tmp_path / "cold").strip().splitlines()[-1])
    assert cold == {"_raster_loop": [0, 1], "_put_loop": [0, 1]}  # nothing cached: each compiles at its call
    out = _python("from twinkit.surface.compiled import compile_ahead; "
                  "print(compile_ahead(('twinkit.surface.texture',)))", tmp_path / "ahead")
    assert "('twinkit.surface.texture._raster_loop', 2)" in out and "_put_loop', 1)" in out
    warm = json.loads(_python(CALL, tmp_path / "ahead").strip().splitlines()[-1])
    assert warm == {"_raster_loop": [1, 0], "_put_loop": [1, 0]}  # loaded from what set-up compiled


def test_every_compiled_loop_carries_the_types_a_run_calls_it_with():
    """Each function handed to ``compiled(...)`` in the code is marked with ``ahead`` in a module that
    AHEAD_MODULES lists, with signatures numba parses (a loop added without a mark would compile at a run's
    first call again)."""
    from numba.core.sigutils import normalize_signature

    for name in comp.AHEAD_MODULES:
        importlib.import_module(name)
    marked = {(fn.__module__, fn.__name__): sigs for fn, sigs in comp._AHEAD.items()}
    used = set()
    for path in [*ROOT.glob("twinkit/**/*.py"), *ROOT.glob("plugins/*/twinkit_*/**/*.py")]:
        for fn in re.findall(r"\bcompiled\((_\w+)\)", path.read_text(encoding="utf-8")):
            pkg = path.relative_to(ROOT).parts
            mod = ".".join(pkg[2:] if pkg[0] == "plugins" else pkg)[:-3]
            used.add((mod, fn))
    assert len(used) >= 10
    assert used <= set(marked), f"compiled without an ahead mark: {sorted(used - set(marked))}"
    for sigs in marked.values():
        assert sigs and all(normalize_signature(s)[0] for s in sigs)

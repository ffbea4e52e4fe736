"""Plain Python loops compiled by numba when it is installed (imported at the first call, never at import).

A loop handed to :func:`compiled` does the same floating-point operations in the same order as the numpy
code it stands in for (numba neither reorders nor fuses them without ``fastmath``), so both give the same
numbers; the numpy code stays as the fallback where numba is missing.

A loop marked with :func:`ahead` names the argument types a pipeline run calls it with; ``make setup`` compiles
those (:func:`compile_ahead`, ``python -m twinkit.surface.compiled``) into numba's cache, so that the first run
after set-up loads machine code instead of compiling it. A call with other types compiles at that call, as
without the mark.
"""
from __future__ import annotations

import importlib
import time
from typing import Callable

_DONE: dict[Callable, Callable | None] = {}
_AHEAD: dict[Callable, tuple[str, ...]] = {}

#: False: every caller runs its numpy code (tests and benchmarks compare the two)
ENABLED = True

#: the modules whose loops carry :func:`ahead` marks (a module not installed is skipped)
AHEAD_MODULES = ("twinkit.surface.texture", "twinkit.surface.closest", "twinkit.surface.watertight",
                 "twinkit.mesh.topology", "twinkit_segmentation.render", "twinkit_segmentation.viewholes",
                 "twinkit_segmentation.oversegment")


def compiled(fn: Callable) -> Callable | None:
    """``fn`` compiled by numba (``nogil``: threads run it side by side; machine code cached on disk next to
    its module), or None when numba is missing or broken or :data:`ENABLED` is False (the caller then runs
    its numpy code)."""
    if not ENABLED:
        return None
    if fn not in _DONE:
        try:
            import numba

            _DONE[fn] = numba.njit(cache=True, nogil=True)(fn)
        except Exception:  # pragma: no cover - numba missing or broken: the numpy code
            _DONE[fn] = None
    return _DONE[fn]


def ahead(*signatures: str) -> Callable[[Callable], Callable]:
    """Decorator: ``fn`` is called with these argument types (numba signature strings, e.g.
    ``"(float32[:, ::1], int64)"``; a read-only array ``Array(uint32, 2, 'C', readonly=True)``) in a pipeline
    run, so :func:`compile_ahead` compiles them. Returns ``fn`` itself."""
    def mark(fn: Callable) -> Callable:
        _AHEAD[fn] = tuple(signatures)
        return fn
    return mark


def compile_ahead(modules: tuple[str, ...] = AHEAD_MODULES) -> list[tuple[str, int]]:
    """Import ``modules`` and compile every signature their :func:`ahead` marks name into numba's on-disk cache
    (one already cached is loaded, not compiled again). Returns (loop, signatures) per loop; empty without numba."""
    for name in modules:
        try:
            importlib.import_module(name)
        except ImportError:
            continue
    from numba.core.sigutils import normalize_signature

    done = []
    for fn, sigs in _AHEAD.items():
        if fn.__module__ not in modules:
            continue
        disp = compiled(fn)
        if disp is None:
            return []
        for sig in sigs:  # as a tuple of types: numba keys its cache by what compile() is given, as a call does
            disp.compile(tuple(normalize_signature(sig)[0]))  # type: ignore[attr-defined]
        done.append((f"{fn.__module__}.{fn.__name__}", len(sigs)))
    return done


def main() -> None:
    """``python -m twinkit.surface.compiled`` (``make setup``): :func:`compile_ahead`, with its count and time."""
    t0 = time.perf_counter()
    loops = compile_ahead()
    print(f"compiled ahead: {sum(n for _, n in loops)} signatures of {len(loops)} loops "
          f"in {time.perf_counter() - t0:.1f} s" if loops else "compiled ahead: nothing (numba missing)")


if __name__ == "__main__":  # run as a script this file is another module: the marks live in the imported one
    importlib.import_module("twinkit.surface.compiled").main()

"""Plain Python loops compiled by numba when it is installed (imported at the first call, never at import).

A loop handed to :func:`compiled` does the same floating-point operations in the same order as the numpy
code it stands in for (numba neither reorders nor fuses them without ``fastmath``), so both give the same
numbers; the numpy code stays as the fallback where numba is missing.
"""
from __future__ import annotations

from typing import Callable

_DONE: dict[Callable, Callable | None] = {}

#: False: every caller runs its numpy code (tests and benchmarks compare the two)
ENABLED = True


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

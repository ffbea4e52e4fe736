"""twinkit: street captures to simulation-ready digital twins.

Public API for plugin authors::

    from twinkit import hookimpl, StepContext

Importing twinkit imports no heavy library (no open3d, torch, bpy, pycolmap).
"""
from __future__ import annotations

import pluggy

__version__ = "0.1.0"

hookimpl = pluggy.HookimplMarker("twinkit")

from twinkit.context import StepContext  # noqa: E402
from twinkit.errors import ConfigError, TwinkitError, PluginError, InputError, StepError  # noqa: E402

__all__ = [
    "hookimpl",
    "StepContext",
    "TwinkitError",
    "ConfigError",
    "PluginError",
    "InputError",
    "StepError",
    "__version__",
]

"""Errors that twinkit reports to users as one clear message (no traceback)."""
from __future__ import annotations


class TwinkitError(Exception):
    """Base class: the message says what happened, where, and what to do next."""

    exit_code = 2


class PluginError(TwinkitError):
    """A plugin could not be loaded, registered or found."""


class ConfigError(TwinkitError):
    """A config, recipe or site is missing, unparsable or inconsistent."""


class InputError(TwinkitError):
    """An input file is missing, corrupt or unsuitable; names the file and the fix."""


class StepError(TwinkitError):
    """A step failed; names the step and plugin."""

    exit_code = 1


class LockedError(TwinkitError):
    """Another twinkit run holds the workspace."""


class ManualActionPending(TwinkitError):
    """A manual step waits for a file and the run is not interactive."""

    exit_code = 3


def say_error(msg: str, code: int = 2) -> int:
    """Print the command's one-line error (``twinkit: error: <msg>``) to stderr; return the exit status ``code``."""
    import sys

    from twinkit.manifest import redact

    print(f"twinkit: error: {redact(msg)}", file=sys.stderr)  # a value read through ${oc.env:...} never shown
    return code

"""Operating-system errors (disk full, permission denied) explained in one line naming the cause and the path."""
from __future__ import annotations

import errno
import re
import shutil
from pathlib import Path

from twinkit.errors import InputError, StepError, TwinkitError


#: numpy's words for a short write (``ndarray.tofile``, ``np.save``): the bytes did not all reach the file
_SHORT_WRITE = re.compile(r"(\d+) requested and (\d+) written")


def os_error_in(exc: BaseException | None) -> OSError | None:
    """The OSError behind an exception (its cause or context chain), if any. A short write without an errno
    (numpy's ``369223 requested and 302636 written``) is a full disk (ENOSPC), as ``write(2)`` says then."""
    seen = 0
    while exc is not None and seen < 10:
        if isinstance(exc, OSError):
            if exc.errno is None and _SHORT_WRITE.search(str(exc)):
                return OSError(errno.ENOSPC, "No space left on device", getattr(exc, "filename", None))
            return exc
        if "database or disk is full" in str(exc):  # sqlite3.OperationalError
            return OSError(errno.ENOSPC, "No space left on device")
        exc = exc.__cause__ or exc.__context__
        seen += 1
    return None


def os_text(exc: OSError, where: Path) -> str:
    """One line for an operating-system error: the cause and the path, and what to do."""
    path = Path(exc.filename) if exc.filename else where
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        probe = path
        while not probe.exists() and probe != probe.parent:
            probe = probe.parent
        try:
            free = f"{shutil.disk_usage(probe).free / 2**20:.0f} MiB free"
        except OSError:
            free = "free space unknown"
        return (f"disk full (no space left on the device) writing {path} ({free}); free some space (twinkit gc "
                f"removes stored results nothing refers to) or set engine.outputs_dir=<a folder on another disk>")
    if exc.errno in (errno.EACCES, errno.EPERM):
        return f"{path}: permission denied; make it readable (and writable for outputs) by this user"
    return f"{path}: {exc.strerror or exc}"


def explaining_os_errors(run, where: Path):
    """Run ``run()``; an OSError (disk full, unreadable file) becomes one line naming the cause and the path."""
    try:
        return run()
    except TwinkitError as exc:
        os_exc = os_error_in(exc.__cause__)
        if os_exc is None or os_exc.errno not in (errno.ENOSPC, errno.EDQUOT, errno.EACCES, errno.EPERM):
            raise
        head = str(exc).split(" failed: ")[0]
        # an unreadable file is the input's problem (exit 2); a full disk is the run's (the step failed, exit 1)
        kind = InputError if os_exc.errno in (errno.EACCES, errno.EPERM) else type(exc)
        raise kind(f"{head} failed: {os_text(os_exc, where)}") from exc.__cause__
    except OSError as exc:  # outside a step: hashing an input, the store, the hash cache
        exc = os_error_in(exc) or exc
        if exc.errno in (errno.ENOSPC, errno.EDQUOT):
            raise StepError(os_text(exc, where)) from exc
        raise InputError(os_text(exc, where)) from exc
    except Exception as exc:  # e.g. sqlite3's "database or disk is full" from the hash cache
        os_exc = os_error_in(exc)
        if os_exc is None or os_exc.errno not in (errno.ENOSPC, errno.EDQUOT):
            raise
        raise StepError(os_text(os_exc, where)) from exc

"""Steps run in a child process, so that a crash in native code, or a native call that does not return,
costs the step and not the run.

:func:`run_in_child` forks (Linux), runs the function in the child and sends back its result or exception
through a pipe. The run then sees:

- a crash (SIGSEGV, SIGABRT, the kernel's OOM kill, ...) as a :class:`NativeCrash` of that step, with
  the signal's name; ``faulthandler`` writes the Python stack of the crash into the run log;
- Ctrl-C or SIGTERM at once, even during a long C call: the child gets SIGINT, and is killed when it
  has not stopped after ``$TWINKIT_KILL_GRACE_S`` seconds (default 3); its temporary folder is removed.

The child dies with the run (``PR_SET_PDEATHSIG``), and so do fan-out workers (:func:`die_with_parent`).
``TWINKIT_ISOLATE_STEPS=0`` runs steps in the run's own process, as before November 2026.
"""
from __future__ import annotations

import contextlib
import logging
import os
import pickle
import signal
import sys
import time
import traceback
from typing import Any, Callable

from twinkit.signals import _raise_terminated, die_with_parent, raise_interrupt

log = logging.getLogger("twinkit")


class NativeCrash(RuntimeError):
    """The process running a step died from a signal (``.signal``: its number)."""

    signal: int = 0


def isolation_enabled() -> bool:
    return hasattr(os, "fork") and os.environ.get("TWINKIT_ISOLATE_STEPS", "1").lower() not in ("0", "false", "no")


def _grace_s() -> float:
    try:
        return float(os.environ.get("TWINKIT_KILL_GRACE_S", "3"))
    except ValueError:
        return 3.0


def _signal_name(sig: int) -> str:
    try:
        return signal.Signals(sig).name
    except ValueError:
        return f"signal {sig}"


def _child(fn: Callable[..., Any], kwargs: dict, w: int, parent: int, threads: int | None) -> None:
    code = 0
    try:
        die_with_parent(parent)
        signal.signal(signal.SIGINT, raise_interrupt)
        signal.signal(signal.SIGTERM, _raise_terminated)
        from twinkit import progress

        progress._ACTIVE = None  # the parent's live display is not this process's to draw
        if threads:
            from twinkit.threads import limit_threads

            limit_threads(threads)
        try:
            result: tuple = ("ok", fn(**kwargs))
        except KeyboardInterrupt:
            result = ("interrupted", None)
        except BaseException as exc:  # sent to the parent, which raises it as the step's failure
            log.debug("".join(traceback.format_exception(exc)))
            try:
                pickle.loads(pickle.dumps(exc))
                result = ("error", exc)
            except Exception:
                result = ("error-text", (type(exc).__name__, str(exc)))
        try:
            data = pickle.dumps(result)
        except Exception as exc:
            data = pickle.dumps(("error-text", (type(exc).__name__, f"the step's result could not be sent back: {exc}")))
        with os.fdopen(w, "wb") as f:
            f.write(data)
    except BaseException:
        code = 1
    finally:
        with contextlib.suppress(Exception):
            for h in logging.getLogger("twinkit").handlers:
                h.flush()
            sys.stdout.flush()
            sys.stderr.flush()
        os._exit(code)


def run_in_child(fn: Callable[..., Any], kwargs: dict, *, threads: int | None = None,
                 cleanup: Callable[[int], None] | None = None, pass_signals: bool = False) -> Any:
    """``fn(**kwargs)`` in a forked child; its result, or its exception raised here.

    ``threads`` caps the child's native thread pools; ``cleanup(child_pid)`` runs after the child was
    killed (interrupt) or crashed, to remove what it left behind. ``pass_signals``: a Ctrl-C or SIGTERM of
    this process is passed on to the child, which stops by itself (a sweep's job: it writes its manifest),
    instead of being stopped within the grace period (main thread only)."""
    if not isolation_enabled():
        return fn(**kwargs)
    for h in logging.getLogger("twinkit").handlers:
        h.flush()
    r, w = os.pipe()
    parent = os.getpid()
    child: list[int] = []
    with _passing_signals(child, enabled=pass_signals):
        pid = os.fork()
        if pid == 0:  # pragma: no cover - the child leaves through os._exit
            os.close(r)
            _child(fn, kwargs, w, parent, threads)
        child.append(pid)
        os.close(w)
        chunks, status = _collect(r, pid, cleanup)
    if os.WIFSIGNALED(status):
        if cleanup is not None:
            cleanup(pid)
        sig = os.WTERMSIG(status)
        what = {int(signal.SIGKILL): "killed (SIGKILL: out of memory, or killed by hand)"}.get(sig, f"crashed with {_signal_name(sig)}")
        crash = NativeCrash(f"the process running it {what}, in native code; the Python stack of the crash, "
                            f"where known, is in the run log")
        crash.signal = sig
        raise crash
    try:
        kind, value = pickle.loads(b"".join(chunks))
    except Exception:
        raise NativeCrash(f"the process running it exited with code {os.WEXITSTATUS(status)} "
                          f"without a result") from None
    if kind == "ok":
        return value
    if kind == "interrupted":
        raise KeyboardInterrupt
    if kind == "error":
        raise value
    name, text = value
    raise type(name, (RuntimeError,), {})(text)


def _collect(r: int, pid: int, cleanup: Callable[[int], None] | None) -> tuple[list[bytes], int]:
    """The child's result bytes from pipe ``r`` and its exit status."""
    chunks = []
    try:
        with os.fdopen(r, "rb") as f:
            while True:
                b = f.read(1 << 16)
                if not b:
                    break
                chunks.append(b)
        _, status = os.waitpid(pid, 0)
    except BaseException:  # Ctrl-C or SIGTERM here: stop the child, within the grace period
        _stop(pid)
        if cleanup is not None:
            cleanup(pid)
        raise
    return chunks, status


@contextlib.contextmanager
def _passing_signals(child: list[int], enabled: bool):
    """While the block runs, SIGINT and SIGTERM of this process go to the child whose pid is in ``child``
    (set before the fork: the child replaces the handlers with its own at once)."""
    import threading

    if not enabled or threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        for pid in child:
            with contextlib.suppress(OSError):
                os.kill(pid, signum)

    old = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def _stop(pid: int) -> None:
    """SIGINT to the child, then SIGKILL when it has not exited within the grace period."""
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGINT)
    deadline = time.monotonic() + _grace_s()
    try:
        while time.monotonic() < deadline:
            try:
                done, _ = os.waitpid(pid, os.WNOHANG)
            except ChildProcessError:
                return
            if done:
                return
            time.sleep(0.05)
    except BaseException:  # a second Ctrl-C: no more waiting
        pass
    log.debug("  the step did not stop within %.0f s of the interrupt; killed", _grace_s())
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGKILL)
    with contextlib.suppress(ChildProcessError):
        os.waitpid(pid, 0)

"""Signals: SIGTERM handled like Ctrl-C, and child processes that die with their parent (Linux).

Light on purpose (the command imports it before anything else)."""
from __future__ import annotations

import contextlib
import os
import signal

PR_SET_PDEATHSIG = 1


class Terminated(KeyboardInterrupt):
    """SIGTERM, handled like Ctrl-C (exit 143 instead of 130)."""


def die_with_parent(parent_pid: int, sig: int = signal.SIGKILL) -> None:
    """Ask the kernel to send ``sig`` to this process when its parent dies (Linux); exit at once when the
    parent is already gone (it died before this was set)."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0)
    except (OSError, AttributeError):
        return
    if os.getppid() != parent_pid:
        os._exit(1)


def _logging_lock_held() -> bool:
    """Whether this thread holds the logging module's lock or a handler's lock (an RLock each)."""
    import logging

    locks = [getattr(logging, "_lock", None)]
    for ref in list(getattr(logging, "_handlerList", [])):
        h = ref() if callable(ref) else None
        locks.append(getattr(h, "lock", None))
    for lock in locks:
        owned = getattr(lock, "_is_owned", None)
        try:
            if owned is not None and owned():
                return True
        except Exception:  # noqa: BLE001
            continue
    return False


def _later_if_logging(signum) -> bool:
    """A signal that lands while this thread holds a logging lock must not raise there: the exception would
    leave the lock held, and another thread that logs (a progress or log-forwarding thread) blocks on it
    for good, so the process never ends (a sweep stopped with SIGTERM hung so, once, on a loaded machine:
    the job's traceback ended in logging's _releaseLock). The signal is sent again 50 ms later instead,
    when the lock is free. True when deferred."""
    if not _logging_lock_held():
        return False
    import threading

    try:
        t = threading.Timer(0.05, os.kill, (os.getpid(), signum))
        t.daemon = True
        t.start()
    except RuntimeError:  # no new threads at interpreter shutdown: raise now after all
        return False
    return True


def _raise_terminated(signum, frame):
    if _later_if_logging(signum):
        return
    raise Terminated("SIGTERM")


def raise_interrupt(signum, frame):
    """SIGINT as KeyboardInterrupt (:func:`signal.default_int_handler`), never inside a logging lock."""
    if _later_if_logging(signum):
        return
    raise KeyboardInterrupt


@contextlib.contextmanager
def sigterm_as_interrupt():
    """In the main thread: SIGTERM raises :class:`Terminated` (a KeyboardInterrupt) while the block runs."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` runs; a zombie (dead, not yet reaped by its new parent) does not."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return True


def _children(pid: int) -> list[int]:
    out: list[int] = []
    try:
        names = os.listdir("/proc")
    except OSError:
        return out
    for name in names:
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat") as f:
                ppid = int(f.read().rsplit(")", 1)[1].split()[1])
            if ppid != pid:
                continue
            with open(f"/proc/{name}/cmdline", "rb") as f:
                cmd = f.read()
        except (OSError, IndexError, ValueError):
            continue
        if b"resource_tracker" not in cmd:  # joblib's and multiprocessing's bookkeepers, not jobs
            out.append(int(name))
    return out


@contextlib.contextmanager
def forward_to_children():
    """In a multirun's main process: the first Ctrl-C or SIGTERM is passed on to the job processes as
    SIGTERM, so that each job stops its step and writes its manifest as a single run does; the jobs'
    errors then end the sweep. A second signal stops this process at once. Yields the state, whose
    ``"exc"`` is the exception the sweep must end with (Ctrl-C: 130, SIGTERM: 143)."""
    import threading

    state: dict = {}
    if threading.current_thread() is not threading.main_thread():
        yield state
        return

    def handler(signum, frame):
        exc = Terminated("SIGTERM") if signum == signal.SIGTERM else KeyboardInterrupt()
        children = _children(os.getpid())
        if "exc" in state or not children:  # a second signal, or jobs that run in this process
            if _later_if_logging(signum):
                return
            raise exc
        state["exc"] = exc
        for pid in children:
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGTERM)

    old = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield state
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def ignore_interrupts() -> dict:
    """Ignore SIGINT and SIGTERM (main thread only); returns the handlers for :func:`restore_handlers`."""
    saved = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            saved[sig] = signal.signal(sig, signal.SIG_IGN)
        except ValueError:  # not the main thread
            break
    return saved


def restore_handlers(saved: dict) -> None:
    for sig, handler in saved.items():
        with contextlib.suppress(ValueError, TypeError):
            signal.signal(sig, handler)

"""One run per workspace: the lock file, the check that the folders can be written, and the removal of
what killed runs left behind (temporary folders of dead processes).

The lock discipline (docs/engine.md, "Locks"):

- ``<workspace>/.twinkit.lock``: one run per workspace (the site's folder, or one sweep job's folder);
- ``<site>/.cache/store.lock``: every run and every sweep job holds it *shared* from start to end;
  ``twinkit gc`` takes it *exclusive* and refuses when it cannot, so it never removes a result that a
  running job has computed but not yet recorded in its folders;
- ``<site>/.cache/steps/<key>.lock``: one computation per cache key across processes.
"""
from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import time
from pathlib import Path
from typing import Iterator

from twinkit.engine.base import EngineBase
from twinkit.engine.records import _now
from twinkit.errors import InputError, LockedError
from twinkit.jsonio import write_text


def _not_a_link(path: Path) -> Path:
    """``path``, after removing a symbolic link there (twinkit never makes one; opening a lock file through it
    would truncate the link's target)."""
    if path.is_symlink():
        path.unlink()
    return path


def unwritable(folder: Path) -> str | None:
    """Why ``folder`` cannot be created or written to, or None when it can (a probe file is written and removed)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / f".write-test-{os.getpid()}"
        probe.write_text("ok")
        probe.unlink()
    except OSError as exc:
        return exc.strerror or str(exc)
    return None


def store_lock_path(site_root: Path) -> Path:
    return Path(site_root) / ".cache" / "store.lock"


class StoreLock:
    """The site store's reader/writer lock (``flock``; released by the kernel when the process dies)."""

    def __init__(self, site_root: Path):
        self.path = store_lock_path(site_root)
        self._fd: int | None = None

    def _open(self) -> int:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        return os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)

    def acquire_shared(self, wait_s: float = 120.0) -> None:
        """For a run or sweep job; waits while ``twinkit gc`` holds the store."""
        fd = self._open()
        deadline = time.monotonic() + wait_s
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
                self._fd = fd
                return
            except BlockingIOError:
                if time.monotonic() > deadline:
                    os.close(fd)
                    raise LockedError(f"'twinkit gc' has held {self.path} for over {wait_s:.0f} s; "
                                      f"run again when it has finished") from None
                time.sleep(0.2)

    def try_exclusive(self) -> bool:
        """For ``twinkit gc``: True when no run or job holds the store."""
        fd = self._open()
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            return False
        self._fd = fd
        return True

    def release(self) -> None:
        if self._fd is not None:
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None


@contextlib.contextmanager
def gc_locks(site_root: Path) -> Iterator[None]:
    """Hold the site's run lock and its store exclusively for ``twinkit gc``; LockedError when a run or a
    sweep job of the site is active."""
    from filelock import FileLock, Timeout

    site_root = Path(site_root)
    lock = FileLock(str(_not_a_link(site_root / ".twinkit.lock")))
    try:
        lock.acquire(timeout=0)
    except Timeout:
        raise LockedError(f"a twinkit run is using {site_root}; run gc when it has finished") from None
    store = StoreLock(site_root)
    try:
        if not store.try_exclusive():
            raise LockedError(f"a twinkit run or sweep job is using the results of {site_root} "
                              f"({store.path} is held); run gc when it has finished")
        try:
            yield
        finally:
            store.release()
    finally:
        lock.release()


def _pid_alive(pid: int) -> bool:
    from twinkit.signals import pid_alive  # a zombie counts as dead (a killed step process, not yet reaped)

    return pid <= 0 or pid_alive(pid)  # no pid in the name: kept, as before


class LockMixin(EngineBase):
    """Part of :class:`~twinkit.engine.runner.Engine`: take the workspace (``self.workspace``, ``self.store``)
    before a run and give it back after (``self._lock``, ``self.hashes``)."""

    def _prepare(self) -> None:
        for d in (self.workspace, self.store):
            problem = unwritable(d)
            if problem:
                raise InputError(f"cannot write to {d} ({problem}); choose a writable folder with engine.outputs_dir=<dir>")
        from filelock import FileLock, Timeout

        lock = FileLock(str(_not_a_link(self.workspace / ".twinkit.lock")))
        try:
            lock.acquire(timeout=0)
        except Timeout:
            holder = (self.workspace / ".twinkit.owner").read_text().strip() if (self.workspace / ".twinkit.owner").exists() else "?"
            raise LockedError(
                f"another twinkit run is using {self.workspace} ({holder}); wait for it to finish, "
                f"or use another engine.outputs_dir"
            ) from None
        self._lock = lock  # held from here on: _release gives it back whatever happens next
        write_text(self.workspace / ".twinkit.owner", f"pid {os.getpid()} since {_now()}\n")  # a link replaced, not followed
        self._store_lock = StoreLock(self.site_root)
        try:
            self._store_lock.acquire_shared()
        except LockedError:
            lock.release()
            self._lock = None
            raise
        # leftovers of killed runs: never counted as done, removed now
        tmp_root = self.store / ".tmp"
        if tmp_root.is_dir():
            for d in tmp_root.iterdir():
                try:
                    pid = int(d.name.split("-")[1])
                except (IndexError, ValueError):
                    pid = -1
                if not _pid_alive(pid):
                    shutil.rmtree(d, ignore_errors=True)
        for d in [*self.workspace.glob(".*.tmp-*"), *self.workspace.glob(".*.old-*")]:
            try:
                pid = int(d.name.rsplit("-", 1)[1])
            except ValueError:
                pid = -1
            if not _pid_alive(pid):
                shutil.rmtree(d, ignore_errors=True)

    def _release(self) -> None:
        store_lock = getattr(self, "_store_lock", None)
        if store_lock is not None:
            store_lock.release()
            self._store_lock = None
        if self._lock is not None:
            self._lock.release()
            self._lock = None
        self.hashes.close()

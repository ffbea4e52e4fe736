"""One run per workspace: the lock file, the check that the folders can be written, and the removal of
what killed runs left behind (temporary folders of dead processes)."""
from __future__ import annotations

import os
import shutil
from pathlib import Path

from twinkit.engine.records import _now
from twinkit.errors import InputError, LockedError


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


def _pid_alive(pid: int) -> bool:
    from twinkit.signals import pid_alive  # a zombie counts as dead (a killed step process, not yet reaped)

    return pid <= 0 or pid_alive(pid)  # no pid in the name: kept, as before


class LockMixin:
    """Part of :class:`~twinkit.engine.runner.Engine`: take the workspace (``self.workspace``, ``self.store``)
    before a run and give it back after (``self._lock``, ``self.hashes``)."""

    def _prepare(self) -> None:
        for d in (self.workspace, self.store):
            problem = unwritable(d)
            if problem:
                raise InputError(f"cannot write to {d} ({problem}); choose a writable folder with engine.outputs_dir=<dir>")
        from filelock import FileLock, Timeout

        lock = FileLock(str(self.workspace / ".twinkit.lock"))
        try:
            lock.acquire(timeout=0)
        except Timeout:
            holder = (self.workspace / ".twinkit.owner").read_text().strip() if (self.workspace / ".twinkit.owner").exists() else "?"
            raise LockedError(
                f"another twinkit run is using {self.workspace} ({holder}); wait for it to finish, "
                f"or use another engine.outputs_dir"
            ) from None
        (self.workspace / ".twinkit.owner").write_text(f"pid {os.getpid()} since {_now()}\n")
        self._lock = lock
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
        if self._lock is not None:
            self._lock.release()
            self._lock = None
        self.hashes.close()

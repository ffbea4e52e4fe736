"""Content hashes of files and artefacts, with a stat cache.

A file's sha256 is computed once and remembered in a small SQLite database
keyed by (device, inode, size, mtime in ns, ctime in ns): a file that was not
modified is never read again; a file touched without change is re-read once and
found equal. The ctime (inode change time) cannot be set back by a program, so an
edit that keeps the size and restores the mtime (``touch -r``) is still seen.
Hard links share one entry.
"""
from __future__ import annotations

import hashlib
import os
import sqlite3
import threading
import time
from pathlib import Path

CHUNK = 1 << 20
BUSY_WAIT_S = 60.0  # how long a run waits for another run (a sweep's parallel job) holding the database


def _patient(call, *args):
    """``call(*args)``, retried while SQLite answers "database is locked" at once.

    The connection's own timeout covers ordinary waits, but SQLite gives up without waiting in some
    cases, e.g. when two processes open a new database together and both switch it to WAL: the
    second one's ``PRAGMA journal_mode`` fails immediately. Such a failure is retried with a growing
    pause for up to ``BUSY_WAIT_S``; any other error is raised as it is."""
    deadline, pause = time.monotonic() + BUSY_WAIT_S, 0.01
    while True:
        try:
            return call(*args)
        except sqlite3.OperationalError as exc:
            text = str(exc)
            if ("locked" not in text and "busy" not in text) or time.monotonic() > deadline:
                raise
        time.sleep(pause)
        pause = min(pause * 2, 0.5)


def sha256_file(path: Path) -> str:
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


class HashCache:
    """sha256 of files, remembered by stat signature. Safe across processes."""

    def __init__(self, db_path: Path | None, read_only: bool = False):
        """``read_only``: remembered hashes are used but nothing is written (``twinkit status``); a missing
        database is not created."""
        self.db_path = db_path
        self.read_only = read_only
        self._conn: sqlite3.Connection | None = None
        self._lock = threading.Lock()
        self._mem: dict[tuple[int, int, int, int, int], str] = {}
        self.bytes_hashed = 0
        self.files_hashed = 0

    def _db(self) -> sqlite3.Connection | None:
        if self.db_path is None:
            return None
        if self._conn is None and self.read_only:
            if not self.db_path.is_file():
                self.db_path = None
                return None
            try:
                # immutable: no -wal/-shm files either; a write by a concurrent run is at worst not seen
                # (the file is then hashed), never trusted wrongly, as every row is keyed by the full stat
                self._conn = sqlite3.connect(f"file:{self.db_path}?mode=ro&immutable=1", uri=True, timeout=60,
                                             isolation_level=None)
                self._conn.execute("SELECT ctime FROM hashes LIMIT 1")
            except sqlite3.Error:  # an older layout, or unreadable: hash without it
                self._conn, self.db_path = None, None
            return self._conn
        if self._conn is None:
            self.db_path.parent.mkdir(parents=True, exist_ok=True)
            conn = sqlite3.connect(str(self.db_path), timeout=BUSY_WAIT_S, isolation_level=None)
            try:
                _patient(self._set_up, conn)
            except BaseException:
                conn.close()
                raise
            self._conn = conn
        return self._conn

    @staticmethod
    def _set_up(conn: sqlite3.Connection) -> None:
        """WAL mode and the table; safe to repeat (``_patient`` retries it whole)."""
        if conn.execute("PRAGMA journal_mode").fetchone()[0].lower() != "wal":
            conn.execute("PRAGMA journal_mode=WAL")
        conn.execute("PRAGMA synchronous=NORMAL")
        cols = [r[1] for r in conn.execute("PRAGMA table_info(hashes)").fetchall()]
        if cols and "ctime" not in cols:  # remembered before ctime was part of the signature
            conn.execute("DROP TABLE IF EXISTS hashes")
        conn.execute(
            "CREATE TABLE IF NOT EXISTS hashes (dev INTEGER, ino INTEGER, size INTEGER, mtime INTEGER, "
            "ctime INTEGER, sha256 TEXT, PRIMARY KEY (dev, ino, size, mtime, ctime))"
        )

    @staticmethod
    def signature(st: os.stat_result) -> tuple[int, int, int, int, int]:
        """What identifies one state of a file without reading it."""
        return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)

    def remember(self, path: Path, digest: str) -> None:
        """Record the sha256 of a file just written (its bytes were hashed while they were written)."""
        sig = self.signature(os.stat(path))
        self._mem[sig] = digest
        if self.read_only:
            return
        with self._lock:
            db = self._db()
            if db is not None:
                _patient(db.execute, "INSERT OR REPLACE INTO hashes VALUES (?,?,?,?,?,?)", (*sig, digest))

    def hash(self, path: Path) -> str:
        st = os.stat(path)
        sig = self.signature(st)
        if sig in self._mem:
            return self._mem[sig]
        with self._lock:
            db = self._db()
            if db is not None:
                try:
                    row = db.execute(
                        "SELECT sha256 FROM hashes WHERE dev=? AND ino=? AND size=? AND mtime=? AND ctime=?", sig
                    ).fetchone()
                except sqlite3.DatabaseError:
                    if not self.read_only:
                        raise
                    row = None
                if row:
                    self._mem[sig] = row[0]
                    return row[0]
        digest = sha256_file(path)
        self.bytes_hashed += st.st_size
        self.files_hashed += 1
        # a file modified while we read it gets a new mtime: store under the stat we saw first only if unchanged
        if self.signature(os.stat(path)) == sig:
            self._mem[sig] = digest
            if not self.read_only:
                with self._lock:
                    db = self._db()
                    if db is not None:
                        _patient(db.execute, "INSERT OR REPLACE INTO hashes VALUES (?,?,?,?,?,?)", (*sig, digest))
        return digest

    def prune(self, keep: set[tuple[int, int, int, int, int]]) -> int:
        """Forget every remembered hash whose stat signature is not in ``keep``; returns how many."""
        with self._lock:
            db = self._db()
            if db is None:
                return 0
            rows = db.execute("SELECT dev, ino, size, mtime, ctime FROM hashes").fetchall()
            doomed = [r for r in rows if tuple(r) not in keep]
            _patient(db.execute, "BEGIN IMMEDIATE")  # the write lock now, or wait for it: never a failed upgrade
            db.executemany("DELETE FROM hashes WHERE dev=? AND ino=? AND size=? AND mtime=? AND ctime=?", doomed)
            db.execute("COMMIT")
            self._mem = {k: v for k, v in self._mem.items() if k in keep}
            return len(doomed)

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None


def list_files(folder: Path) -> list[Path]:
    """Every regular file below ``folder``, sorted, as relative paths."""
    out = []
    for root, dirs, files in os.walk(folder):
        dirs.sort()
        for f in sorted(files):
            out.append((Path(root) / f).relative_to(folder))
    return out


def companions(path: Path) -> list[Path]:
    """Files that travel with ``path``: same folder, same stem (``mesh.obj`` -> ``mesh.mtl``, ``mesh.png``)."""
    stem = path.name.split(".", 1)[0]
    if not path.parent.is_dir():
        return []
    return sorted(
        p for p in path.parent.iterdir() if p != path and p.is_file() and p.name.split(".", 1)[0] == stem
    )


def artefact_hash(path: Path, cache: HashCache) -> str:
    """Combined content hash of an artefact: a file with its companions, or a folder's files."""
    h = hashlib.sha256()
    if path.is_dir():
        for rel in list_files(path):
            h.update(f"{rel.as_posix()}:{cache.hash(path / rel)}\n".encode())
        return h.hexdigest()
    h.update(f"{path.name}:{cache.hash(path)}\n".encode())
    for c in companions(path):
        h.update(f"{c.name}:{cache.hash(c)}\n".encode())
    return h.hexdigest()

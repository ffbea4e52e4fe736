"""Which reports stay on disk: the newest ``engine.keep_reports`` runs' reports (their manifests and logs
always stay), no temporary report folder of a killed run, and no cached picture or model that no report
uses. Called at the end of each single run and by ``twinkit gc`` (docs/engine.md "Disk space")."""
from __future__ import annotations

import logging
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

from twinkit.report.run import REPORT_DIR

log = logging.getLogger("twinkit.report")

#: a cached file no report links is kept this long after its last use (a parallel job may be about to link it)
UNLINKED_GRACE_S = 3600.0


@dataclass
class Collected:
    """What a tidy-up removed (or, dry, would remove), and the bytes that frees."""

    reports: list[Path] = field(default_factory=list)
    leftovers: list[Path] = field(default_factory=list)
    cached: list[Path] = field(default_factory=list)
    freed: int = 0

    def summary(self, dry_run: bool = False) -> str:
        """One line: what was removed and how much it freed."""
        verb = "would remove" if dry_run else "removed"
        return (f"{verb} {len(self.reports)} older run report(s), {len(self.leftovers)} temporary report "
                f"folder(s) of killed runs and {len(self.cached)} unused cached report file(s): "
                f"{self.freed / 2**20:.1f} MiB")


def _freed(path: Path) -> int:
    """Bytes removing ``path`` frees: its files that have no other hard link."""
    files = [path] if path.is_file() else [p for p in path.rglob("*") if p.is_file() and not p.is_symlink()]
    total = 0
    for f in files:
        try:
            st = f.stat()
        except OSError:
            continue
        if st.st_nlink <= 1:
            total += st.st_size
    return total


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def report_leftovers(site_root: Path) -> list[Path]:
    """Temporary report folders (``.report.tmp-<pid>``, ``.report.old-<pid>``) whose process is dead: left by
    a run killed while it wrote its report, in any run folder or sweep job of the site."""
    from twinkit.signals import pid_alive

    out = []
    for parent in (*site_root.glob("runs/*"), *site_root.glob("sweeps/*/*"), *site_root.glob("sweeps/*")):
        for d in [*parent.glob(f".{REPORT_DIR}.tmp-*"), *parent.glob(f".{REPORT_DIR}.old-*")]:
            try:
                pid = int(d.name.rsplit("-", 1)[1])
            except ValueError:
                continue  # not ours
            if pid > 0 and not pid_alive(pid):
                out.append(d)
    return out


def older_reports(site_root: Path, keep: int, current: Path | None = None) -> list[Path]:
    """The report folders of the site's runs (``runs/<time>/report``) beyond the newest ``keep`` (0 = keep
    every one). The run folders are named by their start time, so their names sort them; ``current`` (the
    run being finished) is never among them."""
    if keep <= 0:
        return []
    reports = sorted((d for d in site_root.glob(f"runs/*/{REPORT_DIR}") if d.is_dir() and not d.is_symlink()),
                     key=lambda d: d.parent.name)
    doomed = reports[:-keep] if len(reports) > keep else []
    cur = Path(current).resolve() if current is not None else None
    return [d for d in doomed if cur is None or d.parent.resolve() != cur]


def unused_cache_files(site_root: Path, grace_s: float = UNLINKED_GRACE_S) -> list[Path]:
    """Files of the report cache (``.cache/report/``) that no report links (one link: the cache's own)
    and that were not used for ``grace_s`` seconds."""
    cache = site_root / ".cache" / REPORT_DIR
    if not cache.is_dir():
        return []
    limit = time.time() - grace_s
    out = []
    for p in cache.iterdir():
        try:
            st = p.lstat()
        except OSError:
            continue
        if p.is_file() and not p.is_symlink() and st.st_nlink <= 1 and st.st_mtime < limit:
            out.append(p)
    return out


def tidy_reports(site_root: Path, keep: int, current: Path | None = None, dry_run: bool = False,
                 grace_s: float = UNLINKED_GRACE_S) -> Collected:
    """Remove (unless ``dry_run``) the reports beyond the newest ``keep``, killed runs' temporary report
    folders, then the cached report files no report links any more. Manifests and logs stay."""
    site_root = Path(site_root)
    done = Collected(reports=older_reports(site_root, keep, current), leftovers=report_leftovers(site_root))
    for d in [*done.reports, *done.leftovers]:
        done.freed += _freed(d)
        if not dry_run:
            _remove(d)
    # after the reports went, their cached pictures and models have one link left (dry: as they are now)
    done.cached = unused_cache_files(site_root, grace_s)
    for p in done.cached:
        done.freed += _freed(p)
        if not dry_run:
            _remove(p)
    return done


def tidy_after_run(site_root: Path, keep: int, current: Path) -> None:
    """:func:`tidy_reports` at the end of a run; never raises (one warning instead)."""
    try:
        done = tidy_reports(site_root, keep, current)
    except Exception as exc:  # noqa: BLE001 - a tidy-up never fails the run
        log.warning("twinkit: older reports left in place (%s: %s)", type(exc).__name__, exc)
        return
    if done.reports or done.leftovers or done.cached:
        log.debug("reports: %s (engine.keep_reports=%d)", done.summary(), keep)

"""One run of a composed config: the engine built, its progress lines, the manifest, the report, the exit status."""
from __future__ import annotations

import contextlib
import datetime as _dt
import logging
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from twinkit.errors import StepError, TwinkitError
from twinkit.os_errors import explaining_os_errors, os_text
from twinkit.quality import DEGRADED_EXIT

log = logging.getLogger("twinkit")


def execute(cfg, run_dir: Path, multirun: bool, overrides: list[str], concurrent_jobs: int = 1,
            conf_dir: str | None = None, argv: list[str] | None = None) -> int:
    """Plan -> run -> manifest (-> report) for one composed config; the run's exit status (0, or the degraded
    one). ``conf_dir``: the config folder (found when None); ``argv``: the command line the manifest records
    (``sys.argv`` when None)."""
    from twinkit.config import check_composed_site_name

    check_composed_site_name(cfg)  # before run.log is written under a folder the name makes
    _setup_logging(run_dir / "run.log")
    _crash_log(run_dir / "run.log")
    run = _prepare(cfg, run_dir, multirun, overrides, concurrent_jobs, conf_dir, argv)
    return _run_engine(run)


@dataclass
class _Run:
    """What one run's manifest and report are written from."""

    run_dir: Path
    overrides: list[str]
    argv: list[str]
    root: Path
    container: dict
    secrets: Any
    site: dict
    engine_cfg: dict
    site_root: Path
    workspace: Path
    registry: Any
    started: str = ""
    t0: float = 0.0
    engine: Any = field(default=None)

    def manifest(self, status: str, error: str | None) -> dict:
        """The run's manifest as it stands now, with ``${oc.env:...}`` values redacted."""
        from twinkit.config import code_allowed
        from twinkit.manifest import build_manifest, redact

        manifest = build_manifest(
            argv=self.argv, overrides=self.overrides, config=self.container, site=self.site,
            outcomes=self.engine.outcomes, engine=self.engine, registry=self.registry, project_root=self.root,
            status=status, error=error, started=self.started,
            finished=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            duration_s=time.perf_counter() - self.t0,
        )
        manifest["code_allowed"] = code_allowed()  # TWINKIT_ALLOW_CODE=1: the command line could name code to run
        # ${oc.env:...} values stay out of the manifest and the report; the file lists keep their real
        # paths (twinkit verify reads them)
        return {k: (v if k in ("inputs", "outputs", "workspace") else redact(v, self.secrets))
                for k, v in manifest.items()}


def _prepare(cfg, run_dir: Path, multirun: bool, overrides: list[str], concurrent_jobs: int,
             conf_dir: str | None, argv: list[str] | None) -> _Run:
    """The plain config checked, and the engine built (not yet run)."""
    from twinkit.config import find_config_dir
    from twinkit.engine import GIVEN_KEY, given_params
    from twinkit.hydra_glue import plain, without_hydra
    from twinkit.manifest import env_secrets, remember_secrets
    from twinkit.plugins import get_registry

    conf = Path(conf_dir or find_config_dir())
    cfg = without_hydra(cfg)
    container = plain(cfg)
    secrets = env_secrets(plain(cfg, resolve=False))
    remember_secrets(secrets)  # the log, the step records, the store and the plugins redact them too
    container[GIVEN_KEY] = given_params(container, overrides)
    site = container.get("site") or {}
    engine_cfg = container["engine"]
    site_root = Path(engine_cfg["outputs_dir"]) / site["name"]
    run = _Run(run_dir=run_dir, overrides=overrides, argv=argv if argv is not None else sys.argv,
               root=conf.parent, container=container, secrets=secrets, site=site, engine_cfg=engine_cfg,
               site_root=site_root, workspace=run_dir if multirun else site_root, registry=get_registry())
    _check(run, conf, overrides)
    run.started = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    run.t0 = time.perf_counter()
    run.engine = _engine(run, concurrent_jobs)
    recipe = container.get("recipe", {}).get("name", "?")
    log.info("twinkit: recipe '%s' on site '%s' -> %s (run log %s)", recipe, site["name"], run.workspace,
             run_dir / "run.log")
    return run


def _check(run: _Run, conf_dir: Path, overrides: list[str]) -> None:
    """The config's values checked (twinkit.config.check_config), naming the site file when one was chosen."""
    from twinkit.config import _chosen, check_config

    try:
        sites = _chosen(overrides, conf_dir).get("site") or []
        chosen_site = sites[0] if len(sites) == 1 else None
    except Exception:  # noqa: BLE001 - only for the message
        chosen_site = None
    check_config(run.container, run.registry,
                 site_file=str(conf_dir / "site" / f"{chosen_site}.yaml") if chosen_site else None, secrets=run.secrets)


def _engine(run: _Run, concurrent_jobs: int):
    """The run's engine, with the run's secrets kept out of its step records."""
    from twinkit.engine import Engine

    engine_cfg = run.engine_cfg
    engine = Engine(
        run.container, run.registry, workspace=run.workspace, site_root=run.site_root,
        rerun=run.container.get("rerun") or [],
        interactive=_interactive(engine_cfg.get("interactive", "auto")),
        threads=engine_cfg.get("threads") or None, config_root=run.root,
        manual_timeout_s=engine_cfg.get("manual_timeout_s"),
        max_threads=_job_threads(concurrent_jobs),
    )
    engine.secrets = run.secrets  # kept out of the step records too
    return engine


def _run_engine(run: _Run) -> int:
    """Run the engine between a "running" manifest and the final one (which says how the run ended)."""
    from twinkit.manifest import write_manifest

    engine = run.engine
    status, error = "ok", None
    saved_handlers: dict = {}
    try:
        # written now as "running": a run killed outright (kill -9, power) is recognisable afterwards
        write_manifest(run.run_dir / "manifest.json", run.manifest("running", None))
        explaining_os_errors(lambda: engine.run(on_step=lambda oc, i, n: log.info(_format_outcome(oc, i, n))),
                             run.site_root)
    except TwinkitError as exc:
        status, error = ("pending" if exc.exit_code == 3 else "failed"), str(exc)
        if exc.__cause__ is not None:
            import traceback

            logging.getLogger("twinkit").debug("".join(traceback.format_exception(exc.__cause__)))
        raise
    except BaseException as exc:  # Ctrl-C, SIGTERM, or a bug in twinkit itself: the manifest must not say "ok"
        status, error = "interrupted", f"{type(exc).__name__}: {exc}"
        if engine.current_step and isinstance(exc, KeyboardInterrupt):
            error += f" (during step '{engine.current_step}')"
        if isinstance(exc, KeyboardInterrupt):
            # a second Ctrl-C (or a sweep's forwarded SIGTERM) must not cut the manifest short
            from twinkit.signals import ignore_interrupts

            saved_handlers = ignore_interrupts()
        raise
    finally:
        if engine._lock is not None:  # stopped while giving the workspace back: the final manifest still follows
            with contextlib.suppress(Exception):
                engine._release()
        status = _finish(run, status, error)
        if saved_handlers:
            from twinkit.signals import restore_handlers

            restore_handlers(saved_handlers)
    return int(run.engine_cfg.get("degraded_exit_code", DEGRADED_EXIT)) if status == "degraded" else 0


def _finish(run: _Run, status: str, error: str | None) -> str:
    """The final manifest written, the run's last log lines and its report; the run's final status."""
    from twinkit.manifest import write_manifest

    engine, run_dir, engine_cfg = run.engine, run.run_dir, run.engine_cfg
    manifest = run.manifest(status, error)
    failed = _failed_step(engine, status, error)
    if failed is not None:
        from twinkit.manifest import redact

        manifest["failed_step"] = redact(failed, run.secrets)
    engine.hashes.close()
    try:
        write_manifest(run_dir / "manifest.json", manifest)
    except OSError as exc:  # a full disk must not hide the run's own error behind a second traceback
        log.error("twinkit: could not write %s: %s", run_dir / "manifest.json", os_text(exc, run_dir))
        if status == "ok":
            raise StepError(f"the run finished, but its manifest could not be written: "
                            f"{os_text(exc, run_dir)}") from None
    if status == "ok":
        status = manifest["status"]  # "degraded" when a step said its result is far below what it should be
        from twinkit.quality import run_status_text

        log.info("twinkit: done in %.1f s (%s); manifest %s", time.perf_counter() - run.t0, run_status_text(manifest),
                 run_dir / "manifest.json")
        _say_degraded(manifest.get("degraded") or [], engine_cfg)
        if engine_cfg.get("report", True):
            _write_report(run_dir, manifest, engine)
    elif failed is not None and engine_cfg.get("report", True):
        _write_report(run_dir, manifest, engine)  # a failed run's report: what ran, and the step that failed
    if run.workspace == run.site_root:  # a single run (a sweep's jobs keep theirs, see docs/engine.md)
        _tidy_reports(run)
    return status


def _failed_step(engine, status: str, error: str | None) -> dict | None:
    """The step a failed run stopped in (id, folder, plugin, error), or None when it stopped before any step
    ran (a plan or preflight refusal) or did not fail (an interrupted run exits at once, without a report)."""
    if status != "failed" or not getattr(engine, "current_step", None):
        return None
    done = {getattr(o, "step", None) for o in (engine.outcomes or [])}
    if engine.current_step in done:
        return None  # the step finished; the run failed after it
    ps = next((p for p in (getattr(engine, "plan", None) or []) if p.id == engine.current_step), None)
    return {"id": engine.current_step, "folder": ps.folder if ps is not None else engine.current_step,
            "plugin": ps.label if ps is not None else "", "status": status, "error": error or ""}


def _say_degraded(entries: list[dict], engine_cfg: dict) -> None:
    """The log's last word on a degraded run: every reason, and the exit status it gets."""
    from twinkit.quality import describe

    if not entries:
        return
    code = int(engine_cfg.get("degraded_exit_code", DEGRADED_EXIT))
    log.error("twinkit: DEGRADED result: %d step result(s) are far below what they should be%s:", len(entries),
              f" (exit status {code})" if code else "")
    for e in entries:
        log.error("  - %s", describe(e))


def _format_outcome(oc, i: int, n: int) -> str:
    dur = f"{oc.duration_s:7.1f} s" if oc.status in ("ran",) or oc.duration_s >= 0.05 else " " * 9
    mem = f"  peak {oc.peak_rss_mb:.0f} MB" if oc.status == "ran" and oc.peak_rss_mb else ""
    from twinkit.quality import degraded_of, gate_text, gates_of

    bad = degraded_of(oc.metrics)
    flag = f"  DEGRADED ({len(bad)}: {bad[0]['reason']}{' ...' if len(bad) > 1 else ''})" if bad else ""
    gates = gates_of(oc.metrics)
    figures = ("  gates: " + "; ".join(gate_text(g) + (f" [item {g['item']}]" if "item" in g else "") for g in gates)
               if gates else "")
    return f"[{i}/{n}] {oc.folder:<24} {oc.status:<7} {dur}  {oc.why}{mem}{figures}{flag}"


def _interactive(setting: str) -> bool:
    if str(setting).lower() in ("true", "yes", "1"):
        return True
    if str(setting).lower() in ("false", "no", "0"):
        return False
    return sys.stdin.isatty() and sys.stderr.isatty()


def _job_threads(concurrent_jobs: int) -> int | None:
    """A multirun job's cap on threads: the cores divided among the launcher's concurrent jobs."""
    if concurrent_jobs <= 1:
        return None
    from twinkit.threads import cores

    return max(1, cores() // concurrent_jobs)


def _setup_logging(run_log: Path | None) -> None:
    from twinkit.manifest import RedactingFilter

    root = logging.getLogger("twinkit")
    root.setLevel(logging.DEBUG)
    for h in list(root.handlers):
        root.removeHandler(h)
    console = logging.StreamHandler(sys.stderr)
    console.addFilter(RedactingFilter())
    console.setLevel(logging.INFO)
    console.setFormatter(logging.Formatter("%(message)s"))
    root.addHandler(console)
    if run_log is not None:
        run_log.parent.mkdir(parents=True, exist_ok=True)
        fh = logging.FileHandler(run_log)
        fh.setLevel(logging.DEBUG)
        fh.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
        fh.addFilter(RedactingFilter())
        root.addHandler(fh)
    root.propagate = False
    logging.raiseExceptions = False  # a full disk under run.log must not print logging's own tracebacks


_FAULT_LOG: list = []


def _crash_log(run_log: Path) -> None:
    """A crash in native code writes the Python stack of every thread into the run log."""
    import faulthandler

    try:
        f = open(run_log, "a")  # kept open for the life of the process
    except OSError:
        return
    faulthandler.enable(file=f, all_threads=True)
    for old in _FAULT_LOG:
        old.close()
    _FAULT_LOG[:] = [f]


def _write_report(run_dir: Path, manifest: dict, engine) -> None:
    try:
        from twinkit.report import write_report
    except ImportError:
        return
    path = write_report(run_dir, manifest, engine)
    if path is not None:
        log.info("twinkit: report file://%s", path.resolve())


def _tidy_reports(run: _Run) -> None:
    """Older runs' reports beyond ``engine.keep_reports``, killed reports' leftovers, unused cached pictures."""
    try:
        from twinkit.report.keep import tidy_after_run
    except ImportError:
        return
    tidy_after_run(run.site_root, int(run.engine_cfg.get("keep_reports", 3)), run.run_dir)

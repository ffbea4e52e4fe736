"""The ``twinkit`` command.

    twinkit [recipe=<name>] [site=<name>] [key=value ...]     run a recipe on a site (Hydra overrides)
    twinkit -m ... a=1,2                                       multirun sweep (joblib launcher)
    twinkit ... --cfg job                                      print the composed config, run nothing
    twinkit status [overrides]                                 what a run would do, per step, without running
    twinkit plugins                                            loaded plugins with distributions and versions
    twinkit plugins <kind>/<name>                              a plugin's parameters: type, range, default, help
    twinkit verify <manifest.json | run folder>                check a run's manifest against the files on disk
    twinkit gc [--dry-run] [site=<name>] [engine.outputs_dir=..] delete stored results no step folder refers to
"""
from __future__ import annotations

import datetime as _dt
import errno
import logging
import os
import shutil
import sys
import time
from pathlib import Path

from twinkit.errors import ConfigError, InputError, StepError, TwinkitError
from twinkit.quality import DEGRADED_EXIT

log = logging.getLogger("twinkit")

SUBCOMMANDS = ("status", "plugins", "verify", "gc")

EXIT_OK, EXIT_STEP_FAILED = 0, 1


def _err(msg: str, code: int = 2) -> int:
    print(f"twinkit: error: {msg}", file=sys.stderr)
    return code


def _setup_logging(run_log: Path | None) -> None:
    root = logging.getLogger("twinkit")
    root.setLevel(logging.DEBUG)
    for h in list(root.handlers):
        root.removeHandler(h)
    console = logging.StreamHandler(sys.stderr)
    console.setLevel(logging.INFO)
    console.setFormatter(logging.Formatter("%(message)s"))
    root.addHandler(console)
    if run_log is not None:
        run_log.parent.mkdir(parents=True, exist_ok=True)
        fh = logging.FileHandler(run_log)
        fh.setLevel(logging.DEBUG)
        fh.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
        root.addHandler(fh)
    root.propagate = False
    logging.raiseExceptions = False  # a full disk under run.log must not print logging's own tracebacks


def _format_outcome(oc, i: int, n: int) -> str:
    dur = f"{oc.duration_s:7.1f} s" if oc.status in ("ran",) or oc.duration_s >= 0.05 else " " * 9
    mem = f"  peak {oc.peak_rss_mb:.0f} MB" if oc.status == "ran" and oc.peak_rss_mb else ""
    from twinkit.quality import degraded_of

    bad = degraded_of(oc.metrics)
    flag = f"  DEGRADED ({len(bad)}: {bad[0]['reason']}{' ...' if len(bad) > 1 else ''})" if bad else ""
    return f"[{i}/{n}] {oc.folder:<24} {oc.status:<7} {dur}  {oc.why}{mem}{flag}"


def _interactive(setting: str) -> bool:
    if str(setting).lower() in ("true", "yes", "1"):
        return True
    if str(setting).lower() in ("false", "no", "0"):
        return False
    return sys.stdin.isatty() and sys.stderr.isatty()


def _check_writable(overrides: list[str], conf_dir: Path | None = None) -> None:
    from twinkit.config import local_outputs_dirs
    from twinkit.engine import unwritable
    from twinkit.hydra_glue import override_value

    outputs = override_value(overrides, "engine.outputs_dir")
    # conf/local/<site>.yaml may move the outputs (engine.outputs_dir there), and is honoured here too
    candidates = [outputs] if outputs is not None else (local_outputs_dirs(overrides, conf_dir) if conf_dir else [])
    for outputs in candidates or ["outputs"]:
        p = Path(outputs)
        problem = unwritable(p)
        if problem:
            raise ConfigError(f"cannot write to the outputs folder {p.resolve()} ({problem}); "
                              f"choose another with engine.outputs_dir=<dir>")


# --------------------------------------------------------------------------- the Hydra job

_STATE: dict = {}


def _job(cfg) -> int:
    """One Hydra job. A TwinkitError becomes a one-line message and an exit code, not a traceback."""
    from twinkit.hydra_glue import is_multirun, job_error

    try:
        return _job_body(cfg)
    except TwinkitError as exc:
        if is_multirun():
            raise job_error(f"twinkit: error: {exc}", exc.exit_code) from None
        _STATE["error"] = exc
        return exc.exit_code
    except KeyboardInterrupt as exc:
        if not is_multirun():
            raise
        return _job_interrupted(exc)


def _job_interrupted(exc: KeyboardInterrupt) -> int:
    """A multirun job stopped by Ctrl-C or SIGTERM (its manifest says so) returns instead of raising: a
    raised error would make joblib kill the other jobs before they have written their manifests. The
    sweep's own process ends with 130 / 143 (``forward_to_children``); later jobs of this worker are skipped."""
    from twinkit.signals import Terminated

    _STATE["interrupted"] = 143 if isinstance(exc, Terminated) else 130
    return _STATE["interrupted"]


def _plain(node, resolve: bool = True) -> dict:
    """A mapping config node (DictConfig) as a plain dict (OmegaConf.to_container), typed as one."""
    from omegaconf import OmegaConf

    out = OmegaConf.to_container(node, resolve=resolve)
    if not isinstance(out, dict):
        raise TypeError(f"not a mapping config node: {type(out).__name__}")
    return out


def _job_body(cfg) -> int:
    """A Hydra (multirun) job: read Hydra's runtime state, then execute."""
    from twinkit.hydra_glue import job_state

    job = job_state()
    jobs = 1
    if job.multirun and _STATE.get("interrupted"):
        log.info("twinkit: job %s not started: the sweep was interrupted", job.num)
        return _STATE["interrupted"]
    if job.multirun:
        from twinkit.executors import use_standard_start_method

        use_standard_start_method()  # a job runs in a loky worker: its fan-out pools must not inherit 'loky'
        from twinkit.threads import cores

        jobs = cores() if job.n_jobs <= 0 else job.n_jobs  # joblib's -1: as many jobs as cores
    from twinkit.signals import sigterm_as_interrupt

    with sigterm_as_interrupt():  # a job's process (a joblib worker) stops like a single run
        return _execute(cfg, run_dir=job.output_dir, multirun=job.multirun, overrides=job.overrides,
                        concurrent_jobs=jobs)


def _execute(cfg, run_dir: Path, multirun: bool, overrides: list[str], concurrent_jobs: int = 1) -> int:
    """Plan -> run -> manifest (-> report) for one composed config."""
    from omegaconf import OmegaConf

    from twinkit.config import find_config_dir
    from twinkit.engine import Engine
    from twinkit.manifest import build_manifest, write_manifest
    from twinkit.plugins import get_registry

    _setup_logging(run_dir / "run.log")
    _crash_log(run_dir / "run.log")
    conf_dir = Path(_STATE.get("conf_dir") or find_config_dir())
    root = conf_dir.parent
    from omegaconf import open_dict

    if "hydra" in cfg:
        cfg = cfg.copy()
        with open_dict(cfg):
            del cfg["hydra"]
    container = _plain(cfg)
    from twinkit.engine import GIVEN_KEY, given_params
    from twinkit.manifest import env_secrets, redact

    secrets = env_secrets(OmegaConf.to_container(cfg, resolve=False))
    container[GIVEN_KEY] = given_params(container, overrides)
    site = container.get("site") or {}
    if not site.get("name"):
        raise ConfigError("the site config has no 'name'")
    engine_cfg = container["engine"]
    site_root = Path(engine_cfg["outputs_dir"]) / site["name"]
    workspace = run_dir if multirun else site_root
    registry = get_registry()
    from twinkit.config import _chosen, check_config

    try:
        sites = _chosen(overrides, conf_dir).get("site") or []
        chosen_site = sites[0] if len(sites) == 1 else None
    except Exception:  # noqa: BLE001 - only for the message
        chosen_site = None
    check_config(container, registry,
                 site_file=str(conf_dir / "site" / f"{chosen_site}.yaml") if chosen_site else None)
    started = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    t0 = time.perf_counter()
    engine = Engine(
        container, registry, workspace=workspace, site_root=site_root, rerun=container.get("rerun") or [],
        interactive=_interactive(engine_cfg.get("interactive", "auto")),
        threads=engine_cfg.get("threads") or None, config_root=root,
        manual_timeout_s=engine_cfg.get("manual_timeout_s"),
        max_threads=_job_threads(concurrent_jobs),
    )
    engine.secrets = secrets  # kept out of the step records too
    recipe = container.get("recipe", {}).get("name", "?")
    log.info("twinkit: recipe '%s' on site '%s' -> %s (run log %s)", recipe, site["name"], workspace,
             run_dir / "run.log")
    status, error = "ok", None
    saved_handlers: dict = {}

    def manifest_now(status: str, error: str | None) -> dict:
        manifest = build_manifest(
            argv=_STATE.get("argv", sys.argv), overrides=overrides, config=container, site=site,
            outcomes=engine.outcomes, engine=engine, registry=registry, project_root=root, status=status,
            error=error, started=started,
            finished=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            duration_s=time.perf_counter() - t0,
        )
        # ${oc.env:...} values stay out of the manifest and the report; the file lists keep their real
        # paths (twinkit verify reads them)
        return {k: (v if k in ("inputs", "outputs", "workspace") else redact(v, secrets))
                for k, v in manifest.items()}

    try:
        # written now as "running": a run killed outright (kill -9, power) is recognisable afterwards
        write_manifest(run_dir / "manifest.json", manifest_now("running", None))
        _explaining_os_errors(lambda: engine.run(on_step=lambda oc, i, n: log.info(_format_outcome(oc, i, n))),
                              site_root)
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
        if engine._lock is None and engine.outcomes is not None:
            manifest = manifest_now(status, error)
            failed = _failed_step(engine, status, error)
            if failed is not None:
                manifest["failed_step"] = failed
            engine.hashes.close()
            try:
                write_manifest(run_dir / "manifest.json", manifest)
            except OSError as exc:  # a full disk must not hide the run's own error behind a second traceback
                log.error("twinkit: could not write %s: %s", run_dir / "manifest.json", _os_text(exc, run_dir))
                if status == "ok":
                    raise StepError(f"the run finished, but its manifest could not be written: "
                                    f"{_os_text(exc, run_dir)}") from None
            if status == "ok":
                status = manifest["status"]  # "degraded" when a step said its result is far below what it should be
                log.info("twinkit: done in %.1f s; manifest %s", time.perf_counter() - t0, run_dir / "manifest.json")
                _say_degraded(manifest.get("degraded") or [], engine_cfg)
                if engine_cfg.get("report", True):
                    _write_report(run_dir, manifest, engine)
            elif failed is not None and engine_cfg.get("report", True):
                _write_report(run_dir, manifest, engine)  # a failed run's report: what ran, and the step that failed
        if saved_handlers:
            from twinkit.signals import restore_handlers

            restore_handlers(saved_handlers)
    return int(engine_cfg.get("degraded_exit_code", DEGRADED_EXIT)) if status == "degraded" else 0


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


def _os_error_in(exc: BaseException | None) -> OSError | None:
    """The OSError behind an exception (its cause or context chain), if any."""
    seen = 0
    while exc is not None and seen < 10:
        if isinstance(exc, OSError):
            return exc
        if "database or disk is full" in str(exc):  # sqlite3.OperationalError
            return OSError(errno.ENOSPC, "No space left on device")
        exc = exc.__cause__ or exc.__context__
        seen += 1
    return None


def _os_text(exc: OSError, where: Path) -> str:
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


def _explaining_os_errors(run, where: Path):
    """Run ``run()``; an OSError (disk full, unreadable file) becomes one line naming the cause and the path."""
    try:
        return run()
    except TwinkitError as exc:
        os_exc = _os_error_in(exc.__cause__)
        if os_exc is None or os_exc.errno not in (errno.ENOSPC, errno.EDQUOT, errno.EACCES, errno.EPERM):
            raise
        head = str(exc).split(" failed: ")[0]
        # an unreadable file is the input's problem (exit 2); a full disk is the run's (the step failed, exit 1)
        kind = InputError if os_exc.errno in (errno.EACCES, errno.EPERM) else type(exc)
        raise kind(f"{head} failed: {_os_text(os_exc, where)}") from exc.__cause__
    except OSError as exc:  # outside a step: hashing an input, the store, the hash cache
        if exc.errno in (errno.ENOSPC, errno.EDQUOT):
            raise StepError(_os_text(exc, where)) from exc
        raise InputError(_os_text(exc, where)) from exc
    except Exception as exc:  # e.g. sqlite3's "database or disk is full" from the hash cache
        os_exc = _os_error_in(exc)
        if os_exc is None or os_exc.errno not in (errno.ENOSPC, errno.EDQUOT):
            raise
        raise StepError(_os_text(os_exc, where)) from exc


def _job_threads(concurrent_jobs: int) -> int | None:
    """A multirun job's cap on threads: the cores divided among the launcher's concurrent jobs."""
    if concurrent_jobs <= 1:
        return None
    from twinkit.threads import cores

    return max(1, cores() // concurrent_jobs)


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


def _run_hydra(argv: list[str]) -> int:
    from twinkit.config import check_choices, check_configs_are_data, find_config_dir
    from twinkit.hydra_glue import open_site_inputs, options_first, register_configs, run_app, use_libyaml
    from twinkit.plugins import get_registry

    use_libyaml()
    conf_dir = find_config_dir()
    argv = open_site_inputs(options_first(argv))
    overrides = [a for a in argv if not a.startswith("-") and "=" in a]
    check_configs_are_data(conf_dir, argv)
    check_choices(overrides, conf_dir)
    if "--cfg" not in argv and "-c" not in argv and "--help" not in argv and "--info" not in argv:
        _check_writable(overrides, conf_dir)
    register_configs(get_registry())
    _STATE.update(conf_dir=str(conf_dir), argv=["twinkit", *argv])
    if not any(a.startswith("-") for a in argv):
        return _run_single(conf_dir, overrides)
    if "-m" in argv or "--multirun" in argv:
        _precheck_sweep(conf_dir, overrides)
    _STATE.pop("error", None)
    from twinkit.signals import forward_to_children

    with forward_to_children() as signalled:  # jobs stop like single runs, with their manifests
        try:
            run_app(conf_dir, argv, _job)
        except BaseException:
            if "exc" in signalled:
                raise signalled["exc"] from None
            raise
    if "exc" in signalled:
        raise signalled["exc"]
    if _STATE.get("error") is not None:
        raise _STATE.pop("error")
    if "-m" in argv or "--multirun" in argv:
        return _sweep_exit_code()
    return 0


def _sweep_exit_code() -> int:
    """A sweep whose jobs all finished exits like its worst job: degraded jobs give the degraded exit status."""
    import json

    try:
        from twinkit.report.sweep import SweepSummaryCallback
    except ImportError:
        return 0
    sweep, SweepSummaryCallback.last_sweep = SweepSummaryCallback.last_sweep, None
    if sweep is None:  # the sweep callback was configured away: nothing to read
        return 0
    worst = 0
    for mf in sorted(sweep.glob("*/manifest.json")):
        try:
            m = json.loads(mf.read_text())
        except (OSError, ValueError):
            continue
        if m.get("status") == "degraded":
            code = int(((m.get("config") or {}).get("engine") or {}).get("degraded_exit_code", DEGRADED_EXIT))
            log.error("twinkit: sweep job %s is DEGRADED (see its report)", mf.parent.name)
            worst = max(worst, code)
    return worst


def _precheck_sweep(conf_dir: Path, overrides: list[str]) -> None:
    """Every job of a sweep composed and its values checked (twinkit.config.check_config) before any job starts.

    So ``-m reconstructor.depth=11,30`` fails with exit 2 before the first job runs a step, as a single
    run does. The jobs are the ones Hydra's basic sweeper makes: the sweep file's
    ``hydra.sweeper.params`` and the command line's sweeps. Whatever this cannot enumerate is left to
    Hydra (and each job checks its own values again).
    """

    from twinkit.config import check_config
    from twinkit.hydra_glue import compose, parse_overrides, sweep_jobs
    from twinkit.plugins import get_registry

    jobs = sweep_jobs(conf_dir, overrides)
    if jobs is None:
        return  # Hydra reports it in its own words
    registry = get_registry()
    composed: dict[tuple, dict] = {}  # one composition per set of group choices; plain values are laid over it
    for job in jobs:
        job = [o for o in job if not o.lstrip("+~").startswith("hydra")]
        try:
            parsed_job = parse_overrides(job)
            values = {o.key_or_group: o.value() for o in parsed_job
                      if "." in o.key_or_group and not o.is_delete() and not o.is_add() and not o.is_force_add()
                      and "/" not in o.key_or_group and isinstance(o.value(), (int, float, str, bool))}
        except Exception:  # noqa: BLE001 -- then compose this job as it is
            values = {}
        rest = tuple(o for o in job if o.split("=", 1)[0].lstrip("+~") not in values)
        if rest not in composed:
            cfg = compose(conf_dir, list(rest) + [f"{k}={v!r}" if isinstance(v, str) else f"{k}={v}"
                                                  for k, v in values.items()])
            composed[rest] = _plain(cfg)
            container = composed[rest]
        else:
            container = _with_values(composed[rest], values)
        try:
            check_config(container, registry)
        except ConfigError as exc:
            raise ConfigError(f"{exc} (sweep job {' '.join(job)})") from None


def _with_values(container: dict, values: dict) -> dict:
    """A copy of a composed config with dotted keys set (the values one sweep job changes)."""
    import copy

    out = copy.deepcopy(container)
    for key, value in values.items():
        node = out
        *parents, last = key.split(".")
        for p in parents:
            if not isinstance(node.get(p), dict):
                node[p] = {}
            node = node[p]
        node[last] = value
    return out


def _run_single(conf_dir: Path, overrides: list[str]) -> int:
    """One run, composed once with Hydra's compose API (Hydra's own entry composes twice)."""
    from twinkit.hydra_glue import compose, set_run_config

    cfg = compose(conf_dir, overrides, hydra_config=True)
    set_run_config(cfg)
    run_dir = Path(cfg.hydra.run.dir)
    _check_writable([f"engine.outputs_dir={cfg.engine.outputs_dir}"])  # wherever the composed config puts it
    run_dir.mkdir(parents=True, exist_ok=True)
    return _execute(cfg, run_dir=run_dir, multirun=False, overrides=overrides)


# --------------------------------------------------------------------------- subcommands


def _compose(overrides: list[str]):

    from twinkit.config import check_choices, check_configs_are_data, find_config_dir
    from twinkit.hydra_glue import compose, open_site_inputs, register_configs, use_libyaml
    from twinkit.plugins import get_registry

    use_libyaml()
    conf_dir = find_config_dir()
    overrides = open_site_inputs(overrides)
    check_configs_are_data(conf_dir)
    check_choices(overrides, conf_dir)
    register_configs(get_registry())
    cfg = compose(conf_dir, overrides)
    from twinkit.engine import GIVEN_KEY, given_params

    container = _plain(cfg)
    container[GIVEN_KEY] = given_params(container, overrides)
    from twinkit.config import check_config

    check_config(container, get_registry())
    return conf_dir, container


def cmd_status(args: list[str]) -> int:
    from twinkit.engine import Engine
    from twinkit.plugins import get_registry

    conf_dir, cfg = _compose(args)
    site = cfg["site"]
    site_root = Path(cfg["engine"]["outputs_dir"]) / site["name"]
    engine = Engine(cfg, get_registry(), workspace=site_root, site_root=site_root, rerun=cfg.get("rerun"),
                    config_root=conf_dir.parent)
    rows = engine.status()
    print(f"recipe '{cfg['recipe'].get('name')}' on site '{site['name']}' in {site_root}")
    for sid, reason in engine.skipped:
        print(f"  {'-- ' + sid:<24} {'skipped':<12} {reason}")
    red = sys.stdout.isatty() and not os.environ.get("NO_COLOR")
    degraded = 0
    for folder, decision, why in rows:
        if decision == "DEGRADED":
            degraded += 1
            decision = f"\033[1;31m{decision:<12}\033[0m" if red else f"{decision:<12}"
        print(f"  {folder:<24} {decision:<12} {why}")
    if degraded:
        print(f"{degraded} step result(s) are DEGRADED: far below what they should be (reasons above)")
    return 0


def cmd_plugins(args: list[str]) -> int:
    from twinkit.plugins import get_registry

    reg = get_registry()
    if args:
        return _plugin_params(reg, args)
    rows = [(p.kind, p.name, p.version, p.distribution, p.description) for p in reg.all()]
    if not rows:
        print("no plugins loaded (TWINKIT_PLUGINS=%r)" % os.environ.get("TWINKIT_PLUGINS"))
        return 0
    w = [max(len(str(r[i])) for r in rows + [("kind", "name", "version", "distribution", "")]) for i in range(4)]
    print(f"{'kind':<{w[0]}}  {'name':<{w[1]}}  {'version':<{w[2]}}  {'distribution':<{w[3]}}  description")
    for r in rows:
        print(f"{r[0]:<{w[0]}}  {r[1]:<{w[1]}}  {r[2]:<{w[2]}}  {r[3]:<{w[3]}}  {r[4]}")
    return 0


def _plugin_params(reg, args: list[str]) -> int:
    """``twinkit plugins <kind>/<name>``: every parameter with its type, range, default and help."""
    import textwrap

    from twinkit.errors import PluginError
    from twinkit.ranges import describe_params

    if len(args) != 1:
        return _err("usage: twinkit plugins [<kind>/<name>]")
    kind, _, name = args[0].rpartition("/")
    found = [p for p in reg.all() if p.name == name and (not kind or p.kind == kind)]
    if len(found) != 1:
        have = ", ".join(p.qualname for p in reg.all()) or "none loaded"
        what = "several plugins named" if found else "no plugin"
        raise PluginError(f"{what} '{args[0]}' (available: {have})")
    plugin = found[0]
    print(f"{plugin.qualname}  {plugin.version}  {plugin.distribution}  {plugin.description}".rstrip())
    rows = describe_params(plugin.params)
    if not rows:
        print("  no parameters")
        return 0
    head = ("parameter", "type", "range", "default")
    w = [max(len(x) for x in col) for col in zip(head, *[(r.name, r.type, r.range, r.default) for r in rows])]
    print("  " + "  ".join(f"{h:<{w[i]}}" for i, h in enumerate(head)).rstrip())
    for r in rows:
        print("  " + "  ".join(f"{v:<{w[i]}}" for i, v in enumerate((r.name, r.type, r.range, r.default))).rstrip())
        if r.help:
            print(textwrap.fill(r.help, width=100, initial_indent=" " * 6, subsequent_indent=" " * 6))
    return 0


def cmd_verify(args: list[str]) -> int:
    from twinkit.manifest import verify_manifest

    if len(args) != 1:
        return _err("usage: twinkit verify <manifest.json | run folder>")
    p = Path(args[0])
    if p.is_dir():
        p = p / "manifest.json"
    if not p.is_file():
        return _err(f"{p}: no such manifest; runs write one to outputs/<site>/runs/<time>/manifest.json")
    problems = verify_manifest(p)
    if problems:
        for line in problems:
            print(line)
        print(f"{len(problems)} difference(s) against {p}")
        return 1
    print(f"ok: every input and output of {p} matches")
    return 0


def cmd_gc(args: list[str]) -> int:
    from twinkit.engine import collect_garbage, prune_hash_cache

    dry = "--dry-run" in args
    overrides = [a for a in args if a != "--dry-run"]
    conf_dir, cfg = _compose(overrides)
    site_root = Path(cfg["engine"]["outputs_dir"]) / cfg["site"]["name"]
    from twinkit.engine.locks import gc_locks

    if not site_root.is_dir():
        doomed: list[Path] = []
        size, forgotten = 0, 0
    else:
        with gc_locks(site_root):
            doomed, size = collect_garbage(site_root, dry_run=dry)
            forgotten = 0 if dry else prune_hash_cache(site_root)
    verb = "would remove" if dry else "removed"
    print(f"{verb} {len(doomed)} stored result(s), {size / 2**20:.1f} MiB, from {site_root / '.cache' / 'steps'}")
    if not dry:
        print(f"forgot {forgotten} remembered file hash(es) of files that are gone")
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    from twinkit.signals import sigterm_as_interrupt

    with sigterm_as_interrupt():  # SIGTERM (schedulers, docker stop, timeout) stops a run like Ctrl-C
        return _main(argv)


def _main(argv: list[str]) -> int:
    try:
        if argv and argv[0] in ("-h", "--help", "help"):
            print(__doc__.strip())
            print("\nHydra's own help: twinkit --hydra-help")
            return 0
        if argv and argv[0] == "--hydra-help":
            argv[0] = "--help"
        if argv and argv[0] in SUBCOMMANDS:
            return {"status": cmd_status, "plugins": cmd_plugins, "verify": cmd_verify,
                    "gc": cmd_gc}[argv[0]](argv[1:])
        return _run_hydra(argv)
    except TwinkitError as exc:
        return _err(str(exc), exc.exit_code)
    except KeyboardInterrupt as exc:
        from twinkit.signals import Terminated

        if isinstance(exc, Terminated):
            return _err("terminated (SIGTERM); finished steps are kept, the interrupted one will run again", 143)
        return _err("interrupted; finished steps are kept, the interrupted one will run again", 130)


if __name__ == "__main__":
    sys.exit(main())

"""The ``twinkit`` command.

    twinkit [recipe=<name>] [site=<name>] [key=value ...]     run a recipe on a site (Hydra overrides)
    twinkit -m ... a=1,2                                       multirun sweep (joblib launcher)
    twinkit ... --cfg job                                      print the composed config, run nothing
    twinkit status [overrides]                                 what a run would do, per step, without running
    twinkit plugins                                            loaded plugins with distributions and versions
    twinkit verify <manifest.json | run folder>                check a run's manifest against the files on disk
    twinkit gc [--dry-run] [site=<name>] [engine.outputs_dir=..] delete stored results no step folder refers to
"""
from __future__ import annotations

import datetime as _dt
import logging
import os
import sys
import time
from pathlib import Path

from twinkit.errors import ConfigError, TwinkitError

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


def _format_outcome(oc, i: int, n: int) -> str:
    dur = f"{oc.duration_s:7.1f} s" if oc.status in ("ran",) or oc.duration_s >= 0.05 else " " * 9
    mem = f"  peak {oc.peak_rss_mb:.0f} MB" if oc.status == "ran" and oc.peak_rss_mb else ""
    return f"[{i}/{n}] {oc.folder:<24} {oc.status:<7} {dur}  {oc.why}{mem}"


def _interactive(setting: str) -> bool:
    if str(setting).lower() in ("true", "yes", "1"):
        return True
    if str(setting).lower() in ("false", "no", "0"):
        return False
    return sys.stdin.isatty() and sys.stderr.isatty()


def _check_writable(overrides: list[str]) -> None:
    outputs = "outputs"
    for ov in overrides:
        if ov.startswith("engine.outputs_dir="):
            outputs = ov.split("=", 1)[1]
    from twinkit.engine import unwritable

    p = Path(outputs)
    problem = unwritable(p)
    if problem:
        raise ConfigError(f"cannot write to the outputs folder {p.resolve()} ({problem}); "
                          f"choose another with engine.outputs_dir=<dir>")


# --------------------------------------------------------------------------- the Hydra job

_STATE: dict = {}


def _job(cfg) -> int:
    """One Hydra job. A TwinkitError becomes a one-line message and an exit code, not a traceback."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    try:
        return _job_body(cfg)
    except TwinkitError as exc:
        if HydraConfig.get().mode == RunMode.MULTIRUN:
            from hydra.errors import CompactHydraException

            raise CompactHydraException(f"twinkit: error: {exc}") from None
        _STATE["error"] = exc
        return exc.exit_code
    except KeyboardInterrupt as exc:
        if HydraConfig.get().mode != RunMode.MULTIRUN:
            raise
        return _job_interrupted(exc)


def _job_interrupted(exc: KeyboardInterrupt) -> int:
    """A multirun job stopped by Ctrl-C or SIGTERM (its manifest says so) returns instead of raising: a
    raised error would make joblib kill the other jobs before they have written their manifests. The
    sweep's own process ends with 130 / 143 (``forward_to_children``); later jobs of this worker are skipped."""
    from twinkit.signals import Terminated

    _STATE["interrupted"] = 143 if isinstance(exc, Terminated) else 130
    return _STATE["interrupted"]


def _job_body(cfg) -> int:
    """A Hydra (multirun) job: read Hydra's runtime state, then execute."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    hc = HydraConfig.get()
    multirun = hc.mode == RunMode.MULTIRUN
    jobs = 1
    if multirun and _STATE.get("interrupted"):
        log.info("twinkit: job %s not started: the sweep was interrupted", hc.job.num)
        return _STATE["interrupted"]
    if multirun:
        from twinkit.executors import use_standard_start_method

        use_standard_start_method()  # a job runs in a loky worker: its fan-out pools must not inherit 'loky'
        from omegaconf import OmegaConf

        from twinkit.threads import cores

        jobs = int(OmegaConf.select(hc, "launcher.n_jobs", default=1) or 1)
        jobs = cores() if jobs <= 0 else jobs  # joblib's -1: as many jobs as cores
    from twinkit.signals import sigterm_as_interrupt

    with sigterm_as_interrupt():  # a job's process (a joblib worker) stops like a single run
        return _execute(cfg, run_dir=Path(hc.runtime.output_dir), multirun=multirun,
                        overrides=list(hc.overrides.task), concurrent_jobs=jobs)


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
    container = OmegaConf.to_container(cfg, resolve=True)
    from twinkit.engine import GIVEN_KEY, given_params

    container[GIVEN_KEY] = given_params(container, overrides)
    site = container.get("site") or {}
    if not site.get("name"):
        raise ConfigError("the site config has no 'name'")
    engine_cfg = container["engine"]
    site_root = Path(engine_cfg["outputs_dir"]) / site["name"]
    workspace = run_dir if multirun else site_root
    registry = get_registry()
    started = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    t0 = time.perf_counter()
    engine = Engine(
        container, registry, workspace=workspace, site_root=site_root, rerun=container.get("rerun") or [],
        interactive=_interactive(engine_cfg.get("interactive", "auto")),
        threads=engine_cfg.get("threads") or None, config_root=root,
        manual_timeout_s=engine_cfg.get("manual_timeout_s"),
        max_threads=_job_threads(concurrent_jobs),
    )
    recipe = container.get("recipe", {}).get("name", "?")
    log.info("twinkit: recipe '%s' on site '%s' -> %s (run log %s)", recipe, site["name"], workspace,
             run_dir / "run.log")
    status, error = "ok", None
    saved_handlers: dict = {}

    def manifest_now(status: str, error: str | None) -> dict:
        return build_manifest(
            argv=_STATE.get("argv", sys.argv), overrides=overrides, config=container, site=site,
            outcomes=engine.outcomes, engine=engine, registry=registry, project_root=root, status=status,
            error=error, started=started,
            finished=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            duration_s=time.perf_counter() - t0,
        )

    try:
        # written now as "running": a run killed outright (kill -9, power) is recognisable afterwards
        write_manifest(run_dir / "manifest.json", manifest_now("running", None))
        engine.run(on_step=lambda oc, i, n: log.info(_format_outcome(oc, i, n)))
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
            engine.hashes.close()
            write_manifest(run_dir / "manifest.json", manifest)
            if status == "ok":
                log.info("twinkit: done in %.1f s; manifest %s", time.perf_counter() - t0, run_dir / "manifest.json")
                if engine_cfg.get("report", True):
                    _write_report(run_dir, manifest, engine)
        if saved_handlers:
            from twinkit.signals import restore_handlers

            restore_handlers(saved_handlers)
    return 0


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


_VALUE_OPTIONS = {"--cfg", "-c", "--package", "-p", "--info", "-i", "--config-path", "-cp", "--config-name", "-cn",
                  "--config-dir", "-cd", "--experimental-rerun", "--shell-completion", "-sc"}


def options_first(argv: list[str]) -> list[str]:
    """Hydra's parser wants options before overrides; accept them in any order."""
    opts: list[str] = []
    overrides: list[str] = []
    i = 0
    while i < len(argv):
        a = argv[i]
        if a.startswith("-") and "=" not in a.split(" ")[0][:2]:
            opts.append(a)
            if a in _VALUE_OPTIONS and i + 1 < len(argv) and not argv[i + 1].startswith("-") and "=" not in argv[i + 1]:
                opts.append(argv[i + 1])
                i += 1
        else:
            overrides.append(a)
        i += 1
    return opts + overrides


def open_site_inputs(args: list[str]) -> list[str]:
    """``site.inputs.<name>=value`` adds the input when the site file does not list it.

    Site inputs are open-ended (a recipe may want photos, a GCP file, an OSM extract...), so a
    plain override adds or replaces the key (Hydra's ``++``); every other key stays strict, so a
    misspelled ``site.sede=3`` still fails at composition.
    """
    return [("++" + a) if a.startswith("site.inputs.") and "=" in a else a for a in args]


def _run_hydra(argv: list[str]) -> int:
    import hydra

    from twinkit.config import check_choices, find_config_dir, register_configs, use_libyaml
    from twinkit.plugins import get_registry

    use_libyaml()
    conf_dir = find_config_dir()
    argv = open_site_inputs(options_first(argv))
    overrides = [a for a in argv if not a.startswith("-") and "=" in a]
    check_choices(overrides, conf_dir)
    if "--cfg" not in argv and "-c" not in argv and "--help" not in argv and "--info" not in argv:
        _check_writable(overrides)
    register_configs(get_registry())
    _STATE.update(conf_dir=str(conf_dir), argv=["twinkit", *argv])
    if not any(a.startswith("-") for a in argv):
        return _run_single(conf_dir, overrides)
    app = hydra.main(config_path=str(conf_dir), config_name="config", version_base="1.3")(_job)
    saved = sys.argv
    sys.argv = ["twinkit", *argv]
    _STATE.pop("error", None)
    from twinkit.signals import forward_to_children

    with forward_to_children() as signalled:  # jobs stop like single runs, with their manifests
        try:
            app()
        except BaseException:
            if "exc" in signalled:
                raise signalled["exc"] from None
            raise
        finally:
            sys.argv = saved
    if "exc" in signalled:
        raise signalled["exc"]
    if _STATE.get("error") is not None:
        raise _STATE.pop("error")
    return 0


def _composition_error(exc: Exception) -> ConfigError:
    """Hydra/OmegaConf composition errors, folded into one line."""
    import re

    m = re.search(r"Could not find '([\w/]+)/([^']+)'\s*\nAvailable options in '[^']+':\s*\n(.*?)\nConfig search path",
                  str(exc), re.S)
    if m:
        options = ", ".join(o.strip() for o in m.group(3).splitlines() if o.strip()) or "none"
        return ConfigError(f"no {m.group(1).split('/')[-1]} plugin named '{m.group(2)}' (available: {options}); "
                           f"install the package that provides it, or check TWINKIT_PLUGINS")
    parts = [str(exc)]
    if exc.__cause__ is not None and str(exc.__cause__) not in parts[0]:
        parts.append(str(exc.__cause__))
    lines = []
    for part in parts:
        for line in part.splitlines():
            t = line.strip()
            if t and not t.startswith(("full_key", "object_type", "reference_type", "To append", "Set the environment")):
                lines.append(t.rstrip("."))
    return ConfigError(". ".join(dict.fromkeys(lines)))


def _run_single(conf_dir: Path, overrides: list[str]) -> int:
    """One run, composed once with Hydra's compose API (Hydra's own entry composes twice)."""
    from hydra import compose, initialize_config_dir
    from hydra.core.hydra_config import HydraConfig
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    try:
        with initialize_config_dir(config_dir=str(conf_dir), version_base="1.3", job_name="twinkit"):
            cfg = compose(config_name="config", overrides=overrides, return_hydra_config=True)
        HydraConfig.instance().set_config(cfg)
        run_dir = Path(cfg.hydra.run.dir)
    except (HydraException, OmegaConfBaseException) as exc:
        raise _composition_error(exc) from None
    run_dir.mkdir(parents=True, exist_ok=True)
    return _execute(cfg, run_dir=run_dir, multirun=False, overrides=overrides)


# --------------------------------------------------------------------------- subcommands


def _compose(overrides: list[str]):
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from twinkit.config import check_choices, find_config_dir, register_configs, use_libyaml
    from twinkit.plugins import get_registry

    use_libyaml()
    conf_dir = find_config_dir()
    overrides = open_site_inputs(overrides)
    check_choices(overrides, conf_dir)
    register_configs(get_registry())
    with initialize_config_dir(config_dir=str(conf_dir), version_base="1.3"):
        cfg = compose(config_name="config", overrides=overrides)
    from twinkit.engine import GIVEN_KEY, given_params

    container = OmegaConf.to_container(cfg, resolve=True)
    container[GIVEN_KEY] = given_params(container, overrides)
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
    for folder, decision, why in rows:
        print(f"  {folder:<24} {decision:<12} {why}")
    return 0


def cmd_plugins(args: list[str]) -> int:
    from twinkit.plugins import get_registry

    reg = get_registry()
    rows = [(p.kind, p.name, p.version, p.distribution, p.description) for p in reg.all()]
    if not rows:
        print("no plugins loaded (TWINKIT_PLUGINS=%r)" % os.environ.get("TWINKIT_PLUGINS"))
        return 0
    w = [max(len(str(r[i])) for r in rows + [("kind", "name", "version", "distribution", "")]) for i in range(4)]
    print(f"{'kind':<{w[0]}}  {'name':<{w[1]}}  {'version':<{w[2]}}  {'distribution':<{w[3]}}  description")
    for r in rows:
        print(f"{r[0]:<{w[0]}}  {r[1]:<{w[1]}}  {r[2]:<{w[2]}}  {r[3]:<{w[3]}}  {r[4]}")
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
    from filelock import FileLock, Timeout

    lock = FileLock(str(site_root / ".twinkit.lock")) if site_root.is_dir() else None
    try:
        if lock is not None:
            lock.acquire(timeout=0)
    except Timeout:
        return _err(f"a twinkit run is using {site_root}; run gc when it has finished")
    try:
        doomed, size = collect_garbage(site_root, dry_run=dry)
        forgotten = 0 if dry else prune_hash_cache(site_root)
    finally:
        if lock is not None and lock.is_locked:
            lock.release()
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

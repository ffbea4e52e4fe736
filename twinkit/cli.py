"""The ``twinkit`` command.

    twinkit [recipe=<name>] [site=<name>] [key=value ...]     run a recipe on a site (Hydra overrides)
    twinkit -m ... a=1,2                                       multirun sweep (joblib launcher)
    twinkit ... --cfg job                                      print the composed config, run nothing
    twinkit status [overrides]                                 what a run would do, per step, without running
    twinkit plugins                                            loaded plugins with distributions and versions
    twinkit plugins <kind>/<name>                              a plugin's parameters: type, range, default, help
    twinkit verify <manifest.json | run folder>                check a run's manifest against the files on disk
    twinkit gc [--dry-run] [site=<name>] [engine.outputs_dir=..] delete stored results no step folder refers to
    twinkit profile <run folder> [<earlier run | profile .json>] seconds and peak MB per step and substep
"""
from __future__ import annotations

import logging
import sys
from pathlib import Path

from twinkit.commands import COMMANDS
from twinkit.errors import ConfigError, TwinkitError, say_error
from twinkit.execute import execute
from twinkit.quality import DEGRADED_EXIT

# here: the command line, a run or a sweep through Hydra; the subcommands are in twinkit/commands.py, one
# run's execution (engine, progress lines, manifest, report, exit status) in twinkit/execute.py

log = logging.getLogger("twinkit")

SUBCOMMANDS = tuple(COMMANDS)  # status, plugins, verify, gc, profile: twinkit/commands.py

EXIT_OK, EXIT_STEP_FAILED = 0, 1


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
    """One Hydra job; a sweep's job runs in a child of the pool's worker and dies with the sweep
    (twinkit/sweeps.py)."""
    from twinkit.hydra_glue import is_multirun

    if not is_multirun():
        return _job_here(cfg)
    from twinkit.hydra_glue import job_state
    from twinkit.sweeps import run_job

    job = job_state()
    if _STATE.get("interrupted"):
        log.info("twinkit: job %s not started: the sweep was interrupted", job.num)
        return _STATE["interrupted"]
    code = run_job(_job_here, cfg, job.output_dir, f"job{job.num} ({' '.join(job.overrides)})")
    if code in (130, 143):
        _STATE["interrupted"] = code  # later jobs of this worker are skipped
    return code


def _job_here(cfg) -> int:
    """One Hydra job in this process. A TwinkitError becomes a one-line message and an exit code, not a
    traceback."""
    from twinkit.hydra_glue import is_multirun, job_error

    try:
        return _job_body(cfg)
    except TwinkitError as exc:
        if is_multirun():
            from twinkit.manifest import redact

            raise job_error(f"twinkit: error: {redact(str(exc))}", exc.exit_code) from None
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


def _job_body(cfg) -> int:
    """A Hydra (multirun) job: read Hydra's runtime state, then execute."""
    from twinkit.hydra_glue import job_state

    job = job_state()
    jobs = 1
    if job.multirun:
        from twinkit.executors import use_standard_start_method

        use_standard_start_method()  # a job runs in a loky worker: its fan-out pools must not inherit 'loky'
        from twinkit.threads import cores

        jobs = cores() if job.n_jobs <= 0 else job.n_jobs  # joblib's -1: as many jobs as cores
    from twinkit.signals import sigterm_as_interrupt

    with sigterm_as_interrupt():  # a job's process (a joblib worker) stops like a single run
        return execute(cfg, run_dir=job.output_dir, multirun=job.multirun, overrides=job.overrides,
                       concurrent_jobs=jobs, conf_dir=_STATE.get("conf_dir"), argv=_STATE.get("argv"))


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
        argv = argv + _precheck_sweep(conf_dir, overrides)
    _check_given_site_name(overrides)  # Hydra's app makes the run folder under it before a job can check
    _STATE.pop("error", None)
    from twinkit.signals import forward_to_children
    from twinkit.sweeps import mark_sweep

    mark_sweep()  # the sweep's workers die with this process
    with forward_to_children() as signalled:  # jobs stop like single runs, with their manifests
        try:
            run_app(conf_dir, argv, _job)
        except BaseException:
            if "exc" in signalled:
                raise signalled["exc"] from None
            from twinkit.sweeps import summary_after_failure

            summary_after_failure()  # a failed job's sweep gets its summary too
            raise
    if "exc" in signalled:
        raise signalled["exc"]
    if _STATE.get("error") is not None:
        raise _STATE.pop("error")
    if "-m" in argv or "--multirun" in argv:
        return _sweep_exit_code()
    return 0


def _check_given_site_name(overrides: list[str]) -> None:
    """A ``site.name`` given on the command line is a plain name (twinkit.config.check_site_name)."""
    from twinkit.config import check_site_name
    from twinkit.hydra_glue import override_value

    name = override_value(overrides, "site.name")
    if name is not None and "${" not in name:
        check_site_name(name)


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


def _precheck_sweep(conf_dir: Path, overrides: list[str]) -> list[str]:
    """Every job of a sweep composed and its values checked (twinkit.config.check_config) before any job starts;
    the overrides that keep the jobs within the sweep's memory budget (twinkit/sweeps.py).

    So ``-m reconstructor.depth=11,30`` fails with exit 2 before the first job runs a step, as a single
    run does. The jobs are the ones Hydra's basic sweeper makes: the sweep file's
    ``hydra.sweeper.params`` and the command line's sweeps. Whatever this cannot enumerate is left to
    Hydra (and each job checks its own values again).
    """

    from twinkit.config import check_config
    from twinkit.hydra_glue import compose, parse_overrides, plain, sweep_jobs
    from twinkit.manifest import env_secrets
    from twinkit.plugins import get_registry

    jobs = sweep_jobs(conf_dir, overrides)
    if jobs is None:
        return []  # Hydra reports it in its own words
    registry = get_registry()
    composed: dict[tuple, dict] = {}  # one composition per set of group choices; plain values are laid over it
    secrets: dict[str, str] = {}
    containers = []
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
            composed[rest] = plain(cfg)
            secrets.update(env_secrets(plain(cfg, resolve=False)))
            container = composed[rest]
        else:
            container = _with_values(composed[rest], values)
        try:
            check_config(container, registry, secrets=secrets)
        except ConfigError as exc:
            raise ConfigError(f"{exc} (sweep job {' '.join(job)})") from None
        containers.append(container)
    return _memory_budget(conf_dir, jobs[0], containers)


def _memory_budget(conf_dir: Path, first_job: list[str], containers: list[dict]) -> list[str]:
    """``hydra.launcher.n_jobs=<k>`` when the sweep's memory budget allows fewer jobs at once than asked
    (``first_job``: the first job's overrides)."""
    from twinkit.hydra_glue import compose, override_value
    from twinkit.sweeps import memory_plan
    from twinkit.threads import cores

    def asked() -> int:
        value = override_value(first_job, "hydra.launcher.n_jobs")
        if value is None:
            value = compose(conf_dir, first_job, hydra_config=True).hydra.launcher.n_jobs
        try:
            n_jobs = int(value)
        except (TypeError, ValueError):
            return len(containers)  # Hydra reports it
        return min(len(containers), cores() if n_jobs <= 0 else n_jobs)

    at_once, why = memory_plan(containers, asked)
    if not why:
        return []
    print(why, file=sys.stderr)
    return [f"hydra.launcher.n_jobs={at_once}"]


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

    from twinkit.config import check_composed_site_name

    cfg = compose(conf_dir, overrides, hydra_config=True)
    check_composed_site_name(cfg)  # the run folder is made under the site's name
    set_run_config(cfg)
    run_dir = Path(cfg.hydra.run.dir)
    _check_writable([f"engine.outputs_dir={cfg.engine.outputs_dir}"])  # wherever the composed config puts it
    run_dir.mkdir(parents=True, exist_ok=True)
    return execute(cfg, run_dir=run_dir, multirun=False, overrides=overrides, conf_dir=_STATE.get("conf_dir"),
                   argv=_STATE.get("argv"))


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
            return COMMANDS[argv[0]](argv[1:])
        return _run_hydra(argv)
    except TwinkitError as exc:
        return say_error(str(exc), exc.exit_code)
    except Exception as exc:  # a Hydra/OmegaConf config error met outside composition: the same one line
        from twinkit.hydra_glue import as_config_error

        err = as_config_error(exc)
        if err is None:
            raise
        return say_error(str(err), err.exit_code)
    except KeyboardInterrupt as exc:
        from twinkit.signals import Terminated

        if isinstance(exc, Terminated):
            return say_error("terminated (SIGTERM); finished steps are kept, the interrupted one will run again", 143)
        return say_error("interrupted; finished steps are kept, the interrupted one will run again", 130)


if __name__ == "__main__":
    sys.exit(main())

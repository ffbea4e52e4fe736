"""The subcommands ``twinkit status``, ``twinkit plugins``, ``twinkit verify``, ``twinkit gc`` and ``twinkit profile``."""
from __future__ import annotations

import os
import sys
from pathlib import Path

from twinkit.errors import say_error


def _compose(overrides: list[str]):
    """The config folder and the checked plain config of ``overrides``, composed as a run composes it."""
    from twinkit.config import check_choices, check_configs_are_data, find_config_dir
    from twinkit.hydra_glue import compose, open_site_inputs, plain, register_configs, use_libyaml
    from twinkit.plugins import get_registry

    use_libyaml()
    conf_dir = find_config_dir()
    overrides = open_site_inputs(overrides)
    check_configs_are_data(conf_dir, overrides)
    check_choices(overrides, conf_dir)
    register_configs(get_registry())
    cfg = compose(conf_dir, overrides)
    from twinkit.engine import GIVEN_KEY, given_params

    container = plain(cfg)
    container[GIVEN_KEY] = given_params(container, overrides)
    from twinkit.config import check_config
    from twinkit.manifest import env_secrets, remember_secrets

    secrets = env_secrets(plain(cfg, resolve=False))
    check_config(container, get_registry(), secrets=secrets)
    remember_secrets(secrets)  # what the command prints is redacted (twinkit.manifest.redact)
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
    from twinkit.manifest import redact

    def say(line: str) -> None:  # a changed value in a reason may be a secret
        print(redact(line))

    say(f"recipe '{cfg['recipe'].get('name')}' on site '{site['name']}' in {site_root}")
    for sid, reason in engine.skipped:
        say(f"  {'-- ' + sid:<24} {'skipped':<12} {reason}")
    red = sys.stdout.isatty() and not os.environ.get("NO_COLOR")
    degraded = 0
    for folder, decision, why in rows:
        if decision == "DEGRADED":
            degraded += 1
            decision = f"\033[1;31m{decision:<12}\033[0m" if red else f"{decision:<12}"
        say(f"  {folder:<24} {decision:<12} {why}")
    note = engine.stale_note()
    if note:
        say(note)
    if degraded:
        say(f"{degraded} step result(s) are DEGRADED: far below what they should be (reasons above)")
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
        return say_error("usage: twinkit plugins [<kind>/<name>]")
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
        return say_error("usage: twinkit verify <manifest.json | run folder>")
    p = Path(args[0])
    if p.is_dir():
        p = p / "manifest.json"
    if not p.is_file():
        return say_error(f"{p}: no such manifest; runs write one to outputs/<site>/runs/<time>/manifest.json")
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

    from twinkit.report.keep import Collected, tidy_reports

    keep = int(cfg["engine"].get("keep_reports", 3))
    reports = Collected()
    if not site_root.is_dir():
        doomed: list[Path] = []
        size, forgotten = 0, 0
    else:
        with gc_locks(site_root):
            doomed, size = collect_garbage(site_root, dry_run=dry)
            reports = tidy_reports(site_root, keep, dry_run=dry)
            forgotten = 0 if dry else prune_hash_cache(site_root)
    verb = "would remove" if dry else "removed"
    print(f"{verb} {len(doomed)} stored result(s), {size / 2**20:.1f} MiB, from {site_root / '.cache' / 'steps'}")
    print(f"{reports.summary(dry)} (engine.keep_reports={keep})")
    if not dry:
        print(f"forgot {forgotten} remembered file hash(es) of files that are gone")
    return 0


def cmd_profile(args: list[str]) -> int:
    """Where a finished run spent its time and memory, per step and substep (``twinkit.profile``)."""
    from twinkit.profile import print_profile

    return print_profile(args)


COMMANDS = {"status": cmd_status, "plugins": cmd_plugins, "verify": cmd_verify, "gc": cmd_gc, "profile": cmd_profile}

"""Planning: a recipe's steps become an ordered list of :class:`PlannedStep`, each bound to its plugin,
its resolved parameters and the sources of its inputs (an earlier step's output or a site input).

Nothing runs and nothing is written here; a wrong recipe fails before the first step."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import logging

from twinkit.engine.params import resolve_params
from twinkit.errors import ConfigError, TwinkitError
from twinkit.plugins import STEP_KINDS, Plugin, Registry
from twinkit.signature import Port, Signature, parse_signature

log = logging.getLogger("twinkit")

_STEP_SPEC_KEYS = {"id", "uses", "params", "inputs", "outputs", "foreach", "manual", "description", "optional"}


@dataclass
class StepSpec:
    """One entry of a recipe's ``steps`` list."""

    id: str
    uses: str | None = None
    params: dict = field(default_factory=dict)
    inputs: dict = field(default_factory=dict)
    outputs: dict = field(default_factory=dict)  # {out_<name>_<ext>: file name}: the step writes that name instead
    foreach: str | None = None
    manual: dict | None = None
    description: str = ""
    optional: bool = False  # skip the step (with a logged reason) when a required input is unavailable


@dataclass
class Source:
    """Where an input comes from: an earlier step's output, or a site input file."""

    filename: str
    step_index: int | None = None  # producer's index in the plan
    path: Path | None = None  # site input


@dataclass
class PlannedStep:
    index: int
    spec: StepSpec
    plugin: Plugin | None
    params: Any
    params_dict: dict
    signature: Signature
    inputs: dict[str, Source | None]
    outputs: tuple[Port, ...]
    components: dict[str, Any]
    foreach: Source | None = None

    @property
    def id(self) -> str:
        return self.spec.id

    @property
    def folder(self) -> str:
        return f"{self.index:02d}_{self.spec.id}"

    @property
    def label(self) -> str:
        return self.plugin.qualname if self.plugin else "manual"


def _spec_from(raw: Any, recipe_name: str, i: int) -> StepSpec:
    if isinstance(raw, str):
        raw = {"id": raw.split("/")[-1], "uses": raw}
    if not isinstance(raw, dict) or "id" not in raw:
        raise ConfigError(f"recipe '{recipe_name}': step #{i + 1} must be a mapping with an 'id' (got {raw!r})")
    unknown = set(raw) - _STEP_SPEC_KEYS
    if unknown:
        raise ConfigError(
            f"recipe '{recipe_name}', step '{raw['id']}': unknown key(s) {sorted(unknown)}; "
            f"allowed: {sorted(_STEP_SPEC_KEYS)}"
        )
    spec = StepSpec(**{k: v for k, v in raw.items()})
    spec.params = dict(spec.params or {})
    spec.inputs = dict(spec.inputs or {})
    spec.outputs = dict(spec.outputs or {})
    if not spec.id.replace("_", "").isalnum():
        raise ConfigError(f"recipe '{recipe_name}': step id {spec.id!r} must be letters, digits and '_'")
    if (spec.uses is None) == (spec.manual is None):
        raise ConfigError(f"recipe '{recipe_name}', step '{spec.id}': give exactly one of 'uses' or 'manual'")
    if spec.manual is not None and spec.outputs:
        raise ConfigError(f"recipe '{recipe_name}', step '{spec.id}': a manual step names its files in "
                          f"'manual: {{outputs: [...]}}', not in 'outputs'")
    return spec


def _site_inputs(site: dict) -> dict[str, Any]:
    return dict(site.get("inputs") or {})


#: the name that selects no plugin of a kind (``road_source=none``; twinkit/config.py offers it for every
#: step-like kind): steps using the kind are left out of the plan (logged), and with them the optional steps
#: that then read nothing a running step writes
NONE = "none"

#: key of the composed config holding the step parameters given on the command line (see ``given_params``)
GIVEN_KEY = "command_line_params"
#: key inside it: the plugins chosen on the command line, ``{kind: name}``
CHOSEN = "_chosen"


def given_params(cfg: dict, overrides: list[str]) -> dict:
    """The step parameters among the command-line ``overrides`` (``steps.<name>.<param>=...`` and
    ``<kind>.<param>=...``), with their composed values: ``{"steps": {name: {param: v}}, kind: {param: v}}``.

    Every parameter is already in the composed config (the plugins' defaults fill it), so a value there
    cannot tell a default from a choice; this keeps the choices, which then override a recipe's fixed
    ``params:``, as a user who types ``reconstructor.depth=11`` expects."""
    out: dict = {}
    for ov in overrides:
        if "=" not in ov or ov.startswith("~"):
            continue
        parts = ov.split("=", 1)[0].lstrip("+").split(".")
        if parts[0] == "steps" and len(parts) == 3:
            node = (cfg.get("steps") or {}).get(parts[1]) or {}
            if parts[2] in node:
                out.setdefault("steps", {}).setdefault(parts[1], {})[parts[2]] = node[parts[2]]
        elif parts[0] == "site" and len(parts) == 2:
            # a site field typed on the command line beats the recipe's ``site_params`` (a generator's params)
            node = cfg.get("site") or {}
            if parts[1] in node:
                out.setdefault("site", {})[parts[1]] = node[parts[1]]
        elif parts[0] in STEP_KINDS and parts[0] not in ("step", "site_generator") and len(parts) == 1:
            # '<kind>=<name>': a plugin chosen on the command line (no fallback replaces it, Plugin.fallback)
            out.setdefault(CHOSEN, {})[parts[0]] = ov.split("=", 1)[1].strip()
        elif parts[0] in STEP_KINDS and parts[0] not in ("step", "site_generator") and len(parts) == 2:
            node = cfg.get(parts[0]) or {}
            if parts[1] != "plugin" and parts[1] in node:
                out.setdefault(parts[0], {})[parts[1]] = node[parts[1]]
    return out


def build_plan(cfg: dict, registry: Registry, config_root: Path | None = None,
               skipped: list[tuple[str, str]] | None = None,
               fallbacks: list[tuple[str, str]] | None = None) -> list[PlannedStep]:
    """Turn the composed config into an ordered list of steps with wired inputs.

    Steps marked ``optional: true`` whose required inputs are unavailable are left out and
    appended to ``skipped`` as (step id, reason). A step whose kind is chosen as ``none``
    (``road_source=none``) is left out too, and after it every optional step none of whose inputs
    comes from a step that runs. A plugin chosen by the recipe's default that cannot serve the site is
    replaced by its registered fallback (``Plugin.fallback``), appended to ``fallbacks`` as (step id,
    reason). Raises ConfigError naming the recipe, step,
    plugin, key or file at fault.
    """
    site = cfg.get("site") or {}
    rname, specs = _recipe_specs(cfg)
    st = _Planning(cfg=cfg, registry=registry, site=site, site_inputs=_site_inputs(site),
                   given=cfg.get(GIVEN_KEY) or {}, site_name=site.get("name", "?"),
                   base_dir=config_root or Path.cwd(), skipped=skipped, fallbacks=fallbacks)
    plan: list[PlannedStep] = []
    idx = 0
    for spec in specs:
        idx += 1
        where = f"recipe '{rname}', step '{spec.id}'"
        plugin: Plugin | None = None
        params_obj: Any = None
        params_dict: dict[str, Any] = {}
        components: dict[str, Any] = {}
        if spec.manual is not None:
            signature = _manual_signature(spec, where)
        else:
            chosen = _bind_plugin(spec, where, st)
            if chosen is None:  # '<kind>=none'
                idx -= 1
                continue
            plugin, params_obj, params_dict, signature, components = chosen
            signature = _renamed_outputs(signature, spec.outputs, where)
        inputs = _wire_inputs(spec, signature, where, st)
        if inputs is None or _reads_nothing_that_runs(spec, signature, inputs, st):
            idx -= 1
            continue
        unknown_wiring = set(spec.inputs) - {p.param for p in signature.inputs}
        if unknown_wiring:
            raise ConfigError(
                f"{where}: 'inputs' names {sorted(unknown_wiring)}, but {plugin.qualname if plugin else 'the step'} "
                f"reads only {[p.param for p in signature.inputs]}"
            )
        foreach_src = None
        if spec.foreach:
            fport = Port("foreach", str(spec.foreach).partition(".")[0], str(spec.foreach).partition(".")[2] or None)
            foreach_src = _resolve_input(fport, spec.foreach, st.produced, st.site_inputs, st.site_name, where,
                                         st.base_dir, False)
            if not signature.wants_item:
                raise ConfigError(f"{where}: 'foreach' needs a plugin whose run() takes an 'item' parameter")
        ps = PlannedStep(idx, spec, plugin, params_obj, params_dict, signature, inputs, signature.outputs,
                         components, foreach_src)
        plan.append(ps)
        for o in ps.outputs:
            st.produced.append((o.filename, o.is_dir, idx))
    return plan


@dataclass
class _Planning:
    """What :func:`build_plan` knows while it walks the recipe's steps."""

    cfg: dict
    registry: Registry
    site: dict
    site_inputs: dict
    given: dict  # the command line's params (GIVEN_KEY)
    site_name: str
    base_dir: Path
    skipped: list[tuple[str, str]] | None
    fallbacks: list[tuple[str, str]] | None
    produced: list[tuple[str, bool, int]] = field(default_factory=list)  # (filename, is_dir, producer index)
    chosen_none: list[str] = field(default_factory=list)  # '<kind>=none' choices that left a step out (see NONE)
    left_out: list[tuple[str, bool, str]] = field(default_factory=list)  # (filename, is_dir, step id) of optional steps left out
    freed: set[str] = field(default_factory=set)  # site input keys read only by a plugin its fallback replaced


def _recipe_specs(cfg: dict) -> tuple[str, list[StepSpec]]:
    """The recipe's name and its steps (the site generator's first when the site names one); ConfigError on an
    empty recipe or a step id used twice."""
    site = cfg.get("site") or {}
    recipe = cfg.get("recipe") or {}
    rname = recipe.get("name", "?")
    raw_steps = list(recipe.get("steps") or [])
    if not raw_steps:
        raise ConfigError(f"recipe '{rname}' has no steps")
    specs: list[StepSpec] = []
    gen = site.get("generator")
    if gen:
        # ``site_params``: what the recipe needs of a generated site (pointcloud_site: no photo walk); the
        # generator takes the fields it knows (``_param_layers``)
        specs.append(StepSpec(id="site", uses=f"site_generator/{gen}", description="generate the site's inputs",
                              params=dict(recipe.get("site_params") or {})))
    specs += [_spec_from(r, rname, i) for i, r in enumerate(raw_steps)]
    ids = [s.id for s in specs]
    dup = {i for i in ids if ids.count(i) > 1}
    if dup:
        raise ConfigError(f"recipe '{rname}': step ids used twice: {sorted(dup)}")
    return rname, specs


def _manual_signature(spec: StepSpec, where: str) -> Signature:
    """The signature of a manual step: its ``outputs`` and ``inputs`` file names as ports."""
    manual = spec.manual or {}
    outs = manual.get("outputs") or []
    if not outs or not manual.get("instructions"):
        raise ConfigError(f"{where}: a manual step needs 'instructions' and 'outputs'")
    ports = []
    for o in outs:
        stem, _, ext = str(o).partition(".")
        ports.append(Port(f"out_{stem}_{ext}", stem, ext or "dir"))
    signature = Signature((), tuple(ports), False)
    in_names = manual.get("inputs") or []
    for n in in_names:
        stem, _, suffix = str(n).partition(".")
        in_ext = suffix or None
        signature = Signature(signature.inputs + (Port(f"in_{stem}" + (f"_{in_ext}" if in_ext else ""), stem, in_ext),), signature.outputs, False)
    return signature


def _renamed_outputs(signature: Signature, renames: dict, where: str) -> Signature:
    """``signature`` with the outputs a recipe step renames (``outputs: {out_gt_labels_npy: labels.npy}``) writing
    the new file names: the step function still receives the path under its own parameter, so one step can serve
    recipes that call its file differently. ConfigError on an unknown parameter, a changed extension (or file
    made folder) or two outputs of one name."""
    if not renames:
        return signature
    by_param = {p.param: p for p in signature.outputs}
    unknown = set(renames) - set(by_param)
    if unknown:
        raise ConfigError(f"{where}: 'outputs' names {sorted(unknown)}, but the step writes only {sorted(by_param)}")
    ports = []
    for p in signature.outputs:
        new = renames.get(p.param)
        if new is None:
            ports.append(p)
            continue
        stem, dot, ext = str(new).partition(".")
        if not stem or (ext if dot else "dir") != p.ext:
            raise ConfigError(f"{where}: 'outputs' renames {p.param} ({p.filename}) to {new!r}; keep its kind "
                              f"({'a folder name' if p.is_dir else '.' + str(p.ext)})")
        ports.append(Port(p.param, stem, p.ext))
    names = [p.filename for p in ports]
    if len(set(names)) != len(names):
        raise ConfigError(f"{where}: 'outputs' gives two outputs one name: {names}")
    return Signature(signature.inputs, tuple(ports), signature.wants_item)


def _bind_plugin(spec: StepSpec, where: str, st: _Planning):
    """The plugin a step uses (after its fallback, when the chosen one cannot serve the site), its resolved
    params, signature and components: (plugin, params, params_dict, signature, components); None when the kind is
    chosen as ``none`` (recorded in ``st.chosen_none`` and ``skipped``)."""
    uses = str(spec.uses)
    if "/" in uses:
        kind, name = uses.split("/", 1)
    else:
        kind, name = uses, None
    if kind not in STEP_KINDS:
        raise ConfigError(f"{where}: 'uses: {uses}' — kind must be one of {', '.join(STEP_KINDS)}")
    node = dict(st.cfg.get(kind) or {}) if kind != "step" else {}
    if name is None:
        name = node.get("plugin")
        if not name:
            raise ConfigError(f"{where}: no {kind} selected; add '{kind}=<name>' or 'uses: {kind}/<name>'")
    if name == NONE and kind not in ("step", "site_generator"):
        # an explicit choice of nothing (road_source=none): the step is left out, and so are the
        # optional steps after it that read nothing a running step writes
        st.chosen_none.append(f"{kind}={NONE}")
        if st.skipped is not None:
            st.skipped.append((spec.id, f"{kind}={NONE} was chosen (no {kind})"))
        return None
    try:
        plugin = st.registry.get(kind, name)
    except TwinkitError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    if plugin.fallback and (st.given.get(CHOSEN) or {}).get(kind) != name:
        alt = _fallback_if_needed(plugin, kind, name, spec, node, where, st)
        if alt is not plugin:
            plugin, name = alt, alt.name
    params_obj, params_dict = resolve_params(plugin, *_param_layers(kind, name, plugin, node, spec, st), where=where)
    try:
        signature = parse_signature(plugin.run)
    except ValueError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    components = {ckind: st.cfg.get(ckind) for ckind in plugin.uses}
    return plugin, params_obj, params_dict, signature, components


def _fallback_if_needed(plugin: Plugin, kind: str, name: str, spec: StepSpec, node: dict, where: str,
                        st: _Planning) -> Plugin:
    """``plugin``, or its registered fallback when it cannot serve the site and the fallback can (logged, and
    recorded in ``fallbacks``; the replaced plugin's site inputs go to ``st.freed``)."""
    why = _cannot_serve(plugin, spec, node, st.produced, st.site, st.site_inputs, st.site_name, where, st.base_dir)
    alt = None
    if why:
        try:
            alt = st.registry.get(kind, str(plugin.fallback))
        except TwinkitError as exc:
            raise ConfigError(f"{where}: {why}, and its fallback: {exc}") from None
        # a fallback that cannot serve the site either: one error naming both fixes (the same problem once),
        # before the first step (was: the chosen plugin's own error only, e.g. "needs input 'osm'" when the
        # scan in its place would have needed a georeference too)
        alt_why = _cannot_serve(alt, spec, {}, st.produced, st.site, st.site_inputs, st.site_name, where, st.base_dir)
        if alt_why:
            if alt_why == why:
                raise ConfigError(f"{where}: {why}")
            raise ConfigError(f"{where}: {kind}={name} cannot serve this site ({why}), nor its fallback "
                              f"{kind}={alt.name} ({alt_why})")
    if alt is None:
        return plugin
    # the site inputs the replaced plugin read: left empty ('???') they stop nothing, and
    # the later steps' optional inputs do not read them (_wire_inputs)
    st.freed |= {port.name for port in parse_signature(plugin.run).inputs}
    log.warning("step '%s': %s=%s cannot serve this site (%s): using %s=%s instead (choose "
                "%s=%s on the command line to insist, or %s=none to leave out the steps that use it)",
                spec.id, kind, name, why, kind, alt.name, kind, name, kind)
    if st.fallbacks is not None:
        st.fallbacks.append((spec.id, f"{kind}={alt.name} instead of {kind}={name}: {why}"))
    return alt


def _param_layers(kind: str, name: str, plugin: Plugin, node: dict, spec: StepSpec, st: _Planning) -> list[dict]:
    """The parameter layers of a step, lowest first: the site's (generator) or the config's, the recipe's fixed
    params, then what the user typed on the command line."""
    layers: list[dict] = []
    if kind == "site_generator":
        fields = [f.name for f in dataclasses.fields(plugin.params)] if plugin.params else []
        given_site = st.given.get("site") or {}
        return [{k: layer[k] for k in fields if k in layer} for layer in (st.site, spec.params, given_site)]
    if kind == "step":
        layers.append(dict((st.cfg.get("steps") or {}).get(name) or {}))
    elif node.get("plugin") == name:
        layers.append(node)
    layers.append(spec.params)
    # what the user typed on the command line beats the recipe's fixed params
    if kind == "step":
        layers.append(dict((st.given.get("steps") or {}).get(name) or {}))
    elif node.get("plugin") == name:
        layers.append(dict(st.given.get(kind) or {}))
    return layers


def _wire_inputs(spec: StepSpec, signature: Signature, where: str, st: _Planning) -> dict[str, Source | None] | None:
    """Each input port's source (None: an optional input not given); None when an optional step is left out
    because an input is unavailable (recorded in ``skipped`` and ``st.left_out``)."""
    inputs: dict[str, Source | None] = {}
    try:
        empty: list[tuple[Port, ConfigError]] = []
        for port in signature.inputs:
            want = spec.inputs.get(port.param)
            key = (want or port.name).partition(".")[0]
            # a site input of a plugin its fallback replaced (an OSM file that does not cover the site) is
            # not read by the later steps' optional inputs either: they take the fallback's files
            if port.optional and key in st.freed and not any(port.accepts(f, d) for f, d, _ in st.produced):
                inputs[port.param] = None
                continue
            try:
                inputs[port.param] = _resolve_input(
                    port, want, st.produced, st.site_inputs, st.site_name, where, st.base_dir, optional=port.optional
                )
            except ConfigError as exc:
                if not (port.optional and "needs input" in str(exc)):
                    raise
                inputs[port.param] = None
                empty.append((port, exc))
        # an optional input whose site input is left empty ('???') is not given when an earlier step
        # feeds the step another input (osm_to_opendrive after road_source=scan on a site without OSM);
        # with nothing else to work on the empty site input is the error
        if empty and not any(src is not None and src.step_index is not None for src in inputs.values()):
            port = empty[0][0]  # the skipped-step message below names this port
            raise empty[0][1]
    except ConfigError as exc:
        # a site input left empty ('???') fails even an optional step, unless a '<kind>=none' choice left
        # out the step that would have used it (site mex's osm with road_source=none)
        if not spec.optional or ("needs input" in str(exc) and not st.chosen_none):
            raise
        by = next((sid for f, d, sid in reversed(st.left_out) if port.accepts(f, d)), None)
        if st.skipped is not None:
            if by is not None:
                st.skipped.append((spec.id, f"optional step: its input {port.param} comes from {by}, which was left out"))
            else:
                why = f" ({', '.join(st.chosen_none)})" if st.chosen_none and "needs input" in str(exc) else ""
                st.skipped.append((spec.id, f"optional step: no {port.name} ({port.param}) on this site{why}"))
        st.left_out.extend((o.filename, o.is_dir, spec.id) for o in signature.outputs)
        return None
    return inputs


def _reads_nothing_that_runs(spec: StepSpec, signature: Signature, inputs: dict, st: _Planning) -> bool:
    """After a '<kind>=none' choice: is this an optional step none of whose inputs a running step writes (then it
    is left out, recorded in ``skipped`` and ``st.left_out``)?"""
    if spec.optional and st.chosen_none and signature.inputs and not any(
            src is not None and src.step_index is not None for src in inputs.values()):
        if st.skipped is not None:
            st.skipped.append((spec.id, f"optional step: none of its inputs ({', '.join(p.param for p in signature.inputs)}) is "
                                        f"written by a step that runs ({', '.join(st.chosen_none)})"))
        st.left_out.extend((o.filename, o.is_dir, spec.id) for o in signature.outputs)
        return True
    return False


def _cannot_serve(plugin: Plugin, spec: StepSpec, node: dict, produced, site: dict, site_inputs: dict,
                  site_name: str, where: str, base_dir: Path) -> str:
    """Why ``plugin`` cannot serve this site ('' when it can): an input it needs cannot be wired, or its
    preflight finds a problem (the cheap checks, run here with its resolved parameters)."""
    try:
        signature = parse_signature(plugin.run)
        inputs: dict[str, Path | None] = {}
        for port in signature.inputs:
            src = _resolve_input(port, spec.inputs.get(port.param), produced, site_inputs, site_name, where,
                                 base_dir, optional=port.optional)
            if src is not None:
                inputs[port.param] = src.path
    except ConfigError as exc:
        return str(exc).replace(f"{where}: ", "")
    if plugin.preflight is None:
        return ""
    try:
        params_obj, _ = resolve_params(plugin, node if node.get("plugin") == plugin.name else {}, spec.params,
                                       where=where)
        found = plugin.preflight(site, params_obj, inputs) or []
    except TwinkitError as exc:
        found = [str(exc)]
    except Exception as exc:  # noqa: BLE001 -- a preflight's bug: no fallback, the run's preflight logs it
        log.debug("%s: preflight of %s failed at plan time: %s", where, plugin.qualname, exc)
        return ""
    return "; ".join(str(p) for p in found)


def _resolve_input(port: Port, want: str | None, produced, site_inputs: dict, site_name: str, where: str,
                   base_dir: Path, optional: bool) -> Source | None:
    # 1. latest earlier step that writes it
    for filename, is_dir, idx in reversed(produced):
        if want is not None:
            ok = filename == want
        else:
            ok = port.accepts(filename, is_dir)
        if ok:
            # ambiguity within the same producer (cloud.e57 / cloud.las / cloud.ply for in_cloud)
            same = [f for f, d, i in produced if i == idx and (f == want if want else port.accepts(f, d))]
            if len(same) > 1:
                raise ConfigError(
                    f"{where}: input '{port.param}' matches {same} of one step; choose one with "
                    f"'inputs: {{{port.param}: <file>}}' in the recipe"
                )
            return Source(filename=filename, step_index=idx)
    # 2. a site input
    key = (want or port.name).partition(".")[0]
    if key in site_inputs:
        value = site_inputs[key]
        if value is None or value == "???" or value == "":
            raise ConfigError(
                f"site '{site_name}' needs input '{key}' (for {where}): give it on the command line "
                f"(site.inputs.{key}=/path/to/file) or in conf/local/{site_name}.yaml"
            )
        path = Path(str(value)).expanduser()
        if not path.is_absolute():
            path = (base_dir / path).resolve()
        if port.ext not in (None, "dir") and path.suffix.lower() != f".{port.ext}":
            raise ConfigError(f"{where}: site input '{key}' is {path.name}, but '{port.param}' reads .{port.ext} files")
        return Source(filename=path.name, path=path)
    if optional:
        return None
    have = sorted({f for f, _, _ in produced}) + [f"site input '{k}'" for k in site_inputs]
    raise ConfigError(
        f"{where}: nothing provides input '{port.param}' ({want or port.name}); no earlier step writes it and site "
        f"'{site_name}' has no input '{key}'. Available: {', '.join(have) or 'nothing'}"
    )

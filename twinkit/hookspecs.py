"""Hook specifications: the only way code becomes part of twinkit.

Every registration hook receives a ``register`` callback::

    register(name, run, params=None, version=None, description="", uses=(), preflight=None, fallback=None)

``name`` is what users type (``reconstructor=poisson``); ``run`` is the
callable described per kind below; ``params`` is a dataclass whose fields are
the plugin's parameters (turned into a Hydra structured config, so a typo or a
wrong type fails at composition); ``version`` defaults to the version of the
distribution that provides the plugin; ``uses`` names component kinds
(``image_model``, ``view_sampler``, ``executor``) whose configuration becomes
part of the step's cache key. Registering a name twice for one kind raises
:class:`twinkit.errors.PluginError`; nothing is ever renamed.

``preflight(site, params, inputs)`` (optional) holds a step-like plugin's cheap checks: the engine
calls it for every planned step before the first step runs, with the site, the step's resolved
parameters and ``inputs`` (``{in_<name>: Path | None}``: every input wired to the step, the path of a
site input file, None for a file an earlier step writes, which does not exist yet). It returns a list of problems, one line each (an empty list:
fine), and may log; a problem stops the run with exit 2 before any long step (docs/engine.md,
"Preflight").

``fallback`` (optional, step-like kinds) names another plugin of the same kind that the planner uses
instead when this one is the recipe's default choice (not typed on the command line) and cannot serve
the site: an input it needs cannot be wired, or its preflight finds a problem. The switch is logged
(``road_source=file`` without an OSM file covering the site falls back to ``road_source=scan``).

Step-like kinds (site generators, reconstructors, segmenters, road sources,
exporters and generic steps) have ``run(params, ctx, **files)``: keyword
arguments named ``in_<name>[_<ext>]`` receive input paths and
``out_<name>[_<ext>]`` receive the paths the step must write (``_dir`` means
a folder). Component kinds (view samplers, image models, executors) have
``run(params)`` returning an object; steps obtain one with
``ctx.component(kind)``.

Report sections are no plugin kind (a recipe cannot bind one): their hook's
``register(name, render, title="", order=500)`` adds a section to the run
report (see :func:`twinkit_register_report_sections`).
"""
from __future__ import annotations

import pluggy

hookspec = pluggy.HookspecMarker("twinkit")


@hookspec
def twinkit_register_site_generators(register):
    """Register generators that write a whole site's inputs (cloud, photos, roads, truth)."""


@hookspec
def twinkit_register_reconstructors(register):
    """Register reconstructors: point cloud or photos in, mesh out."""


@hookspec
def twinkit_register_segmenters(register):
    """Register segmenters: mesh in, per-vertex CityScapes labels out."""


@hookspec
def twinkit_register_view_samplers(register):
    """Register view samplers (components): ``run(params)`` returns an object with ``sample(mesh, ctx) -> views``."""


@hookspec
def twinkit_register_image_models(register):
    """Register 2D segmentation models (components): ``run(params)`` returns an object with ``predict(images)``."""


@hookspec
def twinkit_register_road_sources(register):
    """Register road sources: site in, OpenStreetMap data out."""


@hookspec
def twinkit_register_exporters(register):
    """Register exporters: labelled mesh (and roads) in, simulator files out."""


@hookspec
def twinkit_register_steps(register):
    """Register generic steps that fit no other kind (cleanup, simplify, evaluate, ...)."""


@hookspec
def twinkit_register_executors(register):
    """Register executors (components) that run fanned-out items: ``run(params)`` returns an object with ``map(fn, items)``."""


@hookspec
def twinkit_register_report_sections(register):
    """Register sections of the run report: ``register(name, render, title="", order=500)``.

    ``name`` is the section's id in the page (``report.json`` lists them); ``render(ctx)`` returns an
    HTML fragment, or ``None``/``""`` to leave the section out (e.g. when the run has none of the
    plugin's files); ``ctx`` is a :class:`twinkit.report.context.SectionContext` (the run's manifest,
    its step folders and ``step.json`` records, HTML helpers, the cached top-down picture, writing a
    picture into the report). ``title`` heads the section; ``order`` places it among the others
    (core: summary 100, timeline 200, 3D view 300, pictures 400, provenance 1000, files 1100).
    Plugins that register the same ``name`` add parts to one section (e.g. their pictures to
    ``pictures``, whose parts return ``<figure>`` elements). A section that raises is left out of the
    page with a note, and the run does not fail.
    """

"""What a report section sees: :class:`SectionContext`.

A section is a function ``render(ctx) -> str | None`` that returns an HTML fragment (``None`` or ``""``:
the section is left out). Plugins register theirs through the hook ``twinkit_register_report_sections``
(see docs/writing-a-plugin.md); the core registers the run summary, the timeline, the 3D view, the
orthophotos, the provenance and the file list (``twinkit.report.sections``).

The context offers, all read-only except the report folder:

- the run: ``ctx.manifest``, ``ctx.run_dir``, ``ctx.workspace``, ``ctx.steps`` (the manifest's steps,
  each a dict with the manifest entry (``id``, ``folder``, ``plugin`` = ``kind/name``, ``status``,
  ``metrics``...) plus ``dir`` (the step folder), ``record`` (its ``step.json``), ``files`` (every file in
  it) and ``hashes``);
- finding outputs: ``ctx.steps_of(distribution=, kind=, name=)``, ``ctx.own_steps()`` (the steps run by
  plugins of the distribution that registered the section), ``ctx.outputs(step)`` (the step's declared
  outputs by name, from ``step.json``), ``ctx.find(pattern, steps=None)`` and ``ctx.first(pattern)``
  (files by glob, latest step first), ``ctx.read_json(path)``;
- the unit of lengths: ``ctx.length_unit()`` ("m", or "model units" for an unscaled photo run);
- HTML helpers: ``ctx.esc``, ``ctx.attr``, ``ctx.url``, ``ctx.link`` (the only way a value from the run goes
  into the page: :mod:`twinkit.report.html`), ``ctx.table``, ``ctx.figure``, ``ctx.legend``, ``ctx.fmt``,
  ``ctx.size``, ``ctx.CITYSCAPES``, ``ctx.palette()``, ``ctx.flatten`` (nested dict -> ``{'a.b': v}``) (see
  :mod:`twinkit.report.page`);
- pictures: ``ctx.ortho()``: the cached top-down orthophoto of the run's mesh (``{'texture': 'img/ortho.png',
  'segmentation': ..., 'bounds': (xmin, ymin, xmax, ymax), 'size': (w, h), 'mesh': Path, 'step': dict}``
  or None), ``ctx.render_topdown`` (the renderer itself), ``ctx.cache_dir`` and ``ctx.key_of(step, path)``
  (a content key for caching a picture in ``<site>/.cache/report/``; ``ctx.file_key(path)`` without a
  step), ``ctx.touch(path)`` (marks a cached file as used: the cache drops files unused for 30 days);
- writing into the report folder: ``ctx.add_image(path, name=None)`` links a picture into ``img/`` and
  returns its page address; ``ctx.out`` is the folder being written (assets go there; the finished
  report is ``ctx.report_dir``); ``ctx.href(path)`` is a link from the page to any file.
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from twinkit.report import html as _html
from twinkit.report import page as _page
from twinkit.report.render import TopDown, render_topdown
from twinkit.report.run import RunView, cached_copy, file_key, flatten, frame_unit, link_or_copy, read_json, rel, touch

log = logging.getLogger("twinkit.report")


class SectionContext:
    """The run, its step folders and the report being written, as one report section sees them."""

    esc = staticmethod(_html.esc)
    attr = staticmethod(_html.attr)
    url = staticmethod(_html.url)
    link = staticmethod(_html.link)
    fmt = staticmethod(_page.fmt)
    size = staticmethod(_page.size)
    table = staticmethod(_page.table)
    figure = staticmethod(_page.figure)
    legend = staticmethod(_page.legend)
    status_badge = staticmethod(_page.status_badge)
    palette = staticmethod(_page.palette)
    CITYSCAPES = _page.CITYSCAPES
    render_topdown = staticmethod(render_topdown)
    flatten = staticmethod(flatten)
    file_key = staticmethod(file_key)
    touch = staticmethod(touch)
    log = log

    def __init__(self, run: RunView, out: Path, topdown: TopDown, distribution: str = "twinkit"):
        self.run = run
        self.out = Path(out)
        self.topdown = topdown
        self.distribution = distribution
        self._state = {"ortho_tried": False}  # shared by the copies of for_distribution

    def for_distribution(self, distribution: str) -> "SectionContext":
        """The same context, as seen by a section of ``distribution`` (``own_steps`` follows it)."""
        c = SectionContext.__new__(SectionContext)
        c.__dict__.update(self.__dict__)
        c.distribution = distribution
        return c

    # ------------------------------------------------------------------ the run
    @property
    def manifest(self) -> dict:
        return self.run.manifest

    @property
    def run_dir(self) -> Path:
        return self.run.run_dir

    @property
    def workspace(self) -> Path:
        return self.run.workspace

    @property
    def report_dir(self) -> Path:
        return self.run.report_dir

    @property
    def cache_dir(self) -> Path:
        return self.run.cache_dir

    @property
    def steps(self) -> list[dict]:
        return self.run.steps

    def steps_of(self, distribution: str | None = None, kind: str | None = None,
                 name: str | None = None) -> list[dict]:
        """Steps run by plugins of ``distribution`` (``step.json``) and/or of plugin ``kind`` / ``name``."""
        out = []
        for s in self.run.steps:
            rec = s.get("record") or {}
            plug = (rec.get("descriptor") or {}).get("plugin") or {}
            k, _, n = str(s.get("plugin") or "").partition("/")
            if distribution is not None and rec.get("distribution") != distribution:
                continue
            if kind is not None and (plug.get("kind") or k) != kind:
                continue
            if name is not None and (plug.get("name") or n) != name:
                continue
            out.append(s)
        return out

    def own_steps(self) -> list[dict]:
        """The steps run by plugins of the distribution that registered this section."""
        return self.steps_of(distribution=self.distribution)

    @staticmethod
    def outputs(step: dict) -> dict[str, Path]:
        """The step's declared outputs that exist, by file name (``step.json``: ``descriptor.outputs``)."""
        names = ((step.get("record") or {}).get("descriptor") or {}).get("outputs") or []
        return {n: step["dir"] / n for n in names if (step["dir"] / n).exists()}

    def find(self, pattern: str, steps: list[dict] | None = None) -> list[tuple[dict, Path]]:
        """Files whose name matches a glob (case-insensitive), latest step first; only in ``steps`` if given."""
        if steps is None:
            return self.run.find(pattern)
        ids = {id(s) for s in steps}
        return [(s, f) for s, f in self.run.find(pattern) if id(s) in ids]

    def first(self, pattern: str, steps: list[dict] | None = None) -> tuple[dict, Path] | None:
        hits = self.find(pattern, steps)
        return hits[0] if hits else None

    def length_unit(self) -> str:
        """The unit to print after a length: "m", or "model units" for an unscaled photo run
        (:func:`~twinkit.report.run.frame_unit`)."""
        return frame_unit(self.run.steps)

    def key_of(self, step: dict, p: Path) -> str:
        return self.run.key_of(step, p)

    @staticmethod
    def read_json(p: Path, limit: int = 4_000_000) -> Any:
        return read_json(p, limit)

    # ------------------------------------------------------------------ the report folder
    def href(self, target: Path) -> str:
        """A relative link from the page to ``target``."""
        return rel(target, self.run.report_dir)

    def add_image(self, src: Path, name: str | None = None) -> str:
        """Put a copy of a picture into the report's ``img/`` (a hard link to its copy in the report cache,
        :func:`~twinkit.report.run.cached_copy`) and return its address in the page."""
        name, src = name or Path(src).name, Path(src)
        cache = self.run.cache_dir
        link_or_copy(src if src.parent == cache else cached_copy(src, cache), self.out / "img" / name)
        return f"img/{name}"

    def ortho(self) -> dict | None:
        """The top-down orthophoto of the run's mesh (rendered once per input content), or None."""
        if not self._state["ortho_tried"]:
            self._state["ortho_tried"] = True
            try:
                self.topdown.ortho()
            except Exception as exc:
                log.warning("twinkit: report: no orthophoto (%s)", exc)
                log.debug("orthophoto", exc_info=True)
        return self.topdown.frame

"""twinkit-tiles' part of the run report: the tile seams picture of merge_tiles in the "Pictures" gallery.

Registered through ``twinkit_register_report_sections`` (plugin.py exposes the hook implementation).
"""
from __future__ import annotations

from twinkit import hookimpl


@hookimpl
def twinkit_register_report_sections(register):
    register("pictures", sec_pictures, order=420)


def sec_pictures(ctx) -> str:
    """The tile seams picture (``tile_seams.png``, next to ``tile_seams.json``)."""
    figs = []
    for pattern, caption in (("tile_seams.png", "Tile seams: open edges on the seams circled (red: facing surface, "
                                                "orange: the surface ends on the seam)"),):
        for s, f in ctx.find(pattern)[:1]:
            name = f"{s.get('folder')}_{f.name}"
            figs.append(ctx.figure(ctx.add_image(f, name), ctx.esc(caption),
                                   f" <span class=\"dim\">{ctx.esc(s.get('folder'))}/{ctx.esc(f.name)}</span>"))
    return "".join(figs)

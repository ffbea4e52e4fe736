"""Page assembly and the HTML helpers that sections use.

Helpers (all return HTML text; every value passed in is escaped unless marked ``("html", text)``; the
escaping itself is :mod:`twinkit.report.html`: ``esc``, ``attr``, ``url``, ``link``):

- ``fmt(v)``: a number as the report prints it (thin-space thousands, 4 significant digits...).
- ``size(n)``: a byte count as ``12.3 MB``.
- ``table(headers, rows, cls="")``: a table; a cell ``("html", text)`` is put in as it is; numbers are
  right-aligned and formatted with ``fmt``.
- ``figure(src, caption, extra="")``: a linked picture (``src`` relative to the report folder, e.g. what
  ``SectionContext.add_image`` returns; made safe with ``url``) with its caption (HTML) and extra HTML after it.
- ``legend(present=None)``: the CityScapes colour legend (all classes, or the trainIds in ``present``).
- ``status_badge(status)``: a step status badge (ran, cached, reused, ...).

``CITYSCAPES`` lists the 19 CityScapes trainIds as (name, (r, g, b)); ``palette()`` is the 256 x 3 lookup.
"""
from __future__ import annotations

import datetime as _dt
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from twinkit import cityscapes
from twinkit.report.html import attr, esc, link, url

ASSETS = Path(__file__).resolve().parents[1] / "report_assets"
CSS_FILE = "report.css"

#: CityScapes trainIds 0..18: names and colours (the official palette, from twinkit.cityscapes).
CITYSCAPES = [(name, tuple(int(v) for v in cityscapes.PALETTE[i])) for i, name in enumerate(cityscapes.NAMES)]
IGNORE_COLOR = cityscapes.IGNORE_RGB


def palette() -> np.ndarray:
    """256 x 3 uint8: CityScapes colours for trainIds 0..18, black for everything else (255 = ignore)."""
    return cityscapes.lut()


def fmt(v: Any) -> str:
    if isinstance(v, bool) or v is None:
        return str(v)
    if isinstance(v, int):
        return f"{v:,}".replace(",", "\u2009")
    if isinstance(v, float):
        if v != v:
            return "nan"
        a = abs(v)
        if a == 0:
            return "0"
        if a >= 1e5 or a < 1e-3:
            return f"{v:.3g}"
        if a >= 100:
            return f"{v:.1f}"
        return f"{v:.4g}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(fmt(x) for x in v) + "]"
    return str(v)


def size(n: float) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if n < 1024 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return str(n)



class Page:
    def __init__(self, out: Path):
        self.out = out
        self.sections: list[tuple[str, str, str]] = []  # id, title, html
        self.notes: list[str] = []
        self.banner: str = ""  # HTML shown above everything (a degraded run's reasons)

    def add(self, sid: str, title: str, body: str | None) -> None:
        if body:
            self.sections.append((sid, title, body))


def table(headers: list[str], rows: list[list[Any]], cls: str = "") -> str:
    h = "".join(f"<th>{esc(x)}</th>" for x in headers)
    body = []
    for r in rows:
        cells = []
        for x in r:
            if isinstance(x, tuple) and len(x) == 2 and x[0] == "html":
                cells.append(f"<td>{x[1]}</td>")
            else:
                num = isinstance(x, (int, float)) and not isinstance(x, bool)
                cells.append(f"<td class=\"num\">{esc(fmt(x))}</td>" if num else f"<td>{esc(fmt(x))}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table{attr('class', cls)}><thead><tr>{h}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def figure(src: str, caption: str, extra: str = "") -> str:
    img = f"<img src=\"{url(src)}\"{attr('alt', caption)} loading=\"lazy\">"
    return f"<figure>{link(src, text_html=img)}<figcaption>{caption}{extra}</figcaption></figure>"


def status_badge(status: str) -> str:
    return f"<span{attr('class', f'badge st-{status}')}>{esc(status)}</span>"


def legend(present: Iterable[int] | None = None) -> str:
    items = [(i, n, c) for i, (n, c) in enumerate(CITYSCAPES) if present is None or i in present]
    return "<div class=\"legendbox\">" + "".join(
        f"<span><i style=\"background:rgb{c}\"></i>{esc(n)}</span>" for _, n, c in items) + "</div>"


def degraded_banner(entries: list[dict]) -> str:
    """The red box of a degraded run: each reason with its step and the setting to try."""
    items = []
    for e in entries:
        where = esc(e.get("step", "?")) + (f" (item {esc(e['item'])})" if e.get("item") is not None else "")
        hint = f" <i>({esc(e['hint'])})</i>" if e.get("hint") else ""
        items.append(f"<li><b>{where}</b>: {esc(e.get('reason', ''))}{hint}</li>")
    return (f"<div class=\"degraded\" id=\"degraded\"><b>Degraded result:</b> the run finished, but "
            f"{len(entries)} step result(s) are far below what they should be.<ul>{''.join(items)}</ul></div>")


def failed_banner(failed: dict) -> str:
    """The red box of a failed run: the step it stopped in and the error."""
    return (f"<div class=\"degraded failed\" id=\"failed\"><b>Failed run:</b> it stopped in step "
            f"{link('#step-' + str(failed.get('folder', '')), text_html='<b>' + esc(failed.get('id', '?')) + '</b>')} "
            f"({esc(failed.get('status', 'failed'))}): {esc(failed.get('error', ''))}. The steps before it are "
            f"shown as they ran.</div>")


def render_page(title: str, page: Page, subtitle: str = "") -> str:
    nav = "".join(link(f"#{sid}", t) for sid, t, _ in page.sections)
    body = "".join(f"<section{attr('id', sid)}><h2>{esc(t)}</h2>{h}</section>" for sid, t, h in page.sections)
    notes = "".join(f"<p class=\"warn\">{esc(n)}</p>" for n in page.notes)
    gen = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    return (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
        f"<title>{esc(title)}</title><link rel=\"stylesheet\" href=\"{url(CSS_FILE)}\"></head><body>"
        f"<header><h1>{esc(title)}</h1><p>{subtitle}</p><nav>{nav}</nav></header>{page.banner}{notes}<main>{body}</main>"
        f"<footer>written by twinkit.report at {gen}</footer></body></html>\n"
    )

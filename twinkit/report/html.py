"""The one way report code puts text into HTML: every value from a run (a name, a path, a message, a
number) goes through these helpers; only literal markup is written by hand.

- ``esc(x)``: ``str(x)`` escaped for HTML text and for a quoted attribute value (``& < > " '``).
- ``attr(name, value)``: `` name="value"`` with the value escaped (for ids, classes, titles, styles).
- ``url(path)``: a relative path or address made safe for ``href``/``src``: characters that would
  change its meaning (space, ``"``, ``<``, ``&``, ``#`` in a file name...) percent-encoded, then escaped.
- ``link(href, text)``: ``<a href="...">text</a>``; ``href`` goes through ``url`` and ``text`` through
  ``esc``; pass ``text_html=`` instead of ``text`` for markup built with these helpers.

Plugin report sections reach them as ``ctx.esc``, ``ctx.attr``, ``ctx.url`` and ``ctx.link`` (or import
them from here); ``tests/report/test_html.py`` checks that a name with ``<``, ``"`` and ``&`` comes out
escaped in a section and in a link.
"""
from __future__ import annotations

import html
from typing import Any
from urllib.parse import quote, urlsplit

#: characters a relative address keeps as they are (path separators, an existing %-escape, a fragment)
_URL_SAFE = "/%#:@!$'()*+,;=~-._"


def esc(x: Any) -> str:
    """``str(x)`` escaped for HTML text and quoted attribute values."""
    return html.escape(str(x), quote=True)


def attr(name: str, value: Any) -> str:
    """`` name="value"``, the value escaped (a space first, so attributes can be joined onto a tag name)."""
    return f' {name}="{esc(value)}"'


def url(target: Any) -> str:
    """An address for ``href``/``src``, escaped for the attribute: a relative path (``img/a b.png``) is
    percent-encoded; an absolute address (``file:///...``, ``https://...``) or an already encoded one
    (from :func:`twinkit.report.run.rel`) keeps its encoding."""
    s = str(target)
    if urlsplit(s).scheme:
        return esc(s)
    path, hash_, frag = s.partition("#")
    return esc(quote(path, safe=_URL_SAFE.replace("#", "")) + (hash_ + quote(frag, safe=_URL_SAFE) if hash_ else ""))


def link(href: Any, text: Any = None, *, text_html: str | None = None, **attrs: Any) -> str:
    """``<a href="...">text</a>``: ``href`` through :func:`url`, ``text`` escaped (or ``text_html`` as it is,
    for markup made with these helpers); ``attrs`` become attributes (``cls=`` gives ``class``)."""
    inner = text_html if text_html is not None else esc(href if text is None else text)
    extra = "".join(attr("class" if k == "cls" else k, v) for k, v in attrs.items())
    return f'<a href="{url(href)}"{extra}>{inner}</a>'

"""Every hook a plugin can implement is documented for plugin authors."""
from __future__ import annotations

import inspect
import re
from pathlib import Path

from twinkit import hookspecs

ROOT = Path(__file__).resolve().parents[1]


def _hookspecs() -> list[str]:
    return [n for n, f in inspect.getmembers(hookspecs, inspect.isfunction)
            if n.startswith("twinkit_") and f.__module__ == hookspecs.__name__]


def test_every_hookspec_is_documented_in_writing_a_plugin():
    doc = (ROOT / "docs" / "writing-a-plugin.md").read_text()
    names = _hookspecs()
    assert len(names) >= 10
    missing = [n for n in names if not re.search(rf"`{n}`", doc)]
    assert not missing, f"docs/writing-a-plugin.md does not document these hooks (by their exact name): {missing}"


def test_documented_hooks_exist():
    doc = (ROOT / "docs" / "writing-a-plugin.md").read_text()
    named = set(re.findall(r"`(twinkit_register_\w+)", doc))
    assert named <= set(_hookspecs()), f"documented but not in twinkit/hookspecs.py: {named - set(_hookspecs())}"


def test_every_hookspec_is_loaded_by_the_registry():
    from twinkit.plugins import KINDS, REPORT_SECTIONS_HOOK

    assert set(_hookspecs()) == set(KINDS.values()) | {REPORT_SECTIONS_HOOK}

"""A plugin's code hash covers every module of its package, so editing a helper re-runs its steps."""
from __future__ import annotations

import importlib
import os
import sys
import time

from twinkit.plugins import Plugin


def test_editing_a_helper_module_changes_the_code_hash(tmp_path, monkeypatch):
    pkg = tmp_path / "hashdemo_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "steps.py").write_text("from .helper import f\n\ndef run(params, ctx):\n    return f()\n")
    (pkg / "helper.py").write_text("def f():\n    return 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    mod = importlib.import_module("hashdemo_pkg.steps")
    try:
        p = Plugin(kind="step", name="hashdemo", run=mod.run, params=None, version="0")
        before = p.code_hash()
        assert before == p.code_hash() and before != "unknown"
        (pkg / "helper.py").write_text("def f():\n    return 2\n")
        later = time.time() + 5  # a new mtime even on a coarse clock
        os.utime(pkg / "helper.py", (later, later))
        assert p.code_hash() != before
        (pkg / "notes.txt").write_text("not code")
        assert p.code_hash() == Plugin(kind="step", name="hashdemo", run=mod.run, params=None, version="0").code_hash()
    finally:
        for name in [n for n in sys.modules if n.startswith("hashdemo_pkg")]:
            del sys.modules[name]


def test_a_plain_module_hashes_its_own_file(tmp_path, monkeypatch):
    (tmp_path / "hashdemo_mod.py").write_text("def run(params, ctx):\n    return 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    mod = importlib.import_module("hashdemo_mod")
    try:
        h = Plugin(kind="step", name="m", run=mod.run, params=None, version="0").code_hash()
        assert len(h) == 16 and h != "unknown"
    finally:
        sys.modules.pop("hashdemo_mod", None)

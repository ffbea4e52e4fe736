"""The import rules of docs/architecture.md, checked on the source tree.

Plugins depend on the core (and third-party libraries), never on each other: a plugin that needs another
plugin's algorithm reaches it through the core's shared library (twinkit.geo, twinkit.mesh, twinkit.surface)
or through the registry. The core imports no plugin. These tests read the files as text, so they also see
imports inside functions, tests and benchmarks.
"""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
IMPORT = re.compile(r"^[ \t]*(?:from|import)[ \t]+(twinkit_\w+)", re.M)


def _packages() -> dict[Path, str]:
    """Each plugin folder (built-in and example) -> the one top-level package it ships."""
    out = {}
    for d in sorted(ROOT.glob("plugins/*/")) + sorted(ROOT.glob("examples/*/")):
        pkgs = [p.name for p in d.glob("twinkit_*") if (p / "__init__.py").exists()]
        assert len(pkgs) == 1, f"{d}: expected one twinkit_* package, found {pkgs}"
        out[d] = pkgs[0]
    return out


def cross_imports(root: Path = ROOT) -> list[str]:
    """Every ``file:line: module`` where a plugin's code, tests or benchmarks import another plugin."""
    bad = []
    for folder, own in _packages().items():
        for f in sorted(folder.rglob("*.py")):
            text = f.read_text(encoding="utf-8", errors="replace")
            for m in IMPORT.finditer(text):
                if m.group(1) != own:
                    line = text.count("\n", 0, m.start()) + 1
                    bad.append(f"{f.relative_to(root)}:{line}: imports {m.group(1)}")
    return bad


def test_no_plugin_imports_another_plugin():
    assert len(_packages()) >= 8, "the plugin folders were not found"
    bad = cross_imports()
    assert not bad, ("plugins must not import each other (move the shared code into twinkit.geo / twinkit.mesh / "
                     "twinkit.surface, or reach it by name through the registry):\n" + "\n".join(bad))


def test_the_core_imports_no_plugin():
    bad = []
    files = sorted((ROOT / "twinkit").rglob("*.py"))
    assert len(files) > 50, "the core's files were not found"
    for f in files:
        text = f.read_text(encoding="utf-8", errors="replace")
        bad += [f"{f.relative_to(ROOT)}: imports {m.group(1)}" for m in IMPORT.finditer(text)]
    assert not bad, "the core must not import plugins:\n" + "\n".join(bad)


def test_the_check_sees_an_import_inside_a_function(tmp_path, monkeypatch):
    """The rule check itself can fail: a lazy import of another plugin in a test file is found."""
    plug = tmp_path / "plugins" / "twinkit-a"
    (plug / "twinkit_a").mkdir(parents=True)
    (plug / "twinkit_a" / "__init__.py").write_text("")
    (plug / "tests").mkdir()
    (plug / "tests" / "test_x.py").write_text("def test():\n    from twinkit_b.meshio import read_ply\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    assert cross_imports(tmp_path) == ["plugins/twinkit-a/tests/test_x.py:2: imports twinkit_b"]


def test_importing_twinkit_and_its_shared_library_stays_light():
    """``import twinkit`` and the shared library's package modules load no heavy library at import time."""
    code = ("import sys, twinkit, twinkit.plugins, twinkit.cityscapes\n"
            "import importlib\n"
            "for m in ('twinkit.geo', 'twinkit.mesh', 'twinkit.street', 'twinkit.surface'):\n"
            "    importlib.import_module(m)\n"
            "heavy = [m for m in ('open3d', 'torch', 'bpy', 'pycolmap', 'pyproj', 'trimesh', 'scipy', 'carla') if m in sys.modules]\n"
            "print(','.join(heavy))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "", f"heavy libraries imported at import time: {out}"

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


def test_the_shared_library_a_plugin_imports_is_in_its_code_hash(tmp_path, monkeypatch):
    """Editing shared core code (mesh I/O, site frame, ...) re-runs the steps of the plugins that import it,
    directly or through another shared module, and no others; framework modules do not count."""
    import twinkit.plugins as plugins

    core = tmp_path / "core"
    (core / "mesh").mkdir(parents=True)
    (core / "mesh" / "__init__.py").write_text("from twinkit.mesh.ply import read\n")
    (core / "mesh" / "ply.py").write_text("def read():\n    from twinkit.geo import frame\n    return frame\n")
    (core / "geo.py").write_text("frame = 1\n")
    (core / "engine.py").write_text("x = 1\n")
    monkeypatch.setattr(plugins, "_CORE", core)
    for name, body in {"user_pkg": "def run(params, ctx):\n    from twinkit.mesh import read\n    return read()\n",
                       "other_pkg": "from twinkit import engine, hookimpl\n\ndef run(params, ctx):\n    return 0\n"}.items():
        (tmp_path / name).mkdir()
        (tmp_path / name / "__init__.py").write_text("")
        (tmp_path / name / "steps.py").write_text(body)
    monkeypatch.syspath_prepend(str(tmp_path))
    user = importlib.import_module("user_pkg.steps")
    other = importlib.import_module("other_pkg.steps")
    try:
        pu = Plugin(kind="step", name="u", run=user.run, params=None, version="0")
        po = Plugin(kind="step", name="o", run=other.run, params=None, version="0")
        used = plugins.shared_sources([tmp_path / "user_pkg" / "steps.py"])
        assert sorted(f.relative_to(core).as_posix() for f in used) == ["geo.py", "mesh/__init__.py", "mesh/ply.py"]
        assert plugins.shared_sources([tmp_path / "other_pkg" / "steps.py"]) == []
        hu, ho = pu.code_hash(), po.code_hash()
        later = time.time() + 5
        (core / "geo.py").write_text("frame = 2\n")  # reached only through mesh/ply.py
        os.utime(core / "geo.py", (later, later))
        assert pu.code_hash() != hu
        assert po.code_hash() == ho  # imports no shared module
        hu = pu.code_hash()
        (core / "engine.py").write_text("x = 2\n")  # framework code is not part of any plugin's hash
        os.utime(core / "engine.py", (later, later))
        assert pu.code_hash() == hu and po.code_hash() == ho
    finally:
        for name in [n for n in sys.modules if n.startswith(("user_pkg", "other_pkg"))]:
            del sys.modules[name]


def test_a_plugins_report_sections_are_not_part_of_its_code_hash(tmp_path, monkeypatch):
    """Editing how a plugin shows its results in the report re-runs none of its steps; editing its steps does."""
    pkg = tmp_path / "hashrep_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "steps.py").write_text("def run(params, ctx):\n    return 1\n")
    (pkg / "report.py").write_text("def section(ctx):\n    return '<p>a</p>'\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    mod = importlib.import_module("hashrep_pkg.steps")
    try:
        p = Plugin(kind="step", name="r", run=mod.run, params=None, version="0")
        before = p.code_hash()
        later = time.time() + 5
        (pkg / "report.py").write_text("def section(ctx):\n    return '<p>b</p>'\n")
        os.utime(pkg / "report.py", (later, later))
        assert p.code_hash() == before
        (pkg / "steps.py").write_text("def run(params, ctx):\n    return 2\n")
        os.utime(pkg / "steps.py", (later, later))
        assert p.code_hash() != before
    finally:
        for name in [n for n in sys.modules if n.startswith("hashrep_pkg")]:
            del sys.modules[name]


LIVE = '''
from pathlib import Path
from twinkit import hookimpl
from .helper import VALUE


def first(params, ctx, *, out_first_txt: Path) -> None:
    """Stands for a person editing the plugin's source while the run goes on."""
    helper = Path(__file__).with_name("helper.py")
    helper.write_text("VALUE = 2\\n")
    import os, time
    later = time.time() + 5
    os.utime(helper, (later, later))
    out_first_txt.write_text("1\\n")


def second(params, ctx, *, in_first_txt: Path, out_second_txt: Path) -> None:
    out_second_txt.write_text(f"{VALUE}\\n")


@hookimpl
def twinkit_register_steps(register):
    register("first", first)
    register("second", second)
'''


def test_a_source_edited_during_a_run_is_not_recorded_as_the_code_that_ran(project):
    """The code hash a step records is the one read when the run started (its modules loaded then): the step
    that ran the old code after the edit re-runs next time instead of being reused as if it ran the new."""
    pkg = project.tmp / "livecode_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "helper.py").write_text("VALUE = 1\n")
    (pkg / "steps.py").write_text(LIVE)
    project.recipe("live", ["{id: first, uses: step/first}", "{id: second, uses: step/second}"])
    env = project.env(TWINKIT_PLUGIN_MODULES="livecode_pkg.steps")
    env["PYTHONPATH"] = f"{project.tmp}{os.pathsep}{env['PYTHONPATH']}"
    r = project.run("site=t", "recipe=live", env=env)
    assert r.rc == 0, r.text
    assert (project.ws / "02_second" / "second.txt").read_text() == "1\n"  # the code loaded at the start ran
    # nothing changed since: the next run loads the edited helper, so 'second' must run again
    r = project.run("site=t", "recipe=live", env=env)
    assert r.rc == 0, r.text
    assert project.status_of(r, "02_second") == "ran", r.text
    assert (project.ws / "02_second" / "second.txt").read_text() == "2\n"


def test_a_model_file_shipped_in_the_package_is_in_the_code_hash(tmp_path, monkeypatch):
    pkg = tmp_path / "hashdata_pkg"
    (pkg / "model").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "steps.py").write_text("def run(params, ctx):\n    return 1\n")
    (pkg / "model" / "weights.json").write_text('{"a": 1}')
    monkeypatch.syspath_prepend(str(tmp_path))
    mod = importlib.import_module("hashdata_pkg.steps")
    try:
        p = Plugin(kind="step", name="hashdata", run=mod.run, params=None, version="0")
        before = p.code_hash()
        (pkg / "model" / "weights.json").write_text('{"a": 2}')  # retrained: the steps that read it re-run
        later = time.time() + 5
        os.utime(pkg / "model" / "weights.json", (later, later))
        after = p.code_hash()
        assert after != before
        (pkg / "README.txt").write_text("notes")  # not a data file the code reads
        assert p.code_hash() == after
    finally:
        for name in [n for n in sys.modules if n.startswith("hashdata_pkg")]:
            del sys.modules[name]

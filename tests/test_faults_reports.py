"""Issue 47, case 4: reports do not pile up. A re-run that changed nothing adds no copy of the 3D view's
model; only the newest ``engine.keep_reports`` runs keep their report (manifests stay); the temporary
report folder of a run killed while writing it is removed by the next run (docs/engine.md "Faults")."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.report.conftest import browser, open_report  # noqa: F401 - the browser fixture

PLUGINS = "tests.support.engine_plugins,tests.support.report_plugins"


def _disk(root: Path) -> int:
    """Bytes on disk under ``root``, each hard-linked file once (as du counts)."""
    seen: set[tuple[int, int]] = set()
    total = 0
    for p in root.rglob("*"):
        st = p.lstat()
        if p.is_file() and not p.is_symlink() and (st.st_dev, st.st_ino) not in seen:
            seen.add((st.st_dev, st.st_ino))
            total += st.st_size
    return total


@pytest.fixture
def glb_project(project):
    project.recipe("glb", ["{id: model, uses: step/make_glb}"])
    project.env_glb = project.env(TWINKIT_PLUGIN_MODULES=PLUGINS)
    return project


def _run(p, *args: str):
    res = p.run("site=t", "recipe=glb", *args, env=p.env_glb)
    assert res.rc == 0, res.text
    return res


def _runs(p) -> list[Path]:
    return sorted((p.ws / "runs").iterdir())


def test_a_no_op_rerun_adds_no_copy_of_the_model(glb_project):
    p = glb_project
    _run(p)
    glb = (p.ws / "01_model" / "twin.glb").stat().st_size
    first = _disk(p.ws / "runs") + _disk(p.ws / ".cache" / "report")
    for _ in range(2):
        _run(p)
    # the site's runs and the report cache together, each hard link counted once
    added = _disk(p.ws / "runs") + _disk(p.ws / ".cache" / "report") - first
    assert added < 0.05 * glb, f"two no-op re-runs added {added} bytes (the model is {glb} bytes)"
    for run in _runs(p):
        viewer = run / "report" / "viewer"
        assert not (viewer / "model.glb").exists()  # one file holds the model: the script the page loads
        assert (viewer / "model.glb.js").is_file()
    from twinkit.report.viewer import read_glb_js

    assert read_glb_js(_runs(p)[-1] / "report" / "viewer" / "model.glb.js") == \
        (p.ws / "01_model" / "twin.glb").read_bytes()


def test_older_reports_are_collected_and_manifests_kept(glb_project):
    p = glb_project
    for seed in (0, 1, 2, 3, 0):  # four different models, the last run as the first
        _run(p, f"steps.make_glb.seed={seed}")
    runs = _runs(p)
    assert len(runs) == 5 and all((r / "manifest.json").is_file() for r in runs)
    with_report = [r for r in runs if (r / "report").exists()]
    assert with_report == runs[-3:], "by default the newest 3 runs keep their report"
    # the models of the collected reports left the cache with them
    assert len(list((p.ws / ".cache" / "report").glob("model-*.glb.js"))) <= 3 + 2  # grace: used this hour
    res = p.run("gc", "site=t", "recipe=glb", "engine.keep_reports=1", env=p.env_glb)
    assert res.rc == 0, res.text
    assert "removed 2 older run report(s)" in res.out
    assert [r for r in _runs(p) if (r / "report").exists()] == runs[-1:]
    assert all((r / "manifest.json").is_file() for r in _runs(p))
    res = p.run("verify", str(runs[0]), env=p.env_glb)
    assert res.rc == 0, res.text  # the provenance of a run whose report was collected still checks
    assert not (runs[0] / "report").exists()


def test_keep_reports_zero_keeps_every_report(glb_project):
    p = glb_project
    for _ in range(4):
        _run(p, "engine.keep_reports=0")
    assert all((r / "report" / "report.html").is_file() for r in _runs(p))


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_a_killed_reports_temporary_folder_is_removed_by_the_next_run(glb_project):
    p = glb_project
    _run(p)
    old = _runs(p)[0]
    dead = old / f".report.tmp-{_dead_pid()}"
    (dead / "viewer").mkdir(parents=True)
    (dead / "viewer" / "model.glb").write_bytes(b"\0" * 100_000)
    stale_old = old / f".report.old-{_dead_pid()}"
    stale_old.mkdir()
    alive = old / f".report.tmp-{os.getpid()}"  # a report being written right now (this process lives)
    alive.mkdir()
    _run(p)
    assert not dead.exists() and not stale_old.exists()
    assert alive.is_dir()
    assert (old / "report" / "report.html").is_file() and (old / "manifest.json").is_file()


def test_the_report_offers_the_model_for_download_from_file_url(glb_project, browser):  # noqa: F811
    p = glb_project
    _run(p, "steps.make_glb.faces=2000")
    page = _runs(p)[-1] / "report" / "report.html"
    st = open_report(browser, page)
    assert st.get("ready") and not st.get("error"), st
    got = browser.execute_async_script(
        "var done = arguments[0], a = document.getElementById('viewer-download');"
        "fetch(a.href).then(r => r.arrayBuffer()).then(b => done([a.download, b.byteLength,"
        " String.fromCharCode.apply(null, new Uint8Array(b.slice(0, 4)))])).catch(e => done(String(e)));")
    assert got == ["model.glb", (p.ws / "01_model" / "twin.glb").stat().st_size, "glTF"], got


def test_a_steps_picture_is_on_disk_once_however_many_reports_show_it(tmp_path):
    from twinkit.report.context import SectionContext
    from twinkit.report.render import TopDown
    from twinkit.report.run import RunView

    ws = tmp_path / "site"
    (ws / "01_step").mkdir(parents=True)
    pic = ws / "01_step" / "qa.png"
    pic.write_bytes(b"\x89PNG" + bytes(range(256)) * 400)
    names = []
    for run in ("r1", "r2"):
        view = RunView(ws / "runs" / run, {"steps": [], "workspace": str(ws)}, None)
        out = ws / "runs" / run / "report"
        ctx = SectionContext(view, out, TopDown(view, out))
        names.append(out / ctx.add_image(pic))
    a, b = names
    assert a.read_bytes() == b.read_bytes() == pic.read_bytes()
    assert a.stat().st_ino == b.stat().st_ino != pic.stat().st_ino  # one copy, never the step folder's file
    pic.write_bytes(b"edited")  # an edit in the step folder leaves the reports as they were
    assert a.read_bytes() != b"edited"

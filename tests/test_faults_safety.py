"""Issue 47, leaked or unsafe (cases 10-12): secrets read through ``${oc.env:...}`` stay out of every file and
line twinkit writes, marker files are never written through a link, and the code opt-in is recorded.

The errors of these cases (site.name, command-line Hydra code) are rows of docs/engine.md's Bad input table
(tests/test_bad_input.py); these are the Faults rows.
"""
from __future__ import annotations

import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest

from tests.conftest import ROOT

TOKEN = "tok-9f3c1e7a55d2"
OSM = (ROOT / "plugins" / "twinkit-roads" / "tests" / "fixtures" / "tiny_roads.osm").read_bytes()
GEO = "crs: EPSG:3067\nbase_point: {lat: 60.16945, lon: 24.93365, alt: 0}\n"


@pytest.fixture
def server():
    """An Overpass stand-in on 127.0.0.1: the fixture OSM for any path, 404 under /missing."""
    class Handler(BaseHTTPRequestHandler):
        def log_message(self, *a):
            pass

        def do_POST(self):
            self.rfile.read(int(self.headers.get("Content-Length", 0)))
            code, body = (404, b"not here") if self.path.startswith("/missing") else (200, OSM)
            self.send_response(code)
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

    httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{httpd.server_address[1]}"
    httpd.shutdown()


def _files_with(root: Path, text: str) -> list[str]:
    return [str(p) for p in root.rglob("*") if p.is_file() and not p.is_symlink()
            and text.encode() in p.read_bytes()]


def test_a_token_in_the_server_url_never_reaches_a_file_or_the_terminal(project, server):
    """A token read with ${oc.env:VAR} in road_source.url: was in step.json's metrics, the store's record, run.log,
    the terminal and the HTTP cache's record; now ``<from env VAR>`` everywhere, a failure's line included."""
    cache = project.tmp / "httpcache"
    project.site("o", f"name: t\n{GEO}")
    project.recipe("osm", ["{id: fetch_roads, uses: road_source}"],
                   extra="defaults:\n  - /road_source: overpass\n  - _self_\n"
                         f"road_source:\n  url: {server}/api/interpreter?key=${{oc.env:TWINKIT_TEST_TOKEN}}\n"
                         f"  cache_dir: {cache}\n  retries: 0\n")
    env = project.env(TWINKIT_PLUGINS="builtins,roads", TWINKIT_TEST_TOKEN=TOKEN)
    r = project.run("site=o", "recipe=osm", env=env)
    assert r.rc == 0, r.text
    assert TOKEN not in r.text
    assert _files_with(project.out, TOKEN) == [] and _files_with(cache, TOKEN) == []
    hidden = "<from env TWINKIT_TEST_TOKEN>"
    rec = json.loads(next(project.ws.glob("0*_fetch_roads/step.json")).read_text())
    assert rec["metrics"]["url"].endswith(f"?key={hidden}")  # still says which server, without the token
    assert hidden in next(project.ws.glob("runs/*/run.log")).read_text()
    meta = json.loads(next(cache.glob("*.json")).read_text())
    assert meta["url"].endswith(f"?key={hidden}")
    # a failure names the server in its one line, the manifest and run.log: the token is not in any
    (project.conf / "recipe" / "osm.yaml").write_text(
        (project.conf / "recipe" / "osm.yaml").read_text().replace("/api/interpreter", "/missing"))
    s = project.run("status", "site=o", "recipe=osm", env=env)  # its reason names the changed URL
    assert s.rc == 0 and hidden in s.out and TOKEN not in s.text, s.text
    r = project.run("site=o", "recipe=osm", env=env)
    assert r.rc == 2 and "refused the request" in r.err and hidden in r.err, r.text
    assert TOKEN not in r.text, r.text
    assert _files_with(project.out, TOKEN) == []


@pytest.mark.parametrize("marker", [".twinkit.owner", ".twinkit.recipe", ".twinkit.lock"])
def test_a_linked_marker_is_replaced_not_followed(project, marker):
    """A symbolic link planted as a marker of the site folder: the run wrote the link's target (a linked lock
    file stopped the run: "Too many levels of symbolic links"); now the link itself is replaced and the target
    is left as it was."""
    victim = project.tmp / "victim.txt"
    victim.write_text("precious\n")
    project.ws.mkdir(parents=True)
    (project.ws / marker).symlink_to(victim)
    r = project.run("site=t", "recipe=chain")
    assert r.rc == 0, r.text
    assert victim.read_text() == "precious\n"
    assert not (project.ws / marker).is_symlink()


def test_the_code_opt_in_runs_a_command_line_callback_and_is_recorded(project):
    """TWINKIT_ALLOW_CODE=1: a command-line callback is accepted (refused without it: Bad input ``cli-callbacks``),
    and each manifest records the opt-in; a run without it records false. The launcher's settings stay allowed."""
    r = project.run("-m", "site=t", "recipe=chain", "steps.make.value=1,2", "hydra.launcher.n_jobs=1",
                    "+hydra.callbacks.x._target_=twinkit.report.SweepSummaryCallback",
                    env=project.env(TWINKIT_ALLOW_CODE="1"))
    assert r.rc == 0, r.text
    manifests = [json.loads(m.read_text()) for m in project.ws.glob("sweeps/*/job*/runs/*/manifest.json")] or \
        [json.loads(m.read_text()) for m in project.ws.glob("sweeps/*/job*/manifest.json")]
    assert len(manifests) == 2 and all(m["code_allowed"] is True for m in manifests)
    r = project.run("site=t", "recipe=chain", "hydra.job.chdir=false")
    assert r.rc == 0, r.text
    m = json.loads(next(project.ws.glob("runs/*/manifest.json")).read_text())
    assert m["code_allowed"] is False


@pytest.mark.parametrize("override,refused", [
    ("hydra.launcher.n_jobs=2", None), ("hydra.sweep.dir=/tmp/s", None), ("hydra.run.dir=/tmp/r", None),
    ("hydra.job.chdir=false", None), ("hydra.sweeper.params.a=1,2", None),
    ("engine.outputs_dir=/tmp/test_target_faces_0/out", None), ("site.name=_target_", None),
    ("+hydra.callbacks.x._target_=os.system", "_target_"), ("+site.h={'_target_': os.getcwd}", "_target_"),
    ("hydra/launcher=basic", "hydra/launcher"), ("~hydra/callbacks", "hydra/callbacks"),
    ("hydra.launcher={n_jobs: 2}", "'hydra.launcher'"), ("hydra.searchpath=[file:///x]", "hydra.searchpath"),
    ("hydra.job_logging.root.level=INFO", "hydra.job_logging"),
])
def test_what_a_command_line_may_set_under_hydra(override, refused):
    """The project's own uses (docs, tests: n_jobs, sweep and run folders, chdir, sweep params) stay allowed."""
    from twinkit.config import override_problem

    why = override_problem(override)
    assert (why is None) if refused is None else (why is not None and refused in why), why

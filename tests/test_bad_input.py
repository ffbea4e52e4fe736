"""The bad-input table of docs/engine.md, run row by row through the real command.

Each row of the table (case, what is given, exit code, message) is one case here: the test reads the
table, so the documentation and the behaviour cannot drift apart. Rows whose "given" column names a
test elsewhere (``tests/test_cli.py::...``) are covered there; this test checks that that test exists.
Every case must fail with the documented exit code and one line on stderr containing the message; a
configuration case must fail before any step runs, an input case must still write the run's manifest.
"""
from __future__ import annotations

import json
import os
import random
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.conftest import ROOT, CliResult, Project

DOC = ROOT / "docs" / "engine.md"


def _table() -> list[tuple[str, str, int, str]]:
    text = DOC.read_text()
    section = text.split("## Bad input", 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in section.splitlines():
        m = re.match(r"^\|\s*`([\w-]+)`\s*\|(.*)\|\s*(\d+)\s*\|(.*)\|\s*$", line)
        if m:
            msg = m.group(4).strip()
            msg = msg[1:-1] if msg.startswith("`") and msg.endswith("`") else msg
            rows.append((m.group(1), m.group(2).strip(), int(m.group(3)), msg.replace("\\|", "|")))
    return rows


ROWS = _table()

MESH = ["{id: make, uses: step/make}", "{id: read_cloud, uses: step/read_cloud}",
        "{id: reconstruct, uses: reconstructor}", "{id: clean, uses: step/clean_mesh}",
        "{id: simplify, uses: step/simplify}"]
POISSON = "defaults:\n  - /reconstructor: poisson\n  - _self_\n"
GEO = "crs: EPSG:3067\nbase_point: {lat: 60.16945, lon: 24.93365, alt: 0}\n"


def _ply(path: Path, pts, normals=None) -> Path:
    head = ["ply", "format ascii 1.0", f"element vertex {len(pts)}", "property float x", "property float y",
            "property float z"] + (["property float nx", "property float ny", "property float nz"] if normals else [])
    rows = [" ".join(str(v) for v in (*p, *(normals[i] if normals else ()))) for i, p in enumerate(pts)]
    path.write_text("\n".join(head + ["end_header"] + rows) + "\n")
    return path


def _cloud_case(p: Project, make) -> list[str]:
    """A site with a georeference and the cloud ``make(tmp)`` returns; the mesh recipe."""
    p.site("c", f"name: t\n{GEO}")
    p.recipe("mesh", MESH[1:4], extra=POISSON)
    return ["site=c", "recipe=mesh", f"site.inputs.cloud={make(p.tmp)}", "reconstructor.depth=8"]


def _param(*extra: str):
    def setup(p: Project) -> list[str]:
        p.site("c", f"name: t\n{GEO}")
        p.recipe("mesh", MESH, extra=POISSON)
        return ["site=c", "recipe=mesh", *extra]
    return setup


def _site(body: str):
    def setup(p: Project) -> list[str]:
        p.site("g", f"name: t\ncrs: EPSG:3067\n{body}\n")
        return ["site=g", "recipe=chain"]
    return setup


def _recipe_params(p: Project) -> list[str]:
    p.site("c", f"name: t\n{GEO}\ninputs: {{cloud: {p.tmp / 'x.ply'}}}\n")
    _ply(p.tmp / "x.ply", [(0, 0, 0)] * 3)
    p.recipe("meshp", [MESH[0], MESH[1], "{id: reconstruct, uses: reconstructor, params: {depth: 30}}"], extra=POISSON)
    return ["site=c", "recipe=meshp"]


def _callbacks(multirun: bool):
    def setup(p: Project) -> list[str]:
        marker = p.tmp / "callback-ran"
        p.recipe("evil", ["{id: make, uses: step/make}"],
                 extra=f"hydra:\n  callbacks:\n    x:\n      _target_: subprocess.call\n"
                       f"      _args_: [[touch, {marker}]]\n")
        return (["-m"] if multirun else []) + ["site=t", "recipe=evil"] + (["steps.make.value=1,2"] if multirun else [])
    return setup


def _site_target(p: Project) -> list[str]:
    p.site("e", "name: t\nhook: {_target_: os.getcwd}\n")
    return ["site=e", "recipe=chain"]


def _local_launcher(p: Project) -> list[str]:
    (p.conf / "local").mkdir(exist_ok=True)
    (p.conf / "local" / "t.yaml").write_text("# @package _global_\ndefaults:\n  - override /hydra/launcher: basic\n")
    return ["site=t", "recipe=chain"]


def _all_nan(tmp: Path) -> Path:
    return _ply(tmp / "allnan.ply", [(float("nan"),) * 3] * 50)


def _folder(tmp: Path) -> Path:
    (tmp / "scans").mkdir()
    _ply(tmp / "scans" / "a.ply", [(0, 0, 0)] * 20)
    return tmp / "scans"


def _broken_link(tmp: Path) -> Path:
    (tmp / "cloud.ply").symlink_to(tmp / "moved-away.ply")
    return tmp / "cloud.ply"


def _sparse(tmp: Path) -> Path:
    rnd = random.Random(1)
    return _ply(tmp / "ten.ply", [(rnd.uniform(0, 20), rnd.uniform(0, 20), rnd.uniform(0, 3)) for _ in range(10)],
                [(0, 0, 1)] * 10)


def _small(tmp: Path) -> Path:
    rnd = random.Random(2)
    return _ply(tmp / "pump.ply", [(rnd.uniform(0, 4), rnd.uniform(0, 4), rnd.uniform(0, 3)) for _ in range(500)],
                [(0, 0, 1)] * 500)


def _write(name: str, data: bytes):
    def make(tmp: Path) -> Path:
        (tmp / name).write_bytes(data)
        return tmp / name
    return make


def _unreadable(p: Project) -> list[str]:
    """A cloud without read permission (tests that run as root drop the capability to read it anyway)."""
    cloud = _ply(p.tmp / "locked.ply", [(i, i % 3, 0) for i in range(30)])
    cloud.chmod(0)
    return _cloud_case(p, lambda t: cloud)


def _as_user(argv: list[str]) -> list[str]:
    """Run without root's power to read any file, so that a mode-000 file is really unreadable."""
    if os.geteuid() != 0:
        return argv
    if not shutil.which("setpriv"):
        pytest.skip("running as root without setpriv: cannot make a file unreadable")
    caps = "-dac_override,-dac_read_search"
    return ["setpriv", f"--inh-caps={caps}", f"--bounding-set={caps}", *argv]


def _bad_osm(p: Project) -> list[str]:
    p.site("o", f"name: t\n{GEO}")
    p.recipe("osm", ["{id: fetch_roads, uses: road_source}"], extra="defaults:\n  - /road_source: file\n  - _self_\n")
    (p.tmp / "area.osm").write_text("<osm version='0.6'><node id='1' lat='60.1' lon=\n")
    return ["site=o", "recipe=osm", f"site.inputs.osm={p.tmp / 'area.osm'}"]


def _env_unset(command: str = "", key: str = "${oc.env:TWINKIT_TEST_UNSET_VAR}"):
    """A site file reading an environment variable that is not set (or a missing key), through ``command``."""
    def setup(p: Project) -> list[str]:
        p.site("e", f"name: t\ntoken: {key}\n")
        return ([command] if command else []) + ["site=e", "recipe=chain"]
    return setup


def _config_path(p: Project) -> list[str]:
    """``--config-path`` to a copy of the config folder whose root config adds a callback (what a shared folder
    could hold)."""
    other = p.tmp / "other"
    shutil.copytree(p.conf, other)
    with (other / "config.yaml").open("a") as f:
        f.write(f"    x:\n      _target_: subprocess.call\n      _args_: [[touch, {p.tmp / 'callback-ran'}]]\n")
    return ["--config-path", str(other), "site=t", "recipe=chain"]


def _cli(*extra: str):
    def setup(p: Project) -> list[str]:
        return [a.replace("MARKER", str(p.tmp / "callback-ran")) for a in extra]
    return setup


def _rerun_pickle(p: Project) -> list[str]:
    """``--experimental-rerun`` with a pickle that runs a command when loaded (Hydra unpickles it)."""
    import pickle

    class Touch:
        def __reduce__(self):
            return subprocess.call, (["touch", str(p.tmp / "callback-ran")],)

    (p.tmp / "config.pickle").write_bytes(pickle.dumps(Touch()))
    return ["--experimental-rerun", str(p.tmp / "config.pickle")]


def _site_name(name: str):
    def setup(p: Project) -> list[str]:
        p.site("n", f"name: {name.replace('TMP', str(p.tmp))}\n")
        return ["site=n", "recipe=chain"]
    return setup


def _street(tmp: Path, name: str, n: int = 400, z=None) -> Path:
    """A 30 x 12 m street-sized ASCII PLY of ``n`` points (``z``: every height, or random 0..3 m)."""
    rnd = random.Random(3)
    pts = [(rnd.uniform(0, 30), rnd.uniform(0, 12), rnd.uniform(0, 3) if z is None else z) for _ in range(n)]
    return _ply(tmp / name, pts, [(0, 0, 1)] * n)


def _undercounted(tmp: Path) -> Path:
    """A PLY whose header declares 50 vertices; the file holds 400 (was read in part, exit 0)."""
    path = _street(tmp, "part.ply")
    path.write_text(path.read_text().replace("element vertex 400", "element vertex 50"))
    return path


def _empty_las(tmp: Path) -> Path:
    import laspy
    from pyproj import CRS

    h = laspy.LasHeader(point_format=3, version="1.2")
    h.add_crs(CRS("EPSG:3067"))
    h.offsets, h.scales = [385000.0, 6672000.0, 0.0], [0.01, 0.01, 0.01]
    laspy.LasData(h).write(str(tmp / "empty.las"))
    return tmp / "empty.las"


def _geographic_site(p: Project) -> list[str]:
    """site.crs EPSG:4326 and a cloud whose x, y are degrees (was "not a street", the street being 0.0003 m)."""
    p.site("c", "name: t\ncrs: EPSG:4326\nbase_point: {lat: 60.16945, lon: 24.93365, alt: 0}\n")
    p.recipe("mesh", MESH[1:4], extra=POISSON)
    rnd = random.Random(4)
    pts = [(24.93365 + rnd.uniform(0, 5e-4), 60.16945 + rnd.uniform(0, 2e-4), rnd.uniform(0, 3)) for _ in range(300)]
    return ["site=c", "recipe=mesh", f"site.inputs.cloud={_ply(p.tmp / 'deg.ply', pts)}"]


def _unknown_crs(p: Project) -> list[str]:
    """A CRS code that does not exist (failed in the first step that used it, exit 1)."""
    p.site("g", "name: t\ncrs: EPSG:99999\nbase_point: {lat: 60.16945, lon: 24.93365, alt: 0}\n")
    return ["site=g", "recipe=chain"]


def _no_georeference(site: str):
    """A cloud in a local frame on a site without ``site.crs`` / ``site.base_point`` and the default roads (no
    OSM: from the scan), which need a georeference (ran 11 steps, then "site has no georeference")."""
    def setup(p: Project) -> list[str]:
        p.site("n", f"name: t\n{site}")
        p.recipe("roads", MESH[1:] + ["{id: texture, uses: step/bake_texture}", "{id: fetch_roads, uses: road_source}"],
                 extra="defaults:\n  - /reconstructor: poisson\n  - /road_source: file\n  - _self_\n")
        return ["site=n", "recipe=roads", f"site.inputs.cloud={_street(p.tmp, 'street.ply')}"]
    return setup


SETUPS = {
    "depth-30": _param("reconstructor.depth=30"),
    "depth-0": _param("reconstructor.depth=0"),
    "depth-negative": _param("reconstructor.depth=-3"),
    "target-faces-negative": _param("steps.simplify.target_faces=-5"),
    "target-faces-0": _param("steps.simplify.target_faces=0"),
    "max-dist-negative": _param("steps.clean_mesh.max_dist_m=-2"),  # -1 = auto
    "backend-unknown": _param("reconstructor.backend=meshroom"),
    "recipe-param-out-of-range": _recipe_params,
    "lat-not-a-number": _site("base_point: {lat: abc, lon: 24.9, alt: 0}"),
    "lat-out-of-range": _site("base_point: {lat: 95.0, lon: 24.9, alt: 0}"),
    "base-point-outside-crs-area": _site("base_point: {lat: 19.4326, lon: -99.1332, alt: 2240}"),
    "recipe-callbacks": _callbacks(False),
    "recipe-callbacks-multirun": _callbacks(True),
    "site-target": _site_target,
    "local-launcher": _local_launcher,
    "cloud-missing": lambda p: _cloud_case(p, lambda t: t / "nope.ply"),
    "cloud-broken-link": lambda p: _cloud_case(p, _broken_link),
    "cloud-folder": lambda p: _cloud_case(p, _folder),
    "cloud-unreadable": _unreadable,
    "cloud-empty-file": lambda p: _cloud_case(p, _write("zero.ply", b"")),
    "cloud-corrupt-ply": lambda p: _cloud_case(p, _write("bad.ply", b"ply\nformat ascii 1.0\nelement vertex 9\n")),
    "cloud-corrupt-e57": lambda p: _cloud_case(p, _write("bad.e57", b"not an e57 file at all" * 100)),
    "cloud-all-nan": lambda p: _cloud_case(p, _all_nan),
    "cloud-too-few-points": lambda p: _cloud_case(p, lambda t: _ply(t / "five.ply", [(i, 0, 0) for i in range(5)])),
    "cloud-too-sparse": lambda p: _cloud_case(p, _sparse),
    "cloud-not-a-street": lambda p: _cloud_case(p, _small),
    "osm-corrupt": _bad_osm,
    "cloud-more-points-than-declared": lambda p: _cloud_case(p, _undercounted),
    "cloud-flat": lambda p: _cloud_case(p, lambda t: _street(t, "plan.ply", z=0.0)),
    "cloud-empty-las": lambda p: _cloud_case(p, _empty_las),
    "site-crs-geographic": _geographic_site,
    "site-crs-unknown": _unknown_crs,
    "site-no-georeference-roads": _no_georeference(""),
    "site-no-crs-suggests-its-utm-zone": _no_georeference("base_point: {lat: 1.2903, lon: 103.8519, alt: 10}\n"),
    "env-unset": _env_unset(),
    "status-env-unset": _env_unset("status"),
    "gc-env-unset": _env_unset("gc"),
    "status-interpolation-missing": _env_unset("status", "${site.nope}"),
    "config-path-callbacks": _config_path,
    "cli-callbacks": _cli("site=t", "recipe=chain", "+hydra.callbacks.x._target_=subprocess.call",
                          "+hydra.callbacks.x._args_=[[touch,MARKER]]"),
    "cli-callbacks-multirun": _cli("-m", "site=t", "recipe=chain", "steps.make.value=1,2",
                                   "+hydra.callbacks.x._target_=subprocess.call",
                                   "+hydra.callbacks.x._args_=[[touch,MARKER]]"),
    "cli-launcher": _cli("-m", "site=t", "recipe=chain", "steps.make.value=1,2", "hydra/launcher=basic"),
    "cli-target": _cli("site=t", "recipe=chain", "+site.hook={_target_: os.getcwd}"),
    "cli-env-set": _cli("site=t", "recipe=chain", "hydra.job.env_set.LD_PRELOAD=/tmp/x.so"),
    "site-name-parent": _site_name("../escaped"),
    "site-name-absolute": _site_name("TMP/elsewhere"),
    "site-name-from-env": _site_name("${oc.env:TWINKIT_CONFIG_DIR}"),
    "cli-experimental-rerun": _rerun_pickle,
    "env-value-in-error": _cli("site=t", "recipe=chain", "steps.make.value=${oc.env:TWINKIT_CONFIG_DIR}"),
}

CONFIG_CASES = {"depth-30", "depth-0", "depth-negative", "target-faces-negative", "target-faces-0", "max-dist-negative",
                "backend-unknown", "recipe-param-out-of-range", "lat-not-a-number", "lat-out-of-range",
                "base-point-outside-crs-area", "site-crs-unknown", "site-no-georeference-roads",
                "site-no-crs-suggests-its-utm-zone",
                "recipe-callbacks", "recipe-callbacks-multirun", "site-target", "local-launcher",
                "env-unset", "status-env-unset", "gc-env-unset", "status-interpolation-missing", "config-path-callbacks",
                "cli-callbacks", "cli-callbacks-multirun", "cli-launcher", "cli-target", "cli-env-set",
                "site-name-parent", "site-name-absolute", "site-name-from-env", "env-value-in-error",
                "cli-experimental-rerun"}


def test_the_table_and_the_cases_match():
    ids = [r[0] for r in ROWS]
    assert len(ids) == len(set(ids)), "a case is listed twice in docs/engine.md"
    here = {i for i, given, _, _ in ROWS if "::" not in given}
    assert here == set(SETUPS), f"docs/engine.md rows without a case here: {here - set(SETUPS)}; " \
                                f"cases not in the table: {set(SETUPS) - here}"
    for case, given, _, _ in ROWS:
        if "::" in given:
            path, name = re.search(r"([\w/.-]+\.py)::(\w+)", given).groups()
            assert f"def {name}(" in (ROOT / path).read_text(), f"{case}: {given} does not exist"


@pytest.mark.parametrize("case,exit_code,message", [(r[0], r[2], r[3]) for r in ROWS if r[0] in SETUPS],
                         ids=[r[0] for r in ROWS if r[0] in SETUPS])
def test_bad_input(project, case, exit_code, message):
    env = project.env(TWINKIT_PLUGINS="builtins,pointcloud,roads")
    argv = SETUPS[case](project)
    if case == "cloud-unreadable":
        cmd = _as_user(project.cmd(*argv, f"engine.outputs_dir={project.out}"))
        p = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=project.tmp, timeout=120)
        r = CliResult(p.returncode, p.stdout, p.stderr)
    else:
        r = project.run(*argv, env=env)
    err = r.err.strip()
    assert r.rc == exit_code, f"{case}: exit {r.rc}\n{r.text[-3000:]}"
    errors = [ln for ln in err.splitlines() if "error" in ln.lower() or "Traceback" in ln]
    assert len(errors) == 1 and errors[0].startswith("twinkit: error: "), f"{case}: not one error line:\n{err}"
    assert message in errors[0], f"{case}: expected {message!r} in\n{errors[0]}"
    assert "Traceback" not in r.text and "Debug info" not in r.text
    if case in CONFIG_CASES:
        assert not project.counts(), f"{case}: a step ran"
        assert not list(project.out.glob("t/0*")) and not list(project.out.glob("t/runs/*/manifest.json"))
        assert not (project.tmp / "callback-ran").exists(), "the recipe's callback ran"
    else:
        manifests = list(project.out.glob("t/runs/*/manifest.json"))
        assert len(manifests) == 1, f"{case}: no manifest"
        m = json.loads(manifests[0].read_text())
        assert m["status"] == "failed" and message in m["error"]


def _faults() -> list[tuple[str, str]]:
    """(case, test reference) of each row of docs/engine.md's 'Faults' table."""
    section = DOC.read_text().split("## Faults", 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in section.splitlines():
        m = re.match(r"^\|\s*`([\w-]+)`\s*\|.*\|\s*`?([\w/.-]+\.py::\w+)`?\s*\|\s*$", line)
        if m:
            rows.append((m.group(1), m.group(2)))
        elif re.match(r"^\|\s*`", line):
            raise AssertionError(f"docs/engine.md Faults row without a test reference in its last column: {line}")
    return rows


def test_the_faults_table_names_real_tests():
    rows = _faults()
    ids = [case for case, _ in rows]
    assert len(ids) == len(set(ids)), "a fault is listed twice in docs/engine.md"
    assert not set(ids) & {r[0] for r in ROWS}, "a case is both a bad input and a fault"
    for case, ref in rows:
        path, name = ref.split("::")
        assert (ROOT / path).exists() and f"def {name}(" in (ROOT / path).read_text(), f"{case}: {ref} does not exist"

"""Faults of issue 47 that the readers handle (docs/engine.md, "Faults"): non-ASCII file names, duplicate points,
far outliers, a short numpy write on a full disk, byte-identical photos. Each runs the real command where the
behaviour is the command's (a tiny site, the one step read_cloud)."""
from __future__ import annotations

import json
import logging
import resource
import signal
import subprocess
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import CliResult, Project

GEO = "crs: EPSG:3067\nbase_point: {lat: 60.16945, lon: 24.93365, alt: 0}\n"
READ = ["{id: read_cloud, uses: step/read_cloud}"]
PLUGINS = "builtins,pointcloud"


def _street(n: int = 3000, seed: int = 0) -> np.ndarray:
    """(n, 3) points of a 30 x 12 x 3 m street-sized box, site-frame metres."""
    rng = np.random.default_rng(seed)
    return np.c_[rng.uniform(0, 30, n), rng.uniform(0, 12, n), rng.uniform(0, 3, n)]


def _run(p: Project, cloud: Path | None, *extra: str, on_command_line: bool = False, **popen) -> CliResult:
    """read_cloud on ``cloud`` (named in the site file, or on the command line)."""
    inputs = "" if cloud is None or on_command_line else f"inputs: {{cloud: '{cloud}'}}\n"
    p.site("c", f"name: t\n{GEO}{inputs}")
    p.recipe("read", READ)
    argv = ["site=c", "recipe=read", *([f"site.inputs.cloud={cloud}"] if on_command_line else []), *extra]
    if not popen:
        return p.run(*argv, env=p.env(TWINKIT_PLUGINS=PLUGINS))
    r = subprocess.run(p.cmd(*argv, f"engine.outputs_dir={p.out}"), capture_output=True, text=True,
                       env=p.env(TWINKIT_PLUGINS=PLUGINS), cwd=p.tmp, timeout=120, **popen)
    return CliResult(r.returncode, r.stdout, r.stderr)


def _metrics(p: Project) -> dict:
    m = json.loads(sorted(p.out.glob("t/runs/*/manifest.json"))[-1].read_text())
    return next(s for s in m["steps"] if s["id"] == "read_cloud")["metrics"]


def _ply(path: Path, xyz: np.ndarray) -> Path:
    from twinkit.mesh import Mesh, write_ply

    write_ply(path, Mesh(xyz), xyz_dtype="f8")
    return path


def _las(path: Path, xyz: np.ndarray) -> Path:
    import laspy
    from pyproj import CRS

    h = laspy.LasHeader(point_format=3, version="1.2")
    h.add_crs(CRS("EPSG:3067"))
    h.offsets, h.scales = np.floor(np.median(xyz, axis=0)), [0.01, 0.01, 0.01]
    las = laspy.LasData(h)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.write(str(path))
    return path


def _e57(path: Path, xyz: np.ndarray) -> Path:
    import pye57

    e = pye57.E57(str(path), mode="w")
    e.write_scan_raw({"cartesianX": xyz[:, 0], "cartesianY": xyz[:, 1], "cartesianZ": xyz[:, 2]},
                     rotation=np.array([1.0, 0, 0, 0]), translation=np.zeros(3))
    e.close()
    return path


@pytest.mark.parametrize("name,write,on_command_line", [
    ("straße.ply", _ply, False), ("№1.ply", _ply, True), ("café №2.las", _las, True), ("größe.e57", _e57, False)])
def test_non_ascii_cloud_names_just_work(project, name, write, on_command_line):
    """A cloud named ``straße.ply`` failed read_cloud with a UnicodeEncodeError traceback (the source file's name
    went into the points PLY's ASCII header); on the command line Hydra's grammar refused the name unquoted."""
    xyz = _street()
    if write is _las:  # in EPSG:3067 around the base point
        from pyproj import Transformer

        e, n = Transformer.from_crs("EPSG:4326", "EPSG:3067", always_xy=True).transform(24.93365, 60.16945)
        xyz = xyz + [e, n, 0.0]
    r = _run(project, write(project.tmp / name, xyz), on_command_line=on_command_line)
    assert r.rc == 0, r.text[-2000:]
    assert "Traceback" not in r.text and "UnicodeEncodeError" not in r.text
    assert _metrics(project)["points"] == len(xyz)
    from twinkit.mesh import read_ply

    assert read_ply(next(project.out.glob("t/01_read_cloud/points.ply"))).n_vertices == len(xyz)


def test_duplicate_points_are_removed_and_the_spacing_measured_without_them(project):
    """A cloud stored three times over (a tripled aerial scan) measured a spacing of 0 m, which set every
    density-based default wrong; the duplicates are removed, logged and counted, the spacing is the single
    cloud's."""
    from twinkit.surface import density

    xyz = _street()
    r = _run(project, _ply(project.tmp / "tripled.ply", np.vstack([xyz, xyz, xyz])))
    assert r.rc == 0, r.text[-2000:]
    m = _metrics(project)
    assert m["duplicates_removed"] == 2 * len(xyz) and m["points"] == len(xyz)
    assert m["spacing_m"] == pytest.approx(density.measure(xyz)["spacing_m"], rel=1e-3) and m["spacing_m"] > 0.1
    assert "removed 6000 duplicate points of 9000" in r.text


def test_a_few_far_outliers_do_not_refuse_the_cloud(project):
    """Three junk points near 0, 0, 0 of a LAS in EPSG:3067 (the cloud 6,700 km away from them) got the whole
    cloud refused as in the wrong CRS, before the first step; now they are dropped, said how many and where."""
    from pyproj import Transformer

    e, n = Transformer.from_crs("EPSG:4326", "EPSG:3067", always_xy=True).transform(24.93365, 60.16945)
    xyz = np.vstack([_street() + [e, n, 0.0], [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 5.0]]])
    r = _run(project, _las(project.tmp / "junk.las", xyz))
    assert r.rc == 0, r.text[-2000:]
    assert "wrong CRS" not in r.text
    assert "dropped 3 of 3003 points more than 20 km from the base point" in r.text
    assert "[0.0, 0.0, 0.0]" in r.text  # where the farthest one is
    assert _metrics(project)["points"] == 3000


def _small_file_limit():
    """In the child: files larger than 200 kB cannot be written (write(2) writes short, then fails, as on a
    full disk), and the signal that would kill the process is ignored, so numpy sees the short write."""
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (200_000, 200_000))


def test_a_short_numpy_write_is_named_a_full_disk(project):
    """numpy's short write (``OSError: 369223 requested and 302636 written``: no errno) is the documented
    disk-full line, naming the path and the free space (exit 1, the manifest written)."""
    r = _run(project, _ply(project.tmp / "big.ply", _street(20000)), preexec_fn=_small_file_limit)
    assert r.rc == 1, r.text[-2000:]
    err = [ln for ln in r.err.splitlines() if "error" in ln.lower()]
    assert len(err) == 1 and "disk full (no space left on the device) writing " in err[0], r.err
    assert "MiB free" in err[0] and "requested and" not in err[0]
    m = json.loads(sorted(project.out.glob("t/runs/*/manifest.json"))[-1].read_text())
    assert m["status"] == "failed" and "disk full" in m["error"]


def test_byte_identical_photos_are_dropped_and_named(tmp_path, caplog):
    """A photo set holding the same file twice (``IMG_3.png`` a copy of ``IMG_1.png``) went into structure from
    motion as two views; the later one in name order is dropped with a warning naming both files."""
    from PIL import Image
    from twinkit_photo.plugin import _photo_infos

    rng = np.random.default_rng(0)
    for i in range(3):
        Image.fromarray(rng.integers(0, 255, (32, 48, 3), dtype=np.uint8)).save(tmp_path / f"IMG_{i}.png")
    (tmp_path / "IMG_3.png").write_bytes((tmp_path / "IMG_1.png").read_bytes())
    log = logging.getLogger("test.photos")
    with caplog.at_level(logging.WARNING, logger="test.photos"):
        infos = _photo_infos(tmp_path, log)
    assert [i.name for i in infos] == ["IMG_0.png", "IMG_1.png", "IMG_2.png"]
    assert "IMG_3.png: byte-identical to IMG_1.png, dropped" in caplog.text

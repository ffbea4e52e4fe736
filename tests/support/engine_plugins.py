"""Small real plugins for engine tests (loaded with TWINKIT_PLUGIN_MODULES=tests.support.engine_plugins).

Each run of a step appends its name to the file named by $TWINKIT_TEST_COUNTER, so tests
can count how often a step really ran, across processes.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

from twinkit import hookimpl
from twinkit.ranges import param


def _count(name: str) -> None:
    path = os.environ.get("TWINKIT_TEST_COUNTER")
    if path:
        with open(path, "a") as f:
            f.write(name + "\n")


@dataclass
class MakeParams:
    value: int = 1
    size_mb: float = 0.0
    sleep_s: float = 0.0
    fail: bool = False


def make(params: MakeParams, ctx, *, out_data_txt: Path) -> dict:
    """Write a number (and optional padding)."""
    _count("make")
    sleep = params.sleep_s or float(os.environ.get("TWINKIT_TEST_SLEEP", "0"))
    if sleep:
        Path(ctx.workdir, "started").write_text(f"{os.getpid()}\n")
        time.sleep(sleep)
    if params.fail:
        raise RuntimeError("boom on purpose")
    if os.environ.get("TWINKIT_TEST_FULL"):  # /dev/full: every write fails with a real ENOSPC
        with open(os.environ["TWINKIT_TEST_FULL"], "wb") as f:
            f.write(b"x" * 65536)
    with open(out_data_txt, "w") as f:
        f.write(f"{params.value}\n")
        if params.size_mb:
            f.write("x" * int(params.size_mb * 2**20))
    return {"value": params.value}


def double(params, ctx, *, in_data_txt: Path, out_double_txt: Path) -> dict:
    """Double the number."""
    _count("double")
    v = int(Path(in_data_txt).read_text().splitlines()[0])
    out_double_txt.write_text(f"{2 * v}\n")
    return {"value": 2 * v}


@dataclass
class ScaleParams:
    factor: int = param(3, help="what the doubled value is multiplied by")
    degrade_below: int = param(0, ge=0, help="a result below this says it is degraded (ctx.degraded)")


def scale(params: ScaleParams, ctx, *, in_double_txt: Path, out_scaled_txt: Path) -> dict:
    """Multiply by a factor."""
    _count("scale")
    v = int(Path(in_double_txt).read_text().splitlines()[0])
    out_scaled_txt.write_text(f"{params.factor * v}\n")
    if params.factor * v < params.degrade_below:
        ctx.degraded(f"scaled value {params.factor * v} is below {params.degrade_below}", "try steps.scale.factor=10")
    return {"value": params.factor * v}


def read_seed(params, ctx, *, in_seed_txt: Path, out_data_txt: Path) -> None:
    """Copy a site input."""
    _count("read_seed")
    out_data_txt.write_text(Path(in_seed_txt).read_text())


def make_ply(params, ctx, *, out_mesh_ply: Path) -> None:
    """A tiny ASCII PLY mesh (one triangle)."""
    _count("make_ply")
    out_mesh_ply.write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 2 0\n3 0 1 2\n"
    )


@dataclass
class TilesParams:
    n: int = 3
    costs: bool = False  # give each item a "cost" (the last tile costs most)


def tiles(params: TilesParams, ctx, *, in_data_txt: Path, out_tiles_json: Path) -> None:
    """List n tiles."""
    _count("tiles")
    out_tiles_json.write_text(json.dumps([{"i": i} | ({"cost": i} if params.costs else {}) for i in range(params.n)]))


def per_tile(params, ctx, *, in_data_txt: Path, item: dict, out_tile_txt: Path) -> dict:
    """One fanned-out item: value + tile index; records the worker pid."""
    _count(f"per_tile{item['i']}")
    sleep = float(os.environ.get("TWINKIT_TEST_TILE_SLEEP", "0"))
    if sleep:
        Path(ctx.workdir, "started").write_text(f"{os.getpid()}\n")
        time.sleep(sleep)
    v = int(Path(in_data_txt).read_text().splitlines()[0])
    out_tile_txt.write_text(f"{v + item['i']}\n{os.getpid()}\n")
    if str(item["i"]) == os.environ.get("TWINKIT_TEST_DEGRADE_TILE"):
        return {"pid": os.getpid(), "degraded": [{"reason": f"tile {item['i']} came out empty"}]}
    return {"pid": os.getpid(), "omp_threads": os.environ.get("OMP_NUM_THREADS"), "started": time.time()}


def gather(params, ctx, *, in_tile_txt: list, out_merged_txt: Path) -> None:
    """Sum the tiles."""
    _count("gather")
    total = sum(int(Path(p).read_text().splitlines()[0]) for p in in_tile_txt)
    out_merged_txt.write_text(f"{total}\n")


def place(params, ctx, *, in_data_txt: Path, out_placed_txt: Path) -> None:
    """Shift the number by the site's base point (reads site.base_point, like read_cloud's frame shift)."""
    _count("place")
    bp = ctx.site.get("base_point") or {}
    if ctx.site.get("tag"):  # read, so in the key (a test's secret)
        (Path(out_placed_txt).parent / "tag.txt").write_text("tagged\n")
    v = int(Path(in_data_txt).read_text().splitlines()[0])
    out_placed_txt.write_text(f"{v + int(bp.get('x', 0))}\n")


def place_tile(params, ctx, *, in_data_txt: Path, item: dict, out_ptile_txt: Path) -> None:
    """A fanned-out item that reads the site's base point (in a worker process)."""
    _count(f"place_tile{item['i']}")
    bp = ctx.site.get("base_point") or {}
    out_ptile_txt.write_text(f"{item['i'] + int(bp.get('x', 0))}\n")


@dataclass
class CrashParams:
    how: str = "segv"  # segv: read address 0 | abort | block: sleep with SIGINT/SIGTERM blocked (a long C call)


def crash(params: CrashParams, ctx, *, in_data_txt: Path, out_crashed_txt: Path, item: dict | None = None) -> None:
    """A stand-in for a native library that crashes, or does not return to Python for a long time."""
    import ctypes
    import signal

    _count("crash")
    Path(ctx.workdir, "started").write_text(f"{os.getpid()}\n")
    if params.how == "segv":
        ctypes.string_at(0)
    elif params.how == "abort":
        os.abort()
    elif params.how == "block":
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
        time.sleep(120)
    out_crashed_txt.write_text("survived\n")


def threads(params, ctx, *, in_data_txt: Path, out_threads_txt: Path) -> dict:
    """Write the step's thread budget and the OpenMP setting it runs under."""
    _count("threads")
    out_threads_txt.write_text(f"{ctx.threads} {os.environ.get('OMP_NUM_THREADS')}\n")
    return {"threads": ctx.threads}


def toy_roads(params, ctx, *, in_data_txt: Path, out_osm_txt: Path) -> None:
    """A road source: writes the 'roads' of the site."""
    _count("toy_roads")
    out_osm_txt.write_text(Path(in_data_txt).read_text())


def convert_roads(params, ctx, *, out_net_txt: Path, in_osm_txt: Path | None = None,
                  in_xodr_txt: Path | None = None) -> None:
    """Reads only optional inputs (like osm_to_opendrive)."""
    _count("convert_roads")
    out_net_txt.write_text(Path(in_osm_txt or in_xodr_txt).read_text())


def align_net(params, ctx, *, in_net_txt: Path, out_aligned_txt: Path) -> None:
    _count("align_net")
    out_aligned_txt.write_text(Path(in_net_txt).read_text())


def export_all(params, ctx, *, in_double_txt: Path, out_export_txt: Path, in_aligned_txt: Path | None = None) -> None:
    """Takes the roads when there are any (like carla_package)."""
    _count("export_all")
    out_export_txt.write_text("roads\n" if in_aligned_txt else "no roads\n")


def toy_roads_preflight(site, params, inputs) -> list[str]:
    """A plugin's cheap check (twinkit/engine/preflight.py): refuses a site marked ``roads_offline``."""
    return ["the toy road server is offline (site.roads_offline)"] if site.get("roads_offline") else []


def toy_file_roads(params, ctx, *, in_osm_txt: Path, out_osm_txt: Path) -> None:
    """A road source reading a site file (like road_source=file), with a fallback (toy_scan)."""
    _count("toy_file_roads")
    out_osm_txt.write_text(Path(in_osm_txt).read_text())


def toy_file_preflight(site, params, inputs) -> list[str]:
    """Refuses a file that 'does not cover the site' (site.osm_far), like road_source=file's box check."""
    return ["the OSM file does not cover the site (site.osm_far)"] if site.get("osm_far") else []


def toy_scan_roads(params, ctx, *, in_data_txt: Path, out_xodr_txt: Path) -> None:
    """A road source from an earlier step's output (like road_source=scan)."""
    _count("toy_scan_roads")
    out_xodr_txt.write_text("scan " + Path(in_data_txt).read_text())


@dataclass
class ToySiteParams:
    points: int = 3
    photos: bool = True


def toy_site(params: ToySiteParams, ctx, *, out_data_txt: Path, out_photos_txt: Path) -> None:
    """A site generator (like the demo's): a number, and 'photos' only when asked for."""
    _count("toy_site")
    out_data_txt.write_text(f"{params.points}\n")
    out_photos_txt.write_text("photos\n" if params.photos else "")


@hookimpl
def twinkit_register_site_generators(register):
    register("toy_site", toy_site, params=ToySiteParams)


@hookimpl
def twinkit_register_road_sources(register):
    register("toy", toy_roads, preflight=toy_roads_preflight)
    register("toy_file", toy_file_roads, preflight=toy_file_preflight, fallback="toy_scan")
    register("toy_scan", toy_scan_roads)


@hookimpl
def twinkit_register_steps(register):
    register("crash", crash, params=CrashParams)
    register("threads", threads)
    register("convert_roads", convert_roads)
    register("align_net", align_net)
    register("export_all", export_all)
    register("make", make, params=MakeParams)
    register("read_seed", read_seed)
    register("make_ply", make_ply)
    register("double", double)
    register("scale", scale, params=ScaleParams)
    register("tiles", tiles, params=TilesParams)
    register("per_tile", per_tile)
    register("gather", gather)
    register("place", place)
    register("place_tile", place_tile)

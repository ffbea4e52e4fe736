"""OSM -> OpenDRIVE with SUMO's netconvert (PyPI ``eclipse-sumo``), and the offline check with carla.Map."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from twinkit import InputError
from twinkit.ranges import param

#: CARLA's Osm2OdrSettings default way types (carla/PythonAPI: settings.set_osm_way_types)
CARLA_WAY_TYPES = ["motorway", "motorway_link", "trunk", "trunk_link", "primary", "primary_link", "secondary",
                   "secondary_link", "tertiary", "tertiary_link", "unclassified", "residential"]


@dataclass
class ConvertParams:
    lane_width_m: float = param(3.25, gt=0, le=20,
                                help="Lane width (m) for ways without width tags (netconvert --default.lanewidth; "
                                     "CARLA's importer uses 4.0).")
    way_types: list[str] = param(default_factory=lambda: list(CARLA_WAY_TYPES), free=True,
                                 help="The highway=* types kept (CARLA's default way types).")
    traffic_lights: bool = param(True,
                                 help="Guess traffic lights from highway=traffic_signals nodes "
                                      "(--tls.guess-signals; CARLA's generate_traffic_lights).")
    all_junctions_traffic_lights: bool = param(False,
                                               help="Signalise every junction (--tls.guess; CARLA's "
                                                    "all_junctions_with_traffic_lights).")
    sidewalks: bool = param(True, help="Add sidewalk lanes beside urban streets (--sidewalks.guess).")
    sidewalk_width_m: float = param(2.0, gt=0, le=20,
                                    help="Width (m) of the guessed sidewalks (--default.sidewalk-width; CARLA's "
                                         "default).")
    osm_sidewalk_tags: bool = param(False,
                                    help="Use OSM's sidewalk=* tags (--osm.sidewalks); shifts one-way streets, see "
                                         "docs/roads.md.")
    layer_elevation_m: float = param(0.0, ge=0,
                                     help="Height (m) of one OSM layer (bridges, tunnels; --osm.layer-elevation, "
                                          "CARLA's elevation_layer_height); 0 = flat.")
    junction_corner_detail: int = param(5, ge=0,
                                        help="Points on each rounded junction corner (--junctions.corner-detail).")
    step_m: float = param(2.0, gt=0, help="Waypoint spacing (m) of the check of the converted map.")
    check_radius_m: float = param(-1.0,
                                  help="Half side (m) of the site box for the check; < 0 = site.osm_radius_m "
                                       "(default 150).")
    min_waypoints_inside: int = param(10, ge=0,
                                      help="The step fails when fewer waypoints than this lie inside the site box.")
    timeout_s: float = param(600.0, gt=0, help="Wall-clock limit (s) of netconvert.")
    extra_args: list[str] = param(default_factory=list, free=True, help="More netconvert options, appended verbatim.")


def netconvert_path() -> Path:
    try:
        import sumo  # the eclipse-sumo wheel
    except ImportError:
        raise InputError("netconvert not found: install SUMO from PyPI (pip install eclipse-sumo)") from None
    base = Path(sumo.__file__).parent
    exe = base / "bin" / ("netconvert.exe" if os.name == "nt" else "netconvert")
    if not exe.is_file():
        raise InputError(f"netconvert not found in the eclipse-sumo package at {exe}; reinstall eclipse-sumo")
    return exe


def netconvert_version() -> str:
    r = subprocess.run([str(netconvert_path()), "--version"], capture_output=True, text=True, timeout=60)
    m = re.search(r"netconvert\s+(\S+)", r.stdout)
    return m.group(1) if m else "?"


def netconvert_args(osm: Path, xodr: Path, proj: str, p: ConvertParams) -> list[str]:
    """The option set of CARLA's OSM importer (Osm2Odr), with the projection of the site frame."""
    args = [str(netconvert_path()),
            "--osm-files", str(osm), "--opendrive-output", str(xodr),
            "--proj", proj, "--offset.disable-normalization",  # coordinates = site frame, no recentring
            "--geometry.remove", "--ramps.guess", "--edges.join", "--junctions.join", "--roundabouts.guess",
            "--keep-edges.by-type", ",".join(f"highway.{t}" for t in p.way_types),
            "--tls.discard-simple", "--tls.join",
            "--default.lanewidth", repr(float(p.lane_width_m)),
            "--junctions.corner-detail", str(int(p.junction_corner_detail)),
            "--output.street-names", "--output.original-names",
            "--no-warnings", "false", "--verbose", "false"]
    if p.layer_elevation_m > 0:
        args += ["--osm.layer-elevation", repr(float(p.layer_elevation_m))]
    if p.traffic_lights:
        args += ["--tls.guess-signals", "--tls.guess-signals.dist", "25"]
    if p.all_junctions_traffic_lights:
        args += ["--tls.guess", "--tls.guess.threshold", "0"]
    if p.sidewalks:
        args += ["--sidewalks.guess", "--default.sidewalk-width", repr(float(p.sidewalk_width_m))]
    if p.osm_sidewalk_tags:
        args += ["--osm.sidewalks"]
    return args + [str(a) for a in p.extra_args]


def _env() -> dict:
    import sumo

    env = dict(os.environ)
    env.setdefault("SUMO_HOME", str(Path(sumo.__file__).parent))
    return env


def run_netconvert(osm: Path, xodr: Path, proj: str, p: ConvertParams, log=None) -> dict:
    """Run netconvert; InputError naming the cause (with netconvert's own message) when it fails."""
    args = netconvert_args(osm, xodr, proj, p)
    t0 = time.perf_counter()
    try:
        r = subprocess.run(args, capture_output=True, text=True, timeout=p.timeout_s, env=_env())
    except subprocess.TimeoutExpired:
        raise InputError(f"netconvert did not finish in {p.timeout_s:g} s on {osm.name}; raise timeout_s or crop "
                         "the OSM data (road_source.crop_radius_m)") from None
    dt = time.perf_counter() - t0
    lines, errors = netconvert_output(r)
    if any("No edges loaded" in ln for ln in errors):
        raise InputError(f"netconvert found no roads in {osm.name}: " + way_type_message(osm, p.way_types))
    return finish_netconvert(r, lines, errors, xodr, args, osm.name, dt, log)


def netconvert_output(r) -> tuple[list[str], list[str]]:
    """netconvert's output lines worth reading, and its errors."""
    # PROJ inside the wheel looks for proj.db at a build-time path; our +proj strings do not need it.
    lines = [ln for ln in (r.stderr + r.stdout).splitlines() if ln.strip() and "proj.db" not in ln
             and "SUMO_HOME" not in ln]
    return lines, [ln for ln in lines if ln.startswith("Error")]


def finish_netconvert(r, lines: list[str], errors: list[str], xodr: Path, args: list[str], what: str,
                      seconds: float, log=None) -> dict:
    """A failed netconvert run (``what``: the input, in words) is an InputError; else the written OpenDRIVE
    is made deterministic and its warnings logged (the first five)."""
    if r.returncode != 0 or errors or not xodr.is_file() or xodr.stat().st_size == 0:
        why = "; ".join(errors[-3:] or lines[-3:]) or f"exit code {r.returncode}"
        raise InputError(f"netconvert failed on {what} (exit {r.returncode}): {why}")
    _make_deterministic(xodr, args)
    warnings = [ln for ln in lines if ln.startswith("Warning")]
    if log is not None:
        for ln in warnings[:5]:
            log.info("netconvert: %s", ln)
    return {"netconvert_s": round(seconds, 3), "netconvert_warnings": len(warnings)}


def way_type_message(osm: Path | None, way_types: list[str]) -> str:
    """Which highway=* way types the OSM file holds, against the kept ones, and the setting that widens them."""
    found: dict[str, int] = {}
    if osm is not None:
        try:
            from .osmio import read_osm

            for _, tags in read_osm(osm).ways.values():
                if "highway" in tags:
                    found[tags["highway"]] = found.get(tags["highway"], 0) + 1
        except InputError:
            pass
    have = ", ".join(f"{k} ({v})" for k, v in sorted(found.items(), key=lambda kv: -kv[1])) or "none"
    kept = [k for k in found if k in way_types]
    if kept:
        return (f"it has highway ways of the types {have}; netconvert built no road from the kept ones "
                f"({', '.join(kept)}): too short, or outside the projection's area? Check the extract in an editor")
    missing = [k for k in sorted(found, key=lambda k: -found[k]) if k not in way_types]
    widen = ",".join(list(way_types) + missing[:3])
    return (f"it has highway ways of the types {have}, and none of them is a kept type "
            f"(way_types: {', '.join(way_types)}). Widen the kept types, e.g. "
            f"steps.osm_to_opendrive.way_types=[{widen}], or give an extract with streets")


def _make_deterministic(xodr: Path, args: list[str]) -> None:
    """Drop netconvert's time stamp and temporary paths, so that the same input gives the same file
    (and later steps are not re-run for nothing); keep the options as a comment."""
    text = xodr.read_text(encoding="utf-8")
    text = re.sub(r"<!--.*?-->\s*", "", text, count=1, flags=re.S)
    shown = [Path(a).name if os.sep in a and not a.startswith("+") else a for a in args[1:]]
    opts = " ".join(shown).replace("--", "- -")  # "--" is not allowed inside an XML comment
    text = re.sub(r'(<header\b[^>]*?)\sdate="[^"]*"', r'\1 date=""', text, count=1)
    head, sep, rest = text.partition("?>")
    if sep:
        text = f"{head}?>\n<!-- written by twinkit-roads with netconvert {netconvert_version()}: {opts} -->{rest}"
    xodr.write_text(text, encoding="utf-8")


def xodr_counts(text: str) -> dict:
    """Roads, junctions, signals and traffic lights counted in the OpenDRIVE XML."""
    import xml.etree.ElementTree as ET

    root = ET.fromstring(text)
    roads = root.findall("road")
    signals = [s for r in roads for s in r.iter("signal")]
    tl = [s for s in signals if s.get("type") in ("1000001", "1000002", "1000011") or
          (s.get("name") or "").lower().startswith("traffic")]
    lanes: dict[str, int] = {}
    for ln in root.iter("lane"):
        t = ln.get("type", "?")
        if ln.get("id") != "0":
            lanes[t] = lanes.get(t, 0) + 1
    return {"roads": len(roads), "junctions": len(root.findall("junction")),
            "junction_roads": sum(1 for r in roads if r.get("junction", "-1") != "-1"),
            "signals": len(signals), "traffic_lights": len(tl), "controllers": len(root.findall("controller")),
            "lanes_by_type": lanes}


def check_xodr(xodr: Path, bounds_local: tuple[float, float, float, float], step_m: float = 2.0,
               timeout_s: float = 300.0, samples: Path | None = None) -> dict:
    """Parse with carla.Map offline in a child process (a malformed file cannot crash the step).

    ``bounds_local`` = (xmin, ymin, xmax, ymax) in the site frame. Returns counts and timings. With
    ``samples``, the waypoints' lane centres are saved there (x, y, z, road, lane, s; see xodrcheck).
    """
    cmd = [sys.executable, "-m", "twinkit_roads.xodrcheck", str(xodr), json.dumps(list(bounds_local)), str(step_m)]
    if samples is not None:
        cmd.append(str(samples))
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        raise InputError(f"carla.Map did not parse {xodr.name} within {timeout_s:g} s") from None
    out = [ln for ln in r.stdout.splitlines() if ln.startswith("{")]
    if r.returncode != 0 or not out:
        tail = (r.stderr.strip().splitlines() or ["no output"])[-1]
        raise InputError(f"carla.Map rejected {xodr.name} (exit {r.returncode}): {tail}")
    res = json.loads(out[-1])
    if "error" in res:
        raise InputError(f"carla.Map rejected {xodr.name}: {res['error']}")
    return res

"""The RoadPainter decals of CARLA's import (rule ``decals`` of :mod:`.carla_contract`).

``make import`` always runs ``LoadAssetMaterials``, which paints random road decals from
``Import/roadpainter_decals.json``; ``Import.py``'s ``generate_decals_file`` writes one with default counts
when the package brings none (Util/BuildTools/Import.py; Util/RoadPainterWrapper.cpp ``ReadConfigFile``;
Commandlet/LoadAssetMaterialsCommandlet.cpp).
"""
from __future__ import annotations

import json
from pathlib import Path

DECALS_FILE = "roadpainter_decals.json"

# -- RoadPainterWrapper.cpp ReadConfigFile: fields read for the entry whose map_name is the map
DECAL_FIELDS = ("map_name", "decal_scale", "fixed_decal_offset", "decal_min_scale", "decal_max_scale",
                "decal_random_yaw", "random_offset")
DECAL_VECTOR_FIELDS = ("decal_scale", "fixed_decal_offset")
# the decal names LoadAssetMaterialsCommandlet.cpp knows (DecalNamesMap), and the counts Import.py's
# generate_decals_file writes when no roadpainter_decals.json exists
DECAL_NAMES = tuple(
    [f"dirt{i}" for i in range(1, 6)] + [f"drip{i}" for i in range(1, 4)] + [f"roadline{i}" for i in range(1, 6)]
    + [f"tiremark{i}" for i in range(1, 4)] + [f"tarsnake{i}" for i in range(1, 12)]
    + [f"cracksbig{i}" for i in range(1, 9)] + [f"crack{i}" for i in range(1, 9)]
    + [f"manhole{i}" for i in range(1, 4)] + [f"mud{i}" for i in range(1, 6)]
    + [f"oilsplat{i}" for i in range(1, 6)] + ["gum", "grate"])
DECAL_DEFAULT_COUNTS = {
    "drip1": 10, "drip3": 10, "dirt1": 10, "dirt3": 10, "dirt4": 10, "dirt5": 10, "roadline1": 20, "roadline5": 20,
    "tiremark1": 20, "tiremark3": 20, "tarsnake1": 10, "tarsnake3": 20, "tarsnake4": 10, "tarsnake5": 20,
    "tarsnake11": 20, "cracksbig1": 10, "cracksbig3": 10, "cracksbig5": 10, "cracksbig8": 10, "mud1": 10, "mud5": 10,
    "oilsplat1": 20, "oilsplat2": 20, "oilsplat3": 20, "oilsplat4": 20, "oilsplat5": 20, "gum": 30, "crack1": 10,
    "crack3": 10, "crack4": 10, "crack5": 10, "crack8": 10}
DECAL_DEFAULT_PARAMS = {"decal_scale": {"x_axis": 1.0, "y_axis": 1.0, "z_axis": 1.0},
                        "fixed_decal_offset": {"x_axis": 15.0, "y_axis": 15.0, "z_axis": 0.0},
                        "decal_min_scale": 0.3, "decal_max_scale": 0.7, "decal_random_yaw": 360.0,
                        "random_offset": 50.0}


def decals_entry(map_name: str, enabled: bool) -> dict:
    """One ``decals`` entry of roadpainter_decals.json for ``map_name``: CARLA's default counts or none.

    With ``enabled`` false the entry names no decal at all (RoadPainter then has no decal material
    to spawn) but keeps every parameter field, which RoadPainterWrapper reads unconditionally.
    """
    entry: dict = {"map_name": map_name}
    if enabled:
        entry.update(DECAL_DEFAULT_COUNTS)
    entry.update(json.loads(json.dumps(DECAL_DEFAULT_PARAMS)))
    return entry


def check_decals(rep, imp: Path, map_names: list[str], expect: bool | None) -> None:
    """The rule ``decals``: ``imp``/roadpainter_decals.json and what it paints on each of ``map_names``; sets
    ``rep.decals`` (True when decals are painted); ``expect``: the setting the package must carry (None: report)."""
    from .carla_contract import _json

    files = sorted(imp.rglob(DECALS_FILE))
    top = imp / DECALS_FILE
    if not files:
        rep.decals = True
        if expect is not True:
            rep.add("decals", f"no {DECALS_FILE} under {imp.name}/: make import would generate one that paints random "
                              f"decals (dirt, cracks, tyre marks, road lines) on {', '.join(map_names) or 'the map'}")
        return
    if top not in files:
        rep.add("decals", f"{DECALS_FILE} must lie directly in Import/ (Import.py copies only Import/{DECALS_FILE} "
                          f"into the package's Content/<Package>/Config)")
        return
    data = _json(top, rep, "decals")
    entries = data.get("decals") if isinstance(data, dict) else None
    if not isinstance(entries, list):
        rep.add("decals", f"{DECALS_FILE}: needs a 'decals' list")
        return
    painted = False
    for name in map_names:
        ent = [e for e in entries if isinstance(e, dict) and e.get("map_name") == name]
        if not ent:
            rep.add("decals", f"{DECALS_FILE}: no entry with map_name {name!r}")
            continue
        e = ent[0]
        missing = [f for f in DECAL_FIELDS if f not in e]
        missing += [f"{f}.{a}" for f in DECAL_VECTOR_FIELDS if isinstance(e.get(f), dict)
                    for a in ("x_axis", "y_axis", "z_axis") if a not in e[f]]
        if missing:
            rep.add("decals", f"{DECALS_FILE}: entry {name!r} lacks {', '.join(missing)} (RoadPainter reads them all)")
        for k in DECAL_NAMES:
            if k in e:
                try:
                    n = float(e[k])
                except (TypeError, ValueError):
                    rep.add("decals", f"{DECALS_FILE}: entry {name!r}: {k} = {e[k]!r} is not a number")
                    continue
                painted = painted or n > 0
    rep.decals = painted
    if expect is not None and painted != expect:
        rep.add("decals", f"{DECALS_FILE}: decals are {'on' if painted else 'off'} for {', '.join(map_names)}, "
                          f"expected {'on' if expect else 'off'}")

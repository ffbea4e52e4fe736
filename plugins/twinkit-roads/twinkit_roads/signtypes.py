"""Which OpenDRIVE type a scanned traffic sign gets, so that CARLA can use it.

CARLA 0.9.16 spawns sign actors for two signal types only (Unreal/CarlaUE4/Plugins/Carla/Source/Carla/Traffic/
TrafficLightManager.cpp, ``ATrafficLightManager`` constructor and ``SpawnSignals``: ``TrafficSignsModels`` holds
``SignalType::StopSign()`` = "206" -> BP_Stop and ``SignalType::YieldSign()`` = "205" -> BP_Yield;
LibCarla/source/carla/road/SignalType.cpp). A speed limit is ``SignalType::MaximumSpeed()`` = "274" with its
value: carla.Map reports it as a landmark (``Landmark.value``), and CARLA's later ``SpawnSignals`` spawns
``BP_SpeedLimit<subtype>`` for subtypes 30 .. 120, so the speed is written as value and subtype. Any other
plate keeps the generic type "-1" (a landmark CARLA spawns nothing for) and its record says why.

Where a type comes from, first that holds:

1. OSM: a node ``highway=stop`` / ``highway=give_way`` / ``traffic_sign=*`` within ``osm_match_m`` of the plate
   (:func:`osm_kind`); a speed sign's value from its ``maxspeed``;
2. the plate's look (:func:`plate_look`): the hue of its coloured texels (red: stop, red with yellow:
   give way, white with a red ring: speed limit, blue: an information plate, generic);
3. a speed limit's value, when the sign does not carry one: the road's speed record (netconvert writes OSM's
   ``maxspeed`` as the lanes' ``<speed max>``, m/s).
"""
from __future__ import annotations

import math

import numpy as np

#: kind -> (OpenDRIVE type, subtype); a speed limit's subtype is its value in km/h
CARLA_SIGN_TYPES = {"stop": ("206", "-1"), "yield": ("205", "-1"), "speed": ("274", "")}
GENERIC = "-1"

# traffic_sign=* values -> kind: the plain words, and national codes with their country (DE: the Vienna-convention
# numbers; FI: the 2020 numbers (363: a speed-limit zone) and the older letters; US: MUTCD)
_OSM_WORDS = {"stop": "stop", "give_way": "yield", "yield": "yield", "maxspeed": "speed"}
_OSM_CODES = {"DE:206": "stop", "DE:205": "yield", "DE:274": "speed", "FI:232": "stop", "FI:231": "yield",
              "FI:361": "speed", "FI:363": "speed", "FI:B6": "stop", "FI:B5": "yield", "FI:C32": "speed", "US:R1-1": "stop",
              "US:R1-2": "yield", "US:R2-1": "speed"}


def osm_kind(tags: dict) -> str | None:
    """The sign kind (stop, yield, speed) an OSM node's tags name, or None."""
    hw = tags.get("highway")
    if hw == "stop":
        return "stop"
    if hw == "give_way":
        return "yield"
    for part in str(tags.get("traffic_sign", "")).replace(";", ",").split(","):
        code = part.strip().split("[")[0]
        kind = _OSM_CODES.get(code.upper()) or _OSM_WORDS.get(code.lower())
        if kind:
            return kind
    return None


def plate_look(colors: np.ndarray, min_share: float = 0.08) -> tuple[str | None, str]:
    """The kind a plate's texture shows, from (n, 3) uint8 RGB of its vertices; (kind or None, why).

    Coloured vertices (HSV saturation > 0.25) vote by hue: red 0-15 / 345-360 degrees, orange-yellow 15-60, blue
    180-260. Blue over half of them: an information plate (None, generic). Red with orange-yellow (at least 12 %
    of the coloured vertices; the demo's stop plates show 0 %, its give-way plates 23-78 % on seeds 0, 3, 7):
    give way. Red over half with most vertices coloured: stop. Coloured vertices a minority, red among them, the
    rest light: a speed limit (white disc, red ring). Fewer than ``min_share`` coloured: None.
    """
    c = np.asarray(colors, float)[:, :3] / 255.0
    if len(c) == 0:
        return None, "no vertices"
    mx, mn = c.max(1), c.min(1)
    sat = np.where(mx > 0, (mx - mn) / np.maximum(mx, 1e-9), 0.0)
    r, g, b = c.T
    hue = np.degrees(np.arctan2(math.sqrt(3) * (g - b), 2 * r - g - b)) % 360
    col = sat > 0.25
    share = float(col.mean())
    if share < min_share:
        return None, f"{share:.0%} of its vertices coloured: no colour to read"
    h = hue[col]
    red = float(np.mean((h < 15) | (h >= 345)))
    warm = float(np.mean((h >= 15) & (h < 60)))
    blue = float(np.mean((h >= 180) & (h < 260)))
    why = f"coloured {share:.0%}: red {red:.0%}, orange-yellow {warm:.0%}, blue {blue:.0%}"
    if blue > 0.5:
        return None, why + " (a blue information plate)"
    if red + warm > 0.6 and warm >= 0.12 and red >= 0.1:
        return "yield", why
    if red + warm > 0.6 and share >= 0.45:
        return "stop", why
    light = float(np.mean(mn[~col] > 0.55)) if (~col).any() else 0.0
    if red + warm > 0.5 and share < 0.45 and light > 0.5:
        return "speed", why + f", light {light:.0%} of the rest"
    return None, why


def road_speed_kmh(road_el) -> float | None:
    """The largest lane speed of a road (``<lane><speed max>`` in m/s, or ``<type><speed max unit>``), km/h."""
    best = None
    for sp in road_el.iter("speed"):
        try:
            v = float(sp.get("max", "nan"))
        except ValueError:
            continue
        if not math.isfinite(v):
            continue
        unit = sp.get("unit", "m/s")
        kmh = v * 3.6 if unit == "m/s" else (v * 1.609344 if unit == "mph" else v)
        best = kmh if best is None else max(best, kmh)
    return None if best is None else float(5 * round(best / 5))


def signal_type(kind: str | None, speed_kmh: float | None) -> tuple[str, str, str | None]:
    """(type, subtype, value) for a kind; a speed limit without a value, and unknown kinds, are generic."""
    if kind in ("stop", "yield"):
        t, st = CARLA_SIGN_TYPES[kind]
        return t, st, None
    if kind == "speed" and speed_kmh:
        v = f"{int(round(speed_kmh))}"
        return "274", v, v
    return GENERIC, "-1", None


def typed_plates(rejected: list, colors: np.ndarray | None) -> list:
    """Sign clusters refused only for the pole under them (thin poles are often lost by the reconstruction)
    whose plate shows a stop, give-way or speed-limit look: kept, ``evidence = "plate_look"``. ``rejected``:
    ``instances.Instance`` list; ``colors``: (n, 3) uint8 of the mesh's vertices. Returns the kept ones."""
    out = []
    if colors is None:
        return out
    for inst in rejected:
        reasons = [r for r in inst.rejected.split("; ") if r]
        if inst.kind != "sign" or inst.members is None or len(reasons) != 1 or "pole vertices" not in reasons[0]:
            continue
        if plate_look(colors[inst.members])[0] in ("stop", "yield", "speed"):
            inst.rejected, inst.evidence = "", "plate_look"
            out.append(inst)
    return out


def ground_typed_signs(root, max_z_offset_m: float = 1.0) -> list[str]:
    """Stand the map's stop, yield and speed-limit signals on the ground (zOffset 0, in place in ``root``, an
    OpenDRIVE element tree): CARLA spawns a whole sign blueprint at road elevation + zOffset
    (``ATrafficLightManager::SpawnSignals``), so a zOffset at the plate's height (RoadRunner writes one) floats
    the pole. Returns a log line per signal changed."""
    out = []
    for sig in root.iter("signal"):
        z = float(sig.get("zOffset", 0.0))
        if sig.get("type") in ("205", "206", "274") and abs(z) > max_z_offset_m:
            sig.set("zOffset", "0.000")
            out.append(f"sign {sig.get('id')} (type {sig.get('type')}): zOffset {z:.2f} m -> 0, CARLA spawns its "
                       "blueprint pole at that height")
    return out


def osm_sign_nodes(osm_path, lonlat_to_local, alignment: dict | None = None) -> list[tuple[float, float, str]]:
    """OSM's sign nodes (``osm_kind``) as (x, y, kind) in the frame of the aligned OpenDRIVE: ``lonlat_to_local``
    ((n, 2) lon, lat -> (n, 2) site metres, ``SiteFrame.lonlat_to_local``), then ``alignment.json``'s similarity
    (aligned_xy = Rz(yaw_deg) @ xy + [tx_m, ty_m]), which moved the OSM network onto the scan."""
    from .osmio import read_osm

    nodes = [(lo, la, osm_kind(t)) for lo, la, t in read_osm(osm_path).nodes.values()]
    nodes = [n for n in nodes if n[2]]
    if not nodes:
        return []
    xy = np.asarray(lonlat_to_local(np.array([[lo, la] for lo, la, _ in nodes], float)), float).reshape(-1, 2)
    if alignment:
        a = math.radians(float(alignment.get("yaw_deg", 0.0)))
        R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        xy = xy @ R.T + [float(alignment.get("tx_m", 0.0)), float(alignment.get("ty_m", 0.0))]
    return [(float(x), float(y), k) for (x, y), (_, _, k) in zip(xy, nodes)]

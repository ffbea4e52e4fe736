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

# traffic_sign=* values (national codes: DE, FI, ... and the plain words) -> kind
_OSM_SIGN = {"stop": "stop", "give_way": "yield", "yield": "yield", "maxspeed": "speed",
             "206": "stop", "205": "yield", "274": "speed",          # DE:..., the Vienna-convention numbers
             "b5": "yield", "b6": "stop", "c32": "speed", "361": "speed",  # FI:B5 / B6 / C32 (Finland)
             "r1-1": "stop", "r1-2": "yield", "r2-1": "speed"}      # US MUTCD


def osm_kind(tags: dict) -> str | None:
    """The sign kind (stop, yield, speed) an OSM node's tags name, or None."""
    hw = tags.get("highway")
    if hw == "stop":
        return "stop"
    if hw == "give_way":
        return "yield"
    for part in str(tags.get("traffic_sign", "")).replace(";", ",").split(","):
        code = part.split(":")[-1].strip().lower().split("[")[0]
        if code in _OSM_SIGN:
            return _OSM_SIGN[code]
    return None


def plate_look(colors: np.ndarray, min_share: float = 0.08) -> tuple[str | None, str]:
    """The kind a plate's texture shows, from (n, 3) uint8 RGB of its vertices; (kind or None, why).

    Coloured vertices (HSV saturation > 0.25) vote by hue: red 0-15 / 345-360 degrees, orange-yellow 15-60, blue
    180-260. Blue over half of them: an information plate (None, generic). Red and yellow both present:
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
    if red + warm > 0.6 and warm >= 0.25 and red >= 0.1:
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

"""Every signal on its road: ``s`` of each ``<signal>`` and ``<signalReference>`` within [0, the road's length].

carla.Map refuses a map with a signal at s < 0 (``RuntimeError: s_position >= 0.0``) and silently moves one
past the road's end onto it. A light defined on the next road (``signals._move_light``) is written
``carla_light_shift_m`` back along its heading, which falls before that road's start when the scanned head
stands within that distance of it: after a small shift of the map (a hand edit of ``alignment.json``) a
head that stood clear of the joint may stand on it. Such a signal is moved onto its road, with a note.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET

#: a signal moved less than this (float rounding) is moved without a note
QUIET_M = 1e-3


def clamp_to_roads(root: ET.Element, placed: list) -> list[str]:
    """Move each ``<signal>`` / ``<signalReference>`` of ``root`` whose s lies outside its road onto the road
    (in place); update the records in ``placed`` (``signals.Placed``: s, note) of the signals defined there.
    Returns one note per signal moved by ``QUIET_M`` or more, naming the signal, the road and the move."""
    notes = []
    for road in root.iter("road"):
        try:
            length = float(road.get("length", "nan"))
        except ValueError:
            continue
        if not length >= 0:
            continue
        rid = road.get("id")
        for el in road.iter():
            raw = el.get("s")
            if el.tag not in ("signal", "signalReference") or raw is None:
                continue
            try:
                s = float(raw)
            except ValueError:
                continue
            on = min(max(s, 0.0), length)
            if not math.isfinite(s):
                continue  # not a position: carla.Map refuses it, and the step's error names the file
            if on == s:
                continue
            el.set("s", f"{on:.8f}")
            what = "signal" if el.tag == "signal" else "reference to signal"
            where = "before the start" if s < 0 else "past the end"
            note = (f"{what} {el.get('id')} on road {rid}: s {s:.3f} m lies {abs(s - on):.3f} m {where} of "
                    f"the road (length {length:.3f} m): moved onto it (s = {on:.3f}); carla.Map refuses a signal "
                    "before its road's start. If the map was shifted by a hand edit of alignment.json, check "
                    "that edit")
            if abs(s - on) >= QUIET_M:
                notes.append(note)
            for p in placed:
                if el.tag == "signal" and p.id == el.get("id") and (p.host_road or p.road) == rid:
                    p.s = on
                    p.note = (p.note + "; " if p.note else "") + f"moved {abs(s - on):.3f} m onto road {rid}"
    return notes

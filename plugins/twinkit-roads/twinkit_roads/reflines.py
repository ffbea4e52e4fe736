"""Roads' reference lines sampled densely from an OpenDRIVE map: the frame signals are written in.

``reference_lines`` samples every road's plan view (lines, arcs, spirals, paramPoly3) into s, x, y,
heading (site frame, m, rad) with its elevation polynomials and driving lanes; ``RefLine`` turns
(s, t) into x, y the way CARLA does and back (``signals.py`` places the signals with them).
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np


@dataclass
class RefLine:
    """A road's reference line sampled densely: s, x, y, heading, and its elevation polynomials."""
    road: str
    length: float
    junction: str
    s: np.ndarray
    xy: np.ndarray
    hdg: np.ndarray
    elev: list = field(default_factory=list)  # (s, a, b, c, d)
    lanes_right: list = field(default_factory=list)  # driving lane ids < 0 (first lane section)
    lanes_left: list = field(default_factory=list)

    def z(self, s: float) -> float:
        rec = [e for e in self.elev if e[0] <= s + 1e-9] or self.elev[:1]
        if not rec:
            return 0.0
        s0, a, b, c, d = rec[-1]
        ds = s - s0
        return a + b * ds + c * ds * ds + d * ds ** 3

    def point(self, s: float, t: float) -> np.ndarray:
        """Site-frame xy of road coordinates (s, t); s is clamped to the line like CARLA's Road does."""
        s = min(max(s, 0.0), self.length)
        i = int(np.clip(np.searchsorted(self.s, s) - 1, 0, len(self.s) - 2))
        f = (s - self.s[i]) / max(self.s[i + 1] - self.s[i], 1e-12)
        p = self.xy[i] + f * (self.xy[i + 1] - self.xy[i])
        h = self.hdg[i]
        return p + t * np.array([-math.sin(h), math.cos(h)])

    def project(self, p) -> tuple[float, float, float]:
        """(s, t, distance beyond the ends) of a site-frame xy point; t > 0 left of the line."""
        p = np.asarray(p, float)[:2]
        a, b = self.xy[:-1], self.xy[1:]
        ab = b - a
        L2 = np.maximum((ab ** 2).sum(1), 1e-12)
        u = np.clip(((p - a) * ab).sum(1) / L2, 0, 1)
        q = a + u[:, None] * ab
        i = int(np.argmin(((p - q) ** 2).sum(1)))
        s = self.s[i] + u[i] * (self.s[i + 1] - self.s[i])
        d = ab[i] / math.sqrt(L2[i])
        r = p - q[i]
        t = d[0] * r[1] - d[1] * r[0]
        # beyond an end: extend along the end tangent so the caller sees how far off the line it is
        over = 0.0
        if u[i] <= 0 and i == 0:
            over = -float(np.dot(p - a[0], d))
        elif u[i] >= 1 and i == len(ab) - 1:
            over = float(np.dot(p - b[-1], d))
        return float(s), float(t), max(over, 0.0)


def _poly_geometry(g: ET.Element, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Points and headings of one <geometry> record in its own s (0..length)."""
    x0, y0, h0, L = (float(g.get(k)) for k in ("x", "y", "hdg", "length"))
    kind = next(iter(g), None)
    n = max(int(math.ceil(L / step)), 1)
    ss = np.linspace(0.0, L, n + 1)
    if kind is None or kind.tag == "line":
        xy = np.stack([x0 + ss * math.cos(h0), y0 + ss * math.sin(h0)], 1)
        return xy, np.full(len(ss), h0)
    if kind.tag == "arc":
        k = float(kind.get("curvature"))
        if abs(k) < 1e-12:
            xy = np.stack([x0 + ss * math.cos(h0), y0 + ss * math.sin(h0)], 1)
            return xy, np.full(len(ss), h0)
        h = h0 + k * ss
        xy = np.stack([x0 + (np.sin(h) - math.sin(h0)) / k, y0 - (np.cos(h) - math.cos(h0)) / k], 1)
        return xy, h
    if kind.tag == "paramPoly3":
        c = {k: float(kind.get(k, 0.0)) for k in ("aU", "bU", "cU", "dU", "aV", "bV", "cV", "dV")}
        normalized = kind.get("pRange", "normalized") == "normalized"
        pmax = 1.0 if normalized else L
        p = np.linspace(0.0, pmax, 20 * (n + 1))
        u = c["aU"] + c["bU"] * p + c["cU"] * p ** 2 + c["dU"] * p ** 3
        v = c["aV"] + c["bV"] * p + c["cV"] * p ** 2 + c["dV"] * p ** 3
        ch, sh = math.cos(h0), math.sin(h0)
        X, Y = x0 + u * ch - v * sh, y0 + u * sh + v * ch
        seg = np.hypot(np.diff(X), np.diff(Y))
        arc = np.concatenate([[0.0], np.cumsum(seg)])
        arc *= L / max(arc[-1], 1e-12)  # the record's length is the arc length
        xs, ys = np.interp(ss, arc, X), np.interp(ss, arc, Y)
        du = c["bU"] + 2 * c["cU"] * p + 3 * c["dU"] * p ** 2
        dv = c["bV"] + 2 * c["cV"] * p + 3 * c["dV"] * p ** 2
        hh = np.unwrap(np.arctan2(du * sh + dv * ch, du * ch - dv * sh))
        return np.stack([xs, ys], 1), np.interp(ss, arc, hh)
    if kind.tag == "spiral":  # numerical integration of the clothoid
        c0, c1 = float(kind.get("curvStart")), float(kind.get("curvEnd"))
        fine = np.linspace(0.0, L, 20 * (n + 1))
        h = h0 + c0 * fine + (c1 - c0) / (2 * max(L, 1e-12)) * fine ** 2
        ds = np.diff(fine)
        X = x0 + np.concatenate([[0.0], np.cumsum(np.cos(h[:-1]) * ds)])
        Y = y0 + np.concatenate([[0.0], np.cumsum(np.sin(h[:-1]) * ds)])
        return np.stack([np.interp(ss, fine, X), np.interp(ss, fine, Y)], 1), np.interp(ss, fine, h)
    raise ValueError(f"unsupported OpenDRIVE geometry <{kind.tag}>")


def reference_lines(root: ET.Element, step: float = 0.05) -> dict[str, RefLine]:
    out = {}
    for road in root.iter("road"):
        S, XY, H = [], [], []
        for g in road.find("planView").findall("geometry"):
            xy, h = _poly_geometry(g, step)
            s0, L = float(g.get("s")), float(g.get("length"))
            S.append(s0 + np.linspace(0.0, L, len(xy)))
            XY.append(xy)
            H.append(h)
        if not S:
            continue
        elev = []
        prof = road.find("elevationProfile")
        if prof is not None:
            elev = sorted(tuple(float(e.get(k, 0.0)) for k in ("s", "a", "b", "c", "d"))
                          for e in prof.findall("elevation"))
        right, left = [], []
        lanes = road.find("lanes")
        sec = lanes.find("laneSection") if lanes is not None else None
        if sec is not None:
            for side, dst in (("right", right), ("left", left)):
                grp = sec.find(side)
                if grp is not None:
                    dst.extend(int(ln.get("id")) for ln in grp.findall("lane") if ln.get("type") == "driving")
        out[road.get("id")] = RefLine(road.get("id"), float(road.get("length")), road.get("junction", "-1"),
                                      np.concatenate(S), np.concatenate(XY), np.concatenate(H), elev,
                                      sorted(right), sorted(left))
    return out

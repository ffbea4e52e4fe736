"""Layout knobs of the demo street for training-data variety (simulated captures, issue 44); the defaults
build the demo as it always was."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Variety:
    """Layout knobs for training-data variety (simulated captures); the defaults build the demo as it always was.

    ``floors``: building floor counts drawn in [lo, hi); ``park_p``: chance that a parking slot holds a car;
    ``tree_scale``: multiplies every tree's size; ``street_trees``: chance of a street tree (in a grass pit) per
    ~11 m of the main road's north and south-west sidewalks and the side streets' sidewalks; ``verge_m``: width (m) of
    a grass verge between the curb and the sidewalk outside the junction (0 = none); ``setback_m``: front gardens (grass)
    this deep between the sidewalk and the buildings; ``hedges``: chance of a hedge along each front garden, and of
    a tree in a deep one; ``hedge_m``: the height of those hedges (0 = the demo's bushes, 0.6-1.1 m; a trimmed
    hedge stands 1-3 m, taller than a single spinning sweep's top beam reaches near it); ``lane_m``, ``park_m``,
    ``sidewalk_m``: the street's widths (None = :class:`Dims`' defaults)."""

    floors: tuple[int, int] = (3, 7)
    park_p: float = 0.65
    tree_scale: float = 1.0
    street_trees: float = 0.0
    verge_m: float = 0.0
    setback_m: float = 0.0
    hedges: float = 0.0
    hedge_m: float = 0.0
    lane_m: float | None = None
    park_m: float | None = None
    sidewalk_m: float | None = None


def random_variety(rng: np.random.Generator, tall_hedges: bool = False) -> Variety:
    """A random :class:`Variety`: low and high-rise streets, few or many parked cars and trees, verges, widths;
    ``tall_hedges``: the hedges' height too (0.6-3 m; the shipped 3D classifier's spinning sweeps have them, with
    rough surfaces: docs/segmentation.md "Rough hedges and rough facades: m16")."""
    lo = int(rng.integers(1, 4))
    sidewalk = float(rng.uniform(2.5, 5.0))
    verge = float(rng.uniform(0.8, 0.5 * sidewalk)) if rng.random() < 0.35 else 0.0
    v = Variety(floors=(lo, lo + int(rng.integers(2, 8))), park_p=float(rng.uniform(0.2, 0.95)),
                tree_scale=float(rng.uniform(0.7, 1.4)), street_trees=float(rng.uniform(0.0, 1.0)), verge_m=verge,
                setback_m=float(rng.uniform(1.5, 7.0)) if rng.random() < 0.6 else 0.0,
                hedges=float(rng.uniform(0.3, 1.0)),
                lane_m=float(rng.uniform(2.9, 3.6)), park_m=float(rng.uniform(1.9, 2.6)), sidewalk_m=sidewalk)
    if tall_hedges:
        v.hedge_m = float(rng.uniform(0.6, 3.0))  # drawn last: the knobs above stay what they were for every seed
    return v

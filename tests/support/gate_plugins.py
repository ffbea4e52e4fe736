"""A stand-in step with quality gates (loaded with TWINKIT_PLUGIN_MODULES=...,tests.support.gate_plugins)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from twinkit import hookimpl
from twinkit.ranges import param


@dataclass
class GaugeParams:
    need: float = param(50.0, help="the 'cover' gate's threshold, %")
    warn: bool = param(False, help="log a plain warning (not a degraded result)")
    no_roads: bool = param(False, help="note that the twin has no road network")
    gates: bool = param(True, help="declare the two gates")


def gauge(params: GaugeParams, ctx, *, in_data_txt: Path, out_gauge_txt: Path) -> dict:
    """Two gates on the number: 'cover' (value x 40 %, >= need) and 'hole' (0.1 m, <= 0.25 m)."""
    v = int(Path(in_data_txt).read_text().splitlines()[0])
    out_gauge_txt.write_text(f"{v}\n")
    if params.gates:
        ctx.gate("cover", 40.0 * v, params.need, ">=", "%", why="the twin must cover the street",
                 hint="try steps.make.value=3")
        ctx.gate("hole", 0.1, 0.25, "<=", "m", why="a wheel drops into a wider hole")
    if params.warn:
        ctx.log.warning("the kerb is %d cm lower than expected", 7)
    if params.no_roads:
        ctx.note("no road network")
    return {"value": v}


@hookimpl
def twinkit_register_steps(register):
    register("gauge", gauge, params=GaugeParams)

"""The package checker's signal rules (contract_signals.py): light groups, conflicting greens, heights, sign types.

Each rule follows CARLA 0.9.16's source, emulated offline by twinkit.street.lights (MapBuilder.cpp
SolveControllerAndJuntionReferences / ComputeSignalTransform; TrafficLightManager.cpp RegisterLightComponent,
SpawnTrafficLights, SpawnSignals; TrafficLightGroup.cpp NextController; SignalType.cpp). Fixtures: the demo
junction as netconvert writes it today, and as place_signals writes it now (tests/street/fixtures).
"""
from __future__ import annotations

import gzip
from pathlib import Path

import pytest

from twinkit_export.carla_contract import RULES, ContractReport
from twinkit_export.contract_signals import check_signals

ROOT = Path(__file__).resolve().parents[3]
FIX = ROOT / "tests" / "street" / "fixtures"
SHARED = ROOT.parent / "shared" / "data" / "opendrive"


def xodr(tmp_path: Path, name: str) -> Path:
    p = tmp_path / name.replace(".gz", "")
    p.write_bytes(gzip.decompress((FIX / name).read_bytes()))
    return p


def rules(rep) -> set[str]:
    return {v.rule for v in rep.violations}


def test_rules_cite_carla_sources():
    for r in ("light_groups", "conflicting_greens", "signal_heights", "sign_types"):
        assert r in RULES and ".cpp" in RULES[r][1]


def test_todays_netconvert_junction_fails_groups_greens_and_heights(tmp_path):
    rep = ContractReport("t")
    out = check_signals(rep, [xodr(tmp_path, "netconvert_junction.xodr.gz")])
    assert {"light_groups", "conflicting_greens", "signal_heights"} <= rules(rep)
    summary = out["netconvert_junction.xodr"]
    assert summary["junctions"]["1"]["groups"] == 14 and summary["problems"]["conflicting_greens"] > 0
    assert any("stacked" in v.message for v in rep.violations)  # 14 lights at 4 poles


def test_twinkit_junction_passes(tmp_path):
    rep = ContractReport("t")
    out = check_signals(rep, [xodr(tmp_path, "twinkit_junction.xodr.gz")])
    assert rep.violations == []
    assert out["twinkit_junction.xodr"]["junctions"]["1"]["groups"] == 1


def test_sign_types_and_heights(tmp_path):
    text = gzip.decompress((FIX / "twinkit_junction.xodr.gz").read_bytes()).decode()
    sigs = ('<signal id="sp" s="5" t="-4" zOffset="0" orientation="+" dynamic="no" type="274" subtype="-1"/>'
            '<signal id="st" s="6" t="-4" zOffset="2.5" orientation="+" dynamic="no" type="206" subtype="-1"/>'
            '<signal id="gen" s="7" t="-4" zOffset="2.5" orientation="+" dynamic="no" type="-1" subtype="-1"/>')
    text = text.replace("<signals>", "<signals>" + sigs, 1)
    p = tmp_path / "m.xodr"
    p.write_text(text)
    rep = ContractReport("t")
    out = check_signals(rep, [p])
    msgs = " ".join(v.message for v in rep.violations)
    assert {"sign_types", "signal_heights"} <= rules(rep) and "speed limit sp" in msgs and "stop sign st" in msgs
    assert "gen" not in msgs and out["m.xodr"]["generic_signs"] == 1  # generic plates are counted, not refused


@pytest.mark.parametrize("town", ["Town10HD.xodr", "Town01.xodr"])
def test_carla_towns_have_one_group_per_junction_and_no_conflicting_greens(town):
    if not (SHARED / town).is_file():
        pytest.skip(f"{SHARED / town} not present")
    rep = ContractReport("t")
    check_signals(rep, [SHARED / town])
    assert not {"light_groups", "conflicting_greens"} & rules(rep), [str(v) for v in rep.violations]

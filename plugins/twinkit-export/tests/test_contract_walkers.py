"""The checker's crosswalk rule (contract_walkers): CARLA's navmesh gets its crosswalk areas from the
OpenDRIVE (Util/DockerUtils/dist/build.sh runs get_xodr_crosswalks.py on carla.Map.get_crosswalks and
addOBJ.py folds them into the navmesh OBJ); emulated with the carla wheel on small maps."""
from __future__ import annotations

import json

from twinkit_export.carla_contract import ContractReport, check_package
from twinkit_export.contract_walkers import check_crosswalks, navmesh_crosswalks

LANES = """<lanes><laneSection s="0">
  <left><lane id="1" type="driving" level="false"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane></left>
  <center><lane id="0" type="none" level="false"/></center>
  <right><lane id="-1" type="driving" level="false"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane></right>
</laneSection></lanes>"""


def xodr(objects: str = "") -> str:
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<OpenDRIVE><header revMajor="1" revMinor="4" name="" version="1.00"/>
<road name="A" length="60.0" id="1" junction="-1">
  <planView><geometry s="0" x="0" y="0" hdg="0" length="60.0"><line/></geometry></planView>
  {LANES}{objects}
</road>
</OpenDRIVE>
"""


def crosswalk(s: float, closed: bool = True, corner: str = "cornerLocal") -> str:
    uv = [(-1.5, -3.25), (1.5, -3.25), (1.5, 3.25), (-1.5, 3.25)] + ([(-1.5, -3.25)] if closed else [])
    if corner == "cornerLocal":
        pts = "".join(f'<cornerLocal u="{u}" v="{v}" z="0"/>' for u, v in uv)
    else:
        pts = "".join(f'<cornerRoad s="{s + u}" t="{v}" dz="0" height="0"/>' for u, v in uv)
    return (f'<object id="{int(s)}" name="Crosswalk" s="{s}" t="0" zOffset="0" hdg="0" orientation="none" '
            f'type="crosswalk" width="6.5" length="3"><outline>{pts}</outline></object>')


def package(tmp_path, text: str):
    pkg = tmp_path / "Import" / "DemoTwin"
    pkg.mkdir(parents=True)
    (pkg / "Demo.xodr").write_text(text)
    (pkg / "DemoTwin.json").write_text(json.dumps({"maps": [{"name": "Demo", "source": "./Demo.fbx",
                                                              "xodr": "./Demo.xodr", "use_carla_materials": True}],
                                                    "props": []}))
    return pkg


def rule_messages(rep) -> list[str]:
    return [v.message for v in rep.violations if v.rule == "crosswalks"]


def test_no_crosswalk_in_the_map_fails_where_the_street_has_zebras(tmp_path):
    pkg = package(tmp_path, xodr())  # today's package: netconvert writes no crosswalk
    rep = ContractReport("DemoTwin")
    assert check_crosswalks(rep, pkg, [{"name": "Demo", "xodr": "./Demo.xodr"}], expect=4) == {"Demo": 0}
    assert any("reports 0 crosswalks, the scan and OSM show 4" in m for m in rule_messages(rep))
    # through check_package: the rule runs, its source cited
    rep = check_package(tmp_path, "DemoTwin", expect_crosswalks=4)
    v = [v for v in rep.violations if v.rule == "crosswalks"]
    assert v and "get_xodr_crosswalks.py" in v[0].source and rep.summary()["crosswalks"] == {"Demo": 0}


def test_four_closed_crosswalks_pass_and_reach_the_navmesh(tmp_path):
    text = xodr("<objects>" + "".join(crosswalk(s) for s in (10, 20, 30, 40)) + "</objects>")
    nav = navmesh_crosswalks(text)
    assert nav.error == "" and len(nav.outlines) == 4 and nav.triangles == 8
    package(tmp_path, text)
    rep = check_package(tmp_path, "DemoTwin", expect_crosswalks=4)
    assert rule_messages(rep) == [] and rep.crosswalks == {"Demo": 4}


def test_unclosed_outline_breaks_the_navmesh_script(tmp_path):
    nav = navmesh_crosswalks(xodr("<objects>" + crosswalk(10, closed=False) + "</objects>"))
    assert "IndexError" in nav.error
    pkg = package(tmp_path, xodr("<objects>" + crosswalk(10, closed=False) + "</objects>"))
    rep = ContractReport("DemoTwin")
    check_crosswalks(rep, pkg, [{"name": "Demo", "xodr": "./Demo.xodr"}])
    assert any("IndexError" in m for m in rule_messages(rep))


def test_corner_road_outline_is_read_as_nothing(tmp_path):
    pkg = package(tmp_path, xodr("<objects>" + crosswalk(10, corner="cornerRoad") + "</objects>"))
    rep = ContractReport("DemoTwin")
    assert check_crosswalks(rep, pkg, [{"name": "Demo", "xodr": "./Demo.xodr"}]) == {"Demo": 0}
    assert any("without cornerLocal" in m for m in rule_messages(rep))


def test_carlas_own_town10_passes():
    from pathlib import Path

    import pytest

    f = (Path(__file__).parent / "../../../../shared/data/opendrive/Town10HD.xodr").resolve()
    if not f.is_file():
        pytest.skip(f"shared sample data absent: {f}")
    nav = navmesh_crosswalks(f.read_text())
    # CARLA's own map: 16 crosswalk objects, each a closed quadrilateral, a fan of 2 triangles
    assert nav.error == "" and len(nav.outlines) == 16 and nav.triangles == 32

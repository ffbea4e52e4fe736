"""Issue 47, case 5: a hand edit of alignment.json shifts the map under the scanned signals; a light defined
on the next road then falls before that road's start, which carla.Map refuses ("s_position >= 0.0"). Each
signal is moved onto its road with a warning naming it, the move and the road; a map that still does not
parse stops with the file's path and the fix (docs/engine.md "Faults", "Bad input")."""
from __future__ import annotations

import json
import logging
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from test_signals import carla_landmarks, scene, xodr

import twinkit_roads.plugin as roads
from twinkit_roads.align import transform_xodr


def _inputs(tmp_path, text: str, light=(50.4, -8.0)) -> dict:
    from twinkit.mesh import write_colored_ply

    V, L = scene(light=light)
    write_colored_ply(tmp_path / "textured_mesh.ply", V, np.array([[0, 1, 2]]), np.full((len(V), 3), 128, np.uint8))
    np.save(tmp_path / "labels.npy", L.astype(np.uint8))
    (tmp_path / "aligned.xodr").write_text(text)
    (tmp_path / "alignment.json").write_text(json.dumps({"yaw_deg": 0.0, "tx_m": 0.5, "ty_m": 0.0, "dz_m": 0.0}))
    return {"in_aligned_xodr": tmp_path / "aligned.xodr", "in_textured_mesh_ply": tmp_path / "textured_mesh.ply",
            "in_labels_npy": tmp_path / "labels.npy", "in_alignment_json": tmp_path / "alignment.json"}


def _place(tmp_path, inputs):
    from twinkit.testing import plugin_from_module, run_step

    return run_step(plugin_from_module(roads, "step", "place_signals"), tmp_path / "run", inputs)


def test_a_light_before_its_roads_start_after_a_shift_is_moved_onto_the_road(tmp_path, caplog):
    # the scanned head stands 0.6 m past road 1's end; the map moved 0.5 m along x (alignment.json's tx_m
    # edited by hand, as apply_alignment moves it) leaves it 0.1 m into road 2, where the light is written
    # 0.25 m back along its heading (CARLA moves it forward again): s = -0.155 on road 2
    shifted = transform_xodr(xodr(), 0.0, 0.5, 0.0, 0.0)
    with caplog.at_level(logging.WARNING):
        out = _place(tmp_path, _inputs(tmp_path, shifted))
    text = out["aligned.xodr"].read_text()
    root = ET.fromstring(text)
    sig = root.find(".//road[@id='2']/signals/signal[@id='3_0']")
    assert sig is not None and float(sig.get("s")) == 0.0
    warned = [r.getMessage() for r in caplog.records if r.getMessage().startswith("signal 3_0 on road 2")]
    assert warned and "0.155 m before the start" in warned[0] and "alignment.json" in warned[0], warned
    lms, _ = carla_landmarks(text)  # parses: the light is where CARLA puts a signal at s = 0
    doc = json.loads(out["signals.json"].read_text())
    rec = next(s for s in doc["signals"] if s["id"] == "3_0")
    assert rec["s"] == 0.0 and "moved 0.155 m onto road 2" in rec["note"]
    loc = lms["3_0"].transform.location  # CARLA's frame: y = -north
    assert np.hypot(loc.x - 50.6, -loc.y + 8.0) < 0.2  # within the move of the scanned head (x 50.6)


def test_a_map_that_still_does_not_parse_names_the_file_and_the_fix(tmp_path):
    from twinkit import InputError

    broken = xodr().replace('s="50.0" t="-1.625"', 's="nan" t="-1.625"')  # a careless hand edit of the map
    inputs = _inputs(tmp_path, broken, light=None)
    with pytest.raises(InputError) as err:
        _place(tmp_path, inputs)
    msg = str(err.value)
    assert msg.startswith(f"{tmp_path / 'aligned.xodr'}: ") and "\n" not in msg
    assert "s_position >= 0.0" in msg
    assert f"if you edited {tmp_path / 'alignment.json'} by hand, undo that edit or re-run align_roads" in msg

"""A photo set without GPS: hints that name keys that work, a scale that the metric thresholds follow, units
that say "model units" until a scale is known, COLMAP's log in run.log (issue 46, item 6)."""
from __future__ import annotations

import ast
import json
import logging
import re
from pathlib import Path

import numpy as np
import pytest

from twinkit.testing import make_context, plugin_from_module, run_step

import twinkit_photo.plugin as photo

PKG = Path(photo.__file__).parent
REPO = PKG.parents[2]
STEPS = ("sfm", "georeference", "roi", "dense", "photo_texture")
FILE_EXT = ("json", "ply", "npz", "py", "png", "obj", "txt", "html")


def _strings() -> list[tuple[str, str]]:
    """Every string literal (f-string parts included) of the plugin's modules, with its file name."""
    out = []
    for f in sorted(PKG.glob("*.py")):
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                out.append((f.name, node.value))
    return out


def _hinted_keys() -> dict[str, str | None]:
    """{key: value or None} for every ``steps.<step>.<param>`` and ``site.<key>`` the plugin's texts name."""
    keys: dict[str, str | None] = {}
    pat = re.compile(r"(?<![\w/.])((?:steps\.[a-z_]+\.[a-z_]+)|(?:site\.[a-z_]+(?:\.[a-z_]+)?))(=[\w.\-:]+)?")
    for _name, text in _strings():
        for m in pat.finditer(text):
            key = m.group(1)
            if key.rsplit(".", 1)[-1] in FILE_EXT:
                continue
            value = m.group(2)[1:] if m.group(2) else None
            complete = value and not value.startswith("<") and not value.endswith(":")  # else an f-string's part
            keys.setdefault(key, value if complete else None)
    return keys


def _sample(key: str) -> str:
    """A value of the right type and range for a key the hints name without one."""
    from dataclasses import fields

    if key.startswith("site."):
        return {"site.crs": "EPSG:32614", "site.base_point": "{lat:19.43,lon:-99.13,alt:2240.0}"}.get(key, "x.json")
    _, step, name = key.split(".")
    f = {f.name: f for f in fields(_params(step))}[name]
    default = f.default_factory() if callable(f.default_factory) else f.default
    if isinstance(default, bool):
        return "true"
    if isinstance(default, list):
        return "[" + ",".join(["1.0"] * {"up_model": 3, "distance_points_model": 6}.get(name, 16)) + "]"
    return str(default)  # the default: in range


def _params(step: str):
    return {"sfm": photo.SfmParams, "georeference": photo.GeorefParams, "roi": photo.RoiParams,
            "dense": photo.DenseParams, "photo_texture": photo.PhotoTextureParams}[step]


def test_no_hint_names_a_bare_step_key():
    """``georeference.scale`` is refused by Hydra (Key 'georeference' not in 'TwinkitBase'): every hint names
    ``steps.<step>.<param>``."""
    bare = re.compile(r"(?<![\w/.])(" + "|".join(STEPS) + r")\.(?!(?:" + "|".join(FILE_EXT) + r")\b)([a-z_]+)")
    json_fields = ("dense.valid_ratio", "dense.per_photo")  # report.py names points_meta.json's fields
    found = [(name, m.group(0)) for name, text in _strings() for m in bare.finditer(text)
             if m.group(0) not in json_fields]
    assert not found, f"hints naming keys Hydra refuses: {found}"


def test_every_key_the_hints_name_is_accepted_by_the_config():
    from twinkit.config import check_config
    from twinkit.hydra_glue import compose, open_site_inputs, plain, register_configs
    from twinkit.plugins import get_registry

    keys = _hinted_keys()
    assert "steps.georeference.scale" in keys and "steps.georeference.distance_m" in keys
    registry = get_registry()
    register_configs(registry)
    for key, value in sorted(keys.items()):
        override = f"{key}={value if value is not None else _sample(key)}"
        cfg = compose(REPO / "conf", open_site_inputs(["recipe=image_site", "site=mex", override]))  # as the CLI
        check_config(plain(cfg, resolve=False), registry)


# --------------------------------------------------------------------------- a scale given: thresholds in metres

def _far_facade_model(tmp_path, unit_m: float) -> Path:
    """sfm/ of cameras walking 10 m along a square, 1.6 m high, looking at a 35 m high facade 60 m away;
    the model in units of ``unit_m`` metres."""
    n = 8
    R_wc = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], float)
    C = np.c_[np.linspace(-5, 5, n), np.zeros(n), np.full(n, 1.6)]
    rng = np.random.default_rng(1)
    ground = np.c_[rng.uniform(-15, 15, 400), rng.uniform(-5, 15, 400), np.zeros(400)]
    facade = np.c_[rng.uniform(-30, 30, 900), np.full(900, 60.0), rng.uniform(0, 35, 900)]
    pts = np.vstack([ground, facade]) / unit_m
    d = tmp_path / "sfm"
    d.mkdir()
    cams = [{"image": f"{k:02d}.jpg", "model": "PINHOLE", "width": 640, "height": 480,
             "params": [800, 800, 320, 240], "K": [[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]],
             "R_world_from_camera": R_wc.tolist(), "center": (c / unit_m).tolist()} for k, c in enumerate(C)]
    (d / "cameras_model.json").write_text(json.dumps({"cameras": cams, "exif_gps": {}}))
    np.savez_compressed(d / "sparse.npz", xyz=pts, rgb=np.zeros((len(pts), 3), np.uint8), error=np.zeros(len(pts)),
                        vis_image=np.array([], str), vis_point=np.array([], np.int64))
    return d


def _roi(tmp_path, scale: float) -> tuple[dict, list[str]]:
    sfm_dir = _far_facade_model(tmp_path, unit_m=5.0)
    g = run_step(plugin_from_module(photo, "step", "georeference"), tmp_path / "g", {"in_sfm_dir": sfm_dir},
                 photo.GeorefParams(method="none", scale=scale, vertical_lines=False, eye_height_m=0.0),
                 site={"name": "t"})
    r = run_step(plugin_from_module(photo, "step", "roi"), tmp_path / "r",
                 {"in_cameras_site_json": g["cameras_site.json"], "in_sparse_site_ply": g["sparse_site.ply"]},
                 photo.RoiParams())
    return json.loads(r["roi.json"].read_text()), []


def test_a_given_scale_keeps_a_far_tall_facade_inside_the_region_of_interest(tmp_path):
    """Scaled to metres (steps.georeference.scale=5), a 35 m facade 60 m from the walk: the box reaches its
    top and the depth limit reaches it (main: max_depth_m 40 m cut it off and the box stopped 25 m up)."""
    doc, _ = _roi(tmp_path, scale=5.0)
    assert doc["scaled"] is True and doc["units"] == "metres"
    ground = doc["ground"]["z_m"]
    assert doc["box"]["max"][2] - ground >= 33.0
    assert doc["box"]["max"][1] >= 59.0
    assert doc["max_depth_m"] >= 60.0
    assert "raised" in doc["max_depth_from"]


def test_an_unscaled_region_of_interest_says_model_units(tmp_path):
    doc, _ = _roi(tmp_path, scale=1.0)
    assert doc["scaled"] is False
    assert "metres" not in doc["_comment"] and "metres" not in doc["units"].replace("model units", "")


def test_most_photos_missing_the_mesh_degrade_the_run(tmp_path):
    from types import SimpleNamespace

    ctx = make_context(tmp_path / "w", site={"name": "t"})
    views = [SimpleNamespace(name=f"{k:02d}.jpg") for k in range(10)]
    info = {"best_view_faces": {"00.jpg": 500, "01.jpg": 20, "02.jpg": 3, "03.jpg": 1}}
    photo._missing_photos_gate(ctx, photo.PhotoTextureParams(), views, info)
    assert info["photos_missing_mesh"] == 6 and info["photos_missing_mesh_ratio"] == 0.6
    reasons = ctx.degraded_reasons
    assert reasons and "6 of 10 photos miss the mesh" in str(reasons[0])


def test_colmaps_log_goes_to_the_run_log_not_the_console(tmp_path, capfd):
    pycolmap = pytest.importorskip("pycolmap")
    from twinkit_photo.sfm import colmap_log_into

    log = logging.getLogger("twinkit.test_colmap_log")
    log.setLevel(logging.DEBUG)
    got: list[logging.LogRecord] = []

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            got.append(record)

    handler = Keep()
    log.addHandler(handler)
    try:
        with colmap_log_into(log, tmp_path):
            pycolmap.logging.info("Registering image #8 of the test")
    finally:
        log.removeHandler(handler)
    assert "Registering image #8" not in capfd.readouterr().err
    debug = [r.getMessage() for r in got if r.levelno == logging.DEBUG]
    assert any("Registering image #8" in m for m in debug)
    assert any("COLMAP's log (" in r.getMessage() for r in got if r.levelno == logging.INFO)

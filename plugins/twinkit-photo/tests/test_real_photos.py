"""Structure from motion on the real photo sets in ../shared (skipped without them).

Downscaled (fewer features, smaller images) so that both sets run in about a minute and a half on
2 cores; the full-size numbers are in docs/photo.md and bench/bench_photo.py.
"""
from __future__ import annotations

import json

import pytest

from twinkit import InputError
from twinkit.testing import check_plugin, plugin_from_module, run_step

import twinkit_photo.plugin as photo

from conftest import shared_photos

pytestmark = pytest.mark.shared


def _sfm():
    return plugin_from_module(photo, "step", "sfm")


def test_contracts():
    for name in ("sfm", "georeference", "roi", "dense", "photo_texture"):
        check_plugin(plugin_from_module(photo, "step", name))


def test_sceaux_registers_all_11(tmp_path):
    folder = shared_photos("sceaux_castle")
    out = run_step(_sfm(), tmp_path / "run", {"in_photos_dir": folder},
                   photo.SfmParams(max_image_px=800, max_features=2048))
    rep = json.loads(out["sfm_report.json"].read_text())
    assert rep["registered"] == 11 and rep["photos"] == 11
    assert rep["intrinsics_from"] == "K.txt"
    assert rep["mean_reprojection_error_px"] < 1.5
    assert (out["sfm"] / "cameras.bin").exists() and (out["sfm"] / "sparse.npz").exists()


def test_lund_walk_registers_at_least_25_of_29(tmp_path):
    folder = shared_photos("lund_street")
    out = run_step(_sfm(), tmp_path / "run", {"in_photos_dir": folder},
                   photo.SfmParams(max_features=4096, matching="exhaustive"))
    rep = json.loads(out["sfm_report.json"].read_text())
    assert rep["photos"] == 29 and rep["photos_with_gps"] == 29
    assert rep["registered"] >= 25, rep["attempts"]
    # georeference from EXIF GPS: Lund's base point, a local transverse Mercator frame
    site = {"name": "lund", "crs": "EPSG:4326", "base_point": {"lat": 55.6982, "lon": 13.1954, "alt": 0.0}}
    geo = run_step(plugin_from_module(photo, "step", "georeference"), tmp_path / "geo",
                   {"in_sfm_dir": out["sfm"]}, photo.GeorefParams(), site=site)
    g = json.loads(geo["georef.json"].read_text())
    assert g["method"] == "gps"
    assert g["gps"]["inliers"] >= 10, g["gps"]  # phone GPS along a 100 m walk: about half the fixes within 8 m
    assert g["gps"]["rmse_m"] < 8.0  # phone GPS: metres
    assert 0.01 < g["transform"]["scale"] < 100


def test_too_few_registered_is_a_clear_error(tmp_path):
    """Two photos of the set that do not overlap: nothing (or too little) registers."""
    import shutil

    folder = shared_photos("lund_street")
    few = tmp_path / "few"
    few.mkdir()
    for name in ("01.jpg", "29.jpg"):
        shutil.copy(folder / name, few / name)
    with pytest.raises(InputError, match="few"):
        run_step(_sfm(), tmp_path / "run", {"in_photos_dir": few}, photo.SfmParams(max_features=1024))
    assert not (tmp_path / "run" / "result").exists()


def test_portrait_and_landscape_photos_register_together(tmp_path):
    """A phone set that mixes orientations: each image size gets its own camera (intrinsics), nothing is dropped.
    Before camera groups, COLMAP's single-camera mode skipped every photo whose size differed from the first."""
    from PIL import Image

    folder = shared_photos("lund_street")
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    for k in range(1, 11):
        name = f"{k:02d}.jpg"
        with Image.open(folder / name) as im:
            exif = im.info.get("exif", b"")
            if k in (3, 6, 9):  # turned to portrait: the pixels themselves, as a phone held upright writes them
                im = im.transpose(Image.Transpose.ROTATE_90)
            im.save(mixed / name, quality=95, exif=exif)
    out = run_step(_sfm(), tmp_path / "run", {"in_photos_dir": mixed},
                   photo.SfmParams(max_features=2048, matching="exhaustive"))
    rep = json.loads(out["sfm_report.json"].read_text())
    groups = {tuple(g["size"]): g for g in rep["camera_groups"]}
    assert set(groups) == {(1024, 768), (768, 1024)} and groups[(768, 1024)]["photos"] == 3
    assert len(rep["cameras"]) == 2
    assert rep["registered"] >= 9, rep
    assert groups[(768, 1024)]["registered"] >= 2, rep["camera_groups"]

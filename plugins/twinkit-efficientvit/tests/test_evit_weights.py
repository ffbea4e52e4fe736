"""Clear errors for missing or corrupt weights files; default-path search."""
from __future__ import annotations

import shutil

import pytest

from twinkit.errors import InputError

pytest.importorskip("torch")

from twinkit_efficientvit.efficientvit import WEIGHTS_FILE, EfficientViTParams, build_efficientvit  # noqa: E402


def test_missing_explicit_path(tmp_path):
    missing = tmp_path / "nope" / WEIGHTS_FILE
    with pytest.raises(InputError) as err:
        build_efficientvit(EfficientViTParams(weights_path=str(missing)))
    msg = str(err.value)
    assert str(missing) in msg and "weights_path" in msg and "han-cai/efficientvit-seg" in msg


def test_missing_in_default_folders(tmp_path, monkeypatch):
    monkeypatch.setenv("TWINKIT_MODELS_DIR", str(tmp_path))
    with pytest.raises(InputError) as err:
        build_efficientvit(EfficientViTParams())
    msg = str(err.value)
    assert WEIGHTS_FILE in msg and str(tmp_path) in msg and "TWINKIT_MODELS_DIR" in msg
    assert "download_if_missing" in msg


def test_corrupt_file_in_default_folder_fails_sha256(tmp_path, monkeypatch):
    (tmp_path / WEIGHTS_FILE).write_bytes(b"not a checkpoint" * 100)
    monkeypatch.setenv("TWINKIT_MODELS_DIR", str(tmp_path))
    with pytest.raises(InputError, match="corrupt or not the expected file") as err:
        build_efficientvit(EfficientViTParams())
    assert str(tmp_path / WEIGHTS_FILE) in str(err.value)


def test_corrupt_explicit_file_is_named(tmp_path):
    bad = tmp_path / "weights.pt"
    bad.write_bytes(b"\x00garbage" * 1000)
    with pytest.raises(InputError, match="could not be read as a PyTorch checkpoint") as err:
        build_efficientvit(EfficientViTParams(weights_path=str(bad)))
    assert str(bad) in str(err.value)


def test_truncated_real_file(tmp_path, evit_weights):
    bad = tmp_path / WEIGHTS_FILE
    bad.write_bytes(evit_weights.read_bytes()[:1_000_000])
    with pytest.raises(InputError, match="could not be read"):
        build_efficientvit(EfficientViTParams(weights_path=str(bad)))
    # with the official hash asked for explicitly, the check fires before torch.load
    from twinkit_efficientvit.efficientvit import WEIGHTS_SHA256

    with pytest.raises(InputError, match="sha256"):
        build_efficientvit(EfficientViTParams(weights_path=str(bad), weights_sha256=WEIGHTS_SHA256))


def test_folder_path_and_env_var(tmp_path, monkeypatch, evit_weights):
    shutil.copy(evit_weights, tmp_path / WEIGHTS_FILE)
    model = build_efficientvit(EfficientViTParams(weights_path=str(tmp_path), device="cpu"))
    assert model.weights_path == tmp_path / WEIGHTS_FILE
    monkeypatch.setenv("TWINKIT_MODELS_DIR", str(tmp_path))
    model = build_efficientvit(EfficientViTParams(device="cpu"))
    assert model.weights_path == tmp_path / WEIGHTS_FILE
    assert model.batch_size == 1  # batch_size=0: automatic, 1 on CPU


def test_default_search_finds_shared_from_other_cwd(tmp_path, monkeypatch, evit_weights):
    """From a cwd without ../shared, the repo root found from the package location still works."""
    from twinkit_efficientvit.weights import candidate_dirs

    monkeypatch.delenv("TWINKIT_MODELS_DIR", raising=False)
    monkeypatch.chdir(tmp_path)
    assert evit_weights.parent.resolve() in candidate_dirs()
    assert build_efficientvit(EfficientViTParams(device="cpu")).weights_path.resolve() == evit_weights.resolve()


def test_wrong_checkpoint_fails_strict(tmp_path):
    import torch

    bad = tmp_path / "other.pt"
    torch.save({"state_dict": {"backbone.foo": torch.zeros(1)}}, bad)
    with pytest.raises(InputError, match="does not fit EfficientViT-Seg-B0"):
        build_efficientvit(EfficientViTParams(weights_path=str(bad)))


def test_download_path_with_a_file_url(tmp_path, monkeypatch, evit_weights):
    """The download code (urllib branch) with a file:// URL; real HTTPS is not reachable here."""
    from twinkit_efficientvit.efficientvit import WEIGHTS_SHA256
    from twinkit_efficientvit.weights import download

    monkeypatch.setenv("TWINKIT_MODELS_DIR", str(tmp_path))
    got = download(WEIGHTS_FILE, evit_weights.resolve().as_uri(), WEIGHTS_SHA256)
    assert got == tmp_path / WEIGHTS_FILE and got.stat().st_size == evit_weights.stat().st_size
    got.unlink()
    with pytest.raises(InputError, match="sha256 does not match"):
        download(WEIGHTS_FILE, evit_weights.resolve().as_uri(), "0" * 64)
    assert (tmp_path / (WEIGHTS_FILE + ".bad")).is_file() and not (tmp_path / WEIGHTS_FILE).exists()
    with pytest.raises(InputError, match="could not download"):
        download(WEIGHTS_FILE, (tmp_path / "absent.pt").as_uri(), WEIGHTS_SHA256)
    assert not list(tmp_path.glob("*.part"))

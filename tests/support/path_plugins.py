"""Plugins whose parameters name input files (``param(path=...)``), for tests/test_faults_edits.py: a step that
reads the file its ``path`` names, and an image model whose ``weights_path`` a step reads."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from twinkit import InputError, hookimpl
from twinkit.ranges import param

from tests.support.engine_plugins import _count


@dataclass
class NamedParams:
    path: str = param("", path=True, help="The file to copy (a map, say).")


def read_named(params: NamedParams, ctx, *, out_named_txt: Path) -> None:
    """Copy the file ``path`` names."""
    _count("read_named")
    if not Path(params.path).is_file():
        raise InputError(f"{params.path} does not exist; set steps.read_named.path to a file")
    out_named_txt.write_text(Path(params.path).read_text())


@dataclass
class ToyModelParams:
    weights_path: str = param("", path=True, help="The weights: a file, or a folder of files.")


def toy_model(params: ToyModelParams):
    return params


def predict(params, ctx, *, out_predicted_txt: Path) -> None:
    """Write what the image model's weights hold (a folder's files joined)."""
    _count("predict")
    w = Path(ctx.config["image_model"]["weights_path"])
    files = sorted(w.iterdir()) if w.is_dir() else [w]
    out_predicted_txt.write_text("".join(f.read_text() for f in files))


@hookimpl
def twinkit_register_image_models(register):
    register("toy_model", toy_model, params=ToyModelParams)


@hookimpl
def twinkit_register_steps(register):
    register("read_named", read_named, params=NamedParams)
    register("predict", predict, uses=("image_model",))

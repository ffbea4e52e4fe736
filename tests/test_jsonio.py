"""twinkit.jsonio: the JSON writer every step uses."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from twinkit.jsonio import write_json


def test_numpy_values_and_paths_become_plain_json(tmp_path):
    out = tmp_path / "m.json"
    write_json(out, {"b": np.float32(0.5), "a": np.arange(3), "p": Path("/x/y"), "n": np.int64(7)})
    text = out.read_text()
    assert json.loads(text) == {"a": [0, 1, 2], "b": 0.5, "n": 7, "p": "/x/y"}
    assert text.index('"a"') < text.index('"b"') and text.endswith("\n")  # sorted keys, one trailing newline
    assert [p.name for p in tmp_path.iterdir()] == ["m.json"]  # no temporary file left behind


def test_a_failed_write_keeps_the_old_file(tmp_path):
    out = tmp_path / "m.json"
    write_json(out, {"v": 1})

    class Boom:
        def __str__(self):
            raise RuntimeError("cannot serialise")

    try:
        write_json(out, {"v": Boom()})
    except RuntimeError:
        pass
    assert json.loads(out.read_text()) == {"v": 1}

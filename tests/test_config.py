"""Configuration helpers."""
from __future__ import annotations

import pytest
import yaml
import yaml.cyaml
from omegaconf import OmegaConf

from twinkit.hydra_glue import use_libyaml

DOC = """
a: 1
b: 1e3
c: 2001-01-01
d: [x, {y: .5}]
e: ${a}
"""


def test_libyaml_loader_keeps_omegaconf_semantics():
    from omegaconf import _utils

    pure = yaml.load(DOC, Loader=_utils.get_yaml_loader())
    assert use_libyaml()
    fast_cls = _utils.get_yaml_loader()
    assert issubclass(fast_cls, yaml.cyaml.CParser)
    assert yaml.load(DOC, Loader=fast_cls) == pure
    assert pure["b"] == 1000.0 and pure["c"] == "2001-01-01"  # OmegaConf's float rule; no timestamps
    with pytest.raises(yaml.constructor.ConstructorError, match="duplicate key"):
        yaml.load("a: 1\na: 2\n", Loader=fast_cls)
    assert OmegaConf.create(DOC).e == 1

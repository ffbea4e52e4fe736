from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="session")
def synth_cloud(tmp_path_factory) -> Path:
    """The synthetic street block as a site-frame PLY cloud with normals and colours."""
    from twinkit.mesh import Mesh, write_ply

    from twinkit_tiles.synthetic import street_block

    P, N, C = street_block(size_m=20.0, spacing_m=0.1)
    path = tmp_path_factory.mktemp("synth") / "cloud.ply"
    write_ply(path, Mesh(vertices=P, attrs={"normals": N, "colors": C}))
    return path


class Project:
    """A throw-away config folder (real config.yaml and tiled_site recipe + a site 'synth') and outputs."""

    def __init__(self, tmp: Path, cloud: Path):
        self.tmp = tmp
        self.conf = tmp / "conf"
        (self.conf / "site").mkdir(parents=True)
        (self.conf / "recipe").mkdir()
        shutil.copy(REPO / "conf" / "config.yaml", self.conf / "config.yaml")
        shutil.copy(REPO / "recipes" / "tiled_site.yaml", self.conf / "recipe" / "tiled_site.yaml")
        (self.conf / "site" / "synth.yaml").write_text(textwrap.dedent(f"""\
            name: synth
            inputs:
              cloud: {cloud}
            """))
        self.out = tmp / "outputs"

    def run(self, *args: str, timeout: float = 600) -> subprocess.CompletedProcess:
        env = dict(os.environ, TWINKIT_CONFIG_DIR=str(self.conf))
        cmd = [sys.executable, "-m", "twinkit", f"engine.outputs_dir={self.out}", *args]
        return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout, cwd=str(self.tmp))


@pytest.fixture
def project(tmp_path, synth_cloud) -> Project:
    return Project(tmp_path, synth_cloud)


HOLE = (5.0, -5.0, 1.2)  # an occlusion shadow inside one tile of the 2 x 2 grid


@pytest.fixture(scope="session")
def holed_cloud(tmp_path_factory) -> Path:
    """The synthetic block with a disc of ground left unscanned (``HOLE``)."""
    from twinkit.mesh import Mesh, write_ply

    from twinkit_tiles.synthetic import street_block

    P, N, C = street_block(size_m=20.0, spacing_m=0.1, ground_hole=HOLE)
    path = tmp_path_factory.mktemp("holed") / "cloud.ply"
    write_ply(path, Mesh(vertices=P, attrs={"normals": N, "colors": C}))
    return path

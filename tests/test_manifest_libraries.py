"""The manifest's library list comes from the loaded plugins' declared requirements."""
from __future__ import annotations

import importlib.metadata as md

import pytest

from twinkit.manifest import declared_libraries, library_versions


def _installed(name: str) -> bool:
    try:
        md.version(name)
        return True
    except md.PackageNotFoundError:
        return False


def test_the_core_alone_gives_its_own_requirements():
    names = declared_libraries(())
    assert names, "twinkit's own requirements were not found (is it installed?)"
    for base in ("hydra-core", "omegaconf", "pluggy", "numpy"):
        assert base in names
    assert "pyproj" not in names  # twinkit[geo] is asked for by no one here
    versions = library_versions(())
    assert versions["twinkit"] and versions["numpy"] == md.version("numpy")


@pytest.mark.skipif(not _installed("twinkit-pointcloud"), reason="needs the twinkit-pointcloud plugin installed")
def test_a_plugins_requirements_and_the_core_extras_it_asks_for():
    names = declared_libraries(("twinkit-pointcloud", "not-an-installed-distribution"))
    assert {"pye57", "laspy", "pymeshlab"} <= set(names)  # its requirements and its optional groups
    assert "pyproj" in names and "scipy" in names  # twinkit[geo,mesh], asked for by it
    assert "pytest" not in names  # its test group is a tool, not a library it runs with
    assert set(library_versions(("twinkit-pointcloud",))) <= {"twinkit", *names}

"""Session fixtures: the small demo site is generated once (shared with the other sessions of a ``make test``
run, twinkit.testing.shared_plugin_run); a sparser one twice, here, for the determinism test."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from twinkit.testing import run_plugin, shared_plugin_run

SITE = {"name": "demo", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 12.0}}


def out_kwargs(folder: Path) -> dict[str, Path]:
    from twinkit_demo_site.plugin import output_paths

    return output_paths(folder)


def _folder_and_metrics(out: dict[str, Path]) -> tuple[Path, dict]:
    folder = out["site.json"].parent
    return folder, json.loads((folder / "step.json").read_text())["metrics"]


@pytest.fixture(scope="session")
def demo(tmp_path_factory):
    """(folder, metrics) of the small preset, seed 0 (read-only files)."""
    return _folder_and_metrics(shared_plugin_run("site_generator", "demo_intersection", tmp_path_factory.mktemp("demo_a"),
                                                 site=dict(SITE), size="small", seed=0))


#: a sparser scan and fewer photos of the same site: cheap to make twice in a session (the determinism test)
SPARSE = {"size": "small", "seed": 0, "density_scale": 0.1, "photo_count": 3}


@pytest.fixture(scope="session")
def sparse_twice(tmp_path_factory):
    """The site with :data:`SPARSE`'s parameters generated twice here, each into a fresh folder."""
    return [_folder_and_metrics(run_plugin("site_generator", "demo_intersection", tmp_path_factory.mktemp(f"sparse_{k}"),
                                           site=dict(SITE), **SPARSE)) for k in "ab"]


@pytest.fixture(scope="session")
def site(demo):
    return json.loads((demo[0] / "site.json").read_text())


@pytest.fixture(scope="session")
def gt(demo):
    """Ground-truth mesh from gt_mesh.ply: vertices (n, 3), faces (m, 3), face labels, vertex labels, and a RaycastingScene."""
    import numpy as np
    import open3d as o3d
    from plyfile import PlyData

    ply = PlyData.read(str(demo[0] / "gt_mesh.ply"))
    v = np.stack([ply["vertex"][k] for k in "xyz"], 1).astype(np.float64)
    f = np.stack(ply["face"]["vertex_indices"]).astype(np.int64)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(v.astype(np.float32)), o3d.core.Tensor(f.astype(np.uint32)))
    return {"v": v, "f": f, "face_label": np.asarray(ply["face"]["label"]), "vertex_label": np.asarray(ply["vertex"]["label"]),
            "vertex_rgb": np.stack([ply["vertex"][k] for k in ("red", "green", "blue")], 1), "scene": scene}


@pytest.fixture(scope="session")
def cloud(demo):
    import numpy as np
    from plyfile import PlyData

    ply = PlyData.read(str(demo[0] / "cloud.ply"))
    el = ply["vertex"]
    return {"xyz": np.stack([el[k] for k in "xyz"], 1).astype(np.float64),
            "normals": np.stack([el[k] for k in ("nx", "ny", "nz")], 1),
            "rgb": np.stack([el[k] for k in ("red", "green", "blue")], 1),
            "label": np.asarray(el["label"]), "scanner": np.asarray(el["scanner"])}

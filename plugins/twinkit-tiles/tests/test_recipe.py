"""The tiled_site recipe end to end through the real ``twinkit`` command: local executor, and a real
Dask LocalCluster (loopback, two worker processes); both must give the same tiles and merged mesh."""
from __future__ import annotations

import json

import pytest

COARSE = ["steps.plan_tiles.tile_m=10", "steps.plan_tiles.overlap_m=1.5", "steps.plan_tiles.voxel_m=0.1",
          "steps.reconstruct_tile.max_dist_m=0.15", "steps.simplify.target_faces=20000",
          "steps.bake_texture.texture_px=256", "steps.evaluate_reconstruction.gt_samples=20000"]


def _record(project, folder):
    return json.loads((project.out / "synth" / folder / "step.json").read_text())


def _no_crack_inside(seams):
    """No open seam edge: the zipper closes the seams, and where the trim near the seams removes one
    tile's side (at the scan's outer edge, 10 m from the centre), the other tile's face hanging on
    the seam goes too, so the mesh's border crosses the seam instead of running along it."""
    assert seams["seam_boundary_edges_after"] == 0, seams["seam_open_runs"]
    assert seams["seam_open_runs"] == []


@pytest.fixture(scope="module")
def local_run(tmp_path_factory, synth_cloud):
    from conftest import Project

    p = Project(tmp_path_factory.mktemp("local"), synth_cloud)
    r = p.run("recipe=tiled_site", "site=synth", "executor=local", "executor.workers=2", *COARSE)
    assert r.returncode == 0, r.stderr[-3000:]
    return p


def test_local_run_is_complete_and_crack_free(local_run):
    ws = local_run.out / "synth"
    plan = json.loads((ws / "02_plan_tiles" / "tiles.json").read_text())
    assert len(plan["items"]) == 4 and plan["grid"]["nx"] == 2
    seams = json.loads((ws / "04_merge_tiles" / "tile_seams.json").read_text())
    assert seams["seam_boundary_edges_before"] > 0
    _no_crack_inside(seams)
    assert seams["faces_outside_core"] == 0
    # the open border near the seams, against lines half-way between them
    near = seams["open_near_lines"]
    assert near["seams"]["planes"] == 2 and near["controls"]["planes"] >= 2
    assert near["seams"]["section_m"] > 5 and near["controls"]["section_m"] > 5
    # every tile votes on the exact trim near its seams, on both sides of them
    import numpy as np

    z = np.load(ws / "03_reconstruct_tiles" / "000" / "seam_votes.npz")
    assert len(z["points"]) == len(z["keep"]) > 100 and z["keep"].any()
    assert "vertices_kept_by_votes" in seams["seam_band_trim"]
    assert seams["seam_band_trim"]["hanging_faces_removed"] > 0  # at the scan's outer edge
    per_item = _record(local_run, "03_reconstruct_tiles")["metrics"]["per_item"]
    assert len(per_item) == 4 and all(it["peak_rss_mb"] > 50 for it in per_item)
    assert (ws / "06_texture" / "textured_mesh.obj").exists()
    m = json.loads((ws / "07_evaluate" / "recon_metrics.json").read_text())
    assert m["cloud_to_mesh_m"]["median"] < 0.02


def test_dask_local_cluster_gives_the_same_result(local_run, tmp_path, synth_cloud):
    from conftest import Project

    p = Project(tmp_path, synth_cloud)
    r = p.run("recipe=tiled_site", "site=synth", "executor=dask", "executor.n_workers=2",
              "executor.memory_limit=3GiB", *COARSE)
    assert r.returncode == 0, r.stderr[-3000:]
    a, b = _record(local_run, "03_reconstruct_tiles"), _record(p, "03_reconstruct_tiles")
    assert a["item_keys"] == b["item_keys"]
    assert a["artefacts"] == b["artefacts"], "tile meshes differ between the local and the Dask executor"
    pids = {it["pid"] for it in b["metrics"]["per_item"]}
    assert len(pids) == 2, "items should run in two Dask worker processes"
    assert _record(local_run, "04_merge_tiles")["artefacts"] == _record(p, "04_merge_tiles")["artefacts"]
    # a second run reuses every tile (cache by key), whatever the executor
    r = p.run("recipe=tiled_site", "site=synth", "executor=dask", "executor.n_workers=2",
              "executor.memory_limit=3GiB", *COARSE)
    assert r.returncode == 0, r.stderr[-3000:]
    line = next(ln for ln in r.stderr.splitlines() if "03_reconstruct_tiles" in ln)
    assert " reused " in line, line


def test_multirun_of_the_tiled_recipe(project):
    # a multirun job runs in a joblib (loky) worker: its fan-out pool used to die at once with
    # "cannot find context for 'loky'" (BrokenProcessPool); the parameter varied is the fan-out step's
    coarse = [a for a in COARSE if not a.startswith("steps.reconstruct_tile.max_dist_m=")]
    r = project.run("-m", "recipe=tiled_site", "site=synth", "executor=local", "executor.workers=2", *coarse,
                    "steps.reconstruct_tile.max_dist_m=0.15,0.2")
    assert r.returncode == 0, r.stderr[-3000:]
    jobs = sorted((project.out / "synth" / "sweeps").glob("*/job*"))
    assert len(jobs) == 2
    for j in jobs:
        assert json.loads((j / "manifest.json").read_text())["status"] == "ok"
        rec = json.loads((j / "03_reconstruct_tiles" / "step.json").read_text())
        assert rec["metrics"]["computed"] == rec["metrics"]["items"] > 1


def test_dask_executor_preserves_order_and_reports_errors():
    from twinkit_tiles.dask_executor import DaskExecutor

    ex = DaskExecutor(n_workers=2, memory_limit="1GiB")
    assert list(ex.map(abs, [-3, 1, -2, 5])) == [3, 1, 2, 5]
    assert len(ex.last_workers) == 2 and all(w.startswith("tcp://127.0.0.1:") for w in ex.last_workers)
    with pytest.raises(TypeError):
        list(DaskExecutor(n_workers=1).map(abs, ["x"]))


def test_bad_plan_parameters_fail_with_the_key(tmp_path, synth_cloud):
    from conftest import Project

    p = Project(tmp_path, synth_cloud)
    r = p.run("recipe=tiled_site", "site=synth", *[c for c in COARSE if "voxel_m" not in c], "steps.plan_tiles.voxel_m=0")
    assert r.returncode == 2, r.stderr[-2000:]
    assert "voxel_m" in r.stderr
    r = p.run("recipe=tiled_site", "site=synth", *COARSE, "steps.plan_tiles.seam_search_m=5")
    assert r.returncode == 2 and "seam_search_m" in r.stderr and "overlap_m" in r.stderr, r.stderr[-2000:]


def test_tiles_simplified_before_merge_stay_crack_free_and_ground_is_filled(tmp_path, holed_cloud):
    """plan_tiles.target_faces shares a face budget between the tiles (each simplified after its cut,
    borders kept), the zipper still closes every seam, and the merge fills the ground's occlusion
    shadow over the whole site; with the fill off the shadow stays open."""
    import numpy as np
    from conftest import HOLE, Project
    from twinkit.mesh import read_ply
    from twinkit.surface.closest import Surface

    p = Project(tmp_path, holed_cloud)
    args = ["recipe=tiled_site", "site=synth", "executor=local", "executor.workers=2", *COARSE,
            "steps.plan_tiles.target_faces=24000"]
    r = p.run(*args)
    assert r.returncode == 0, r.stderr[-3000:]
    ws = p.out / "synth"
    plan = json.loads((ws / "02_plan_tiles" / "tiles.json").read_text())
    targets = [it["target_faces"] for it in plan["items"]]
    assert abs(sum(targets) - 24000) < 10 * len(targets)
    per_item = _record(p, "03_reconstruct_tiles")["metrics"]["per_item"]
    for it, t in zip(per_item, targets):
        assert it["cut_faces"] > t, "the test needs tiles larger than their share"
        assert it["faces"] <= 1.05 * t
    seams = json.loads((ws / "04_merge_tiles" / "tile_seams.json").read_text())
    assert seams["seam_boundary_edges_before"] > 0
    _no_crack_inside(seams)
    assert seams["ground_fill"]["filled_cells"] > 0
    centre = np.array([[HOLE[0], HOLE[1], 0.15 * np.sin(HOLE[0] / 3) * np.cos(HOLE[1] / 4)]])

    def gap_at_centre():
        m = read_ply(ws / "04_merge_tiles" / "clean_mesh.ply")
        return float(Surface(m.vertices, m.faces).distance(centre)[0])

    assert gap_at_centre() < 0.05
    r = p.run(*args, "steps.merge_tiles.fill_ground_cell_m=0")
    assert r.returncode == 0, r.stderr[-3000:]
    assert json.loads((ws / "04_merge_tiles" / "tile_seams.json").read_text())["ground_fill"] is None
    assert gap_at_centre() > 0.3


def test_unreadable_seam_votes_name_the_file(local_run, tmp_path):
    import logging

    from twinkit import InputError
    from twinkit_tiles.plugin import MergeTilesParams, merge_tiles

    ws = local_run.out / "synth"
    tiles = sorted((ws / "03_reconstruct_tiles").glob("*/tile_mesh.ply"))
    bad = tmp_path / "seam_votes.npz"
    bad.write_bytes(b"PK\x03\x04 not really a zip")
    votes = [p.with_name("seam_votes.npz") for p in tiles]
    votes[1] = bad

    class Ctx:
        log = logging.getLogger("test")
        threads = 1

    out = tmp_path / "clean_mesh.ply"
    out.write_text("previous result")
    with pytest.raises(InputError, match=r"seam_votes\.npz: cannot read the tile's seam votes.*re-run reconstruct_tiles"):
        merge_tiles(MergeTilesParams(), Ctx(), in_tiles_json=ws / "02_plan_tiles" / "tiles.json", in_tile_mesh_ply=tiles,
                    in_seam_votes_npz=votes, in_points_ply=ws / "01_read_cloud" / "points.ply",
                    out_clean_mesh_ply=out, out_tile_seams_json=tmp_path / "tile_seams.json")
    assert out.read_text() == "previous result"

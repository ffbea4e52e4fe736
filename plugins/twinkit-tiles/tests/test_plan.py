"""Grid planning and the memory model."""
from __future__ import annotations

import numpy as np
import pytest

from twinkit_tiles.tiling import choose_grid, estimate_tile_mb, in_box


def _xy(n=200_000, w=120.0, h=60.0, seed=0):
    rng = np.random.default_rng(seed)
    return np.c_[rng.uniform(0, w, n), rng.uniform(0, h, n)]


def test_fixed_tile_size_covers_the_site_with_open_outer_sides():
    grid, why = choose_grid(_xy(), 40.0, 2.0, 4.0, 0.03)
    tiles = grid.tiles()
    assert (why["nx"], why["ny"]) == (3, 2) and len(tiles) == 6
    first, last = tiles[0], tiles[-1]
    assert first["core"][0] is None and first["core"][1] is None  # outer sides are never cut
    assert last["core"][2] is None and last["core"][3] is None
    assert first["padded"][2] == pytest.approx(first["core"][2] + 2.0)
    # every point lies in exactly one core
    xy = _xy()
    owners = np.zeros(len(xy), int)
    for t in tiles:
        c = [(-np.inf if v is None else v) if i < 2 else (np.inf if v is None else v) for i, v in enumerate(t["core"])]
        owners += in_box(xy, c) & ~((xy[:, 0] == c[2]) | (xy[:, 1] == c[3]))
    assert (owners == 1).all()


def test_automatic_size_follows_the_memory_budget():
    xy = _xy()
    small_grid, small = choose_grid(xy, 0.0, 2.0, 0.6, 0.03)
    big_grid, big = choose_grid(xy, 0.0, 2.0, 4.0, 0.03)
    assert small["auto"] and small["tile_m"] < big["tile_m"]
    assert small["nx"] * small["ny"] > big["nx"] * big["ny"]
    assert small["predicted_tile_mb"] <= 0.6 * 1024 + 1


def test_memory_model_grows_with_points_and_finer_voxels():
    assert estimate_tile_mb(2e6, 1000, 0.03) > estimate_tile_mb(1e6, 1000, 0.03)
    assert estimate_tile_mb(5e6, 1000, 0.01) > estimate_tile_mb(5e6, 1000, 0.05)


def test_too_many_tiles_is_a_config_error():
    from twinkit.errors import ConfigError

    with pytest.raises(ConfigError, match="max_tiles"):
        choose_grid(_xy(), 1.0, 0.5, 4.0, 0.03, max_tiles=10)


def test_seams_move_off_poles_and_trunks_within_the_search_width():
    from twinkit_tiles.tiling import Grid, place_seams

    rng = np.random.default_rng(1)
    ground = np.c_[rng.uniform(0, 60, 50_000), rng.uniform(0, 60, 50_000)]
    # a row of poles (upright points) right on the line x = 20, none elsewhere within 1 m of it
    poles = np.c_[rng.normal(20.05, 0.08, 3000), rng.uniform(0, 60, 3000)]
    x = np.r_[ground[:, 0], poles[:, 0]]
    upright = np.r_[np.zeros(len(ground), bool), np.ones(len(poles), bool)]
    lines, rep = place_seams(x, upright, np.array([0.0, 20.0, 40.0, 60.0]), search_m=1.0)
    assert lines[0] == 0.0 and lines[-1] == 60.0  # the outer lines stay
    assert 0.3 <= abs(lines[1] - 20.05) <= 1.0 and rep[0]["upright_points_after"] < 0.01 * rep[0]["upright_points_before"]
    assert lines[2] == 40.0 and rep[1]["moved_m"] == 0.0  # nothing upright there: not moved
    # the moved lines are the grid's: cores and padded boxes follow them
    g = Grid(0.0, 0.0, 60.0, 60.0, 3, 1, 2.0, xs=lines)
    t = g.tiles()
    assert t[0]["core"][2] == lines[1] and t[1]["core"][0] == lines[1]
    assert t[1]["padded"][0] == pytest.approx(lines[1] - 2.0)
    # nothing to search: unchanged
    same, rep0 = place_seams(x, upright, np.array([0.0, 20.0, 40.0]), search_m=0.0)
    assert same.tolist() == [0.0, 20.0, 40.0] and rep0 == []

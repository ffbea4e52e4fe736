"""The parts of merge_tiles (twinkit_tiles.merge) on hand-made records."""
from __future__ import annotations

from twinkit_tiles.merge import open_seams, tile_trim


def test_open_seams_splits_cracks_by_what_lies_across_and_counts_strip_edges():
    runs = [{"tile_edges": 5, "facing_edges": 2, "edges": 7, "facing_length_m": 0.2, "tile_edges_length_m": 0.5,
             "length_m": 0.8},
            {"tile_edges": 1, "facing_edges": 1, "edges": 1, "facing_length_m": 0.1, "tile_edges_length_m": 0.1,
             "length_m": 0.1}]
    cracks, kinds, ends, open_len = open_seams(runs)
    assert cracks == 6 and kinds == {"facing_surface": 3, "surface_ends": 3} and ends == 2
    assert open_len == {"facing_surface": 0.3, "surface_ends": 0.3, "strip_edges": 0.3}
    assert open_seams([]) == (0, {"facing_surface": 0, "surface_ends": 0}, 0,
                              {"facing_surface": 0, "surface_ends": 0, "strip_edges": 0})


def test_tile_trim_reads_the_tiles_comment():
    assert tile_trim(["other", "twinkit-tiles trim seam_band_m 0.5 max_dist_m 0.08"]) == {"seam_band_m": 0.5,
                                                                                          "max_dist_m": 0.08}
    assert tile_trim(["twinkit-tiles trim seam_band_m x"]) == {}
    assert tile_trim(None) == {}

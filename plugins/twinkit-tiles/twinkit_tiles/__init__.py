"""twinkit-tiles: tiled reconstruction of large scenes."""

"""twinkit-roads: OpenStreetMap road sources, OSM -> OpenDRIVE and road alignment."""
__version__ = "0.1.0"

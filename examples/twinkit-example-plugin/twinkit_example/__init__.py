"""An example third-party twinkit plugin."""

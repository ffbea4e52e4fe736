"""twinkit-demo-site: the built-in demo site generator (see docs/demo-site.md)."""

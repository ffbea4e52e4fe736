from pathlib import Path

import pytest

HERE = Path(__file__).parent
FIXTURES = HERE / "fixtures"
SHARED = (HERE / "../../../../shared/data").resolve()
OSM_DIR = SHARED / "osm"
DEMO_SITE = {"name": "demo", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 12.0}}


def need_shared(name: str) -> Path:
    p = OSM_DIR / name
    if not p.is_file():
        pytest.skip(f"shared sample data absent: {p}")
    return p


@pytest.fixture(scope="session")
def demo_site(tmp_path_factory):
    """The demo site generated once (roads.osm shifted and rotated by a known amount, truth, gt mesh)."""
    from twinkit.testing import need_plugin, run_plugin

    need_plugin("site_generator", "demo_intersection")  # the twinkit-demo-site package
    # roads, truth, ground-truth mesh and cameras do not depend on the scan: a sparse scan keeps this fast
    return run_plugin("site_generator", "demo_intersection", tmp_path_factory.mktemp("demo_site"),
                      site=dict(DEMO_SITE, size="small"), size="small", density_scale=0.02, shadows=False)

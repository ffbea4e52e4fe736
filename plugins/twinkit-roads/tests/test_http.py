"""The download sources against a real HTTP server on 127.0.0.1 serving a fixture."""
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

from twinkit import InputError
from twinkit.testing import plugin_from_module, run_step

import twinkit_roads.plugin as roads
from twinkit_roads.http import CachedHttp
from twinkit_roads.osmio import read_osm

from conftest import DEMO_SITE, FIXTURES

FIXTURE = (FIXTURES / "tiny_roads.osm").read_bytes()


class Server:
    def __init__(self):
        self.hits: list[tuple[str, str, str]] = []  # (method, path, user agent)
        self.fail_next = 0
        self.delay_s = 0.0
        srv = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *a):
                pass

            def _answer(self):
                srv.hits.append((self.command, self.path, self.headers.get("User-Agent", "")))
                if self.command == "POST":
                    self.rfile.read(int(self.headers.get("Content-Length", 0)))
                if srv.delay_s:
                    time.sleep(srv.delay_s)
                if self.path.startswith("/missing"):
                    code, body = 404, b"not here"
                elif srv.fail_next > 0:
                    srv.fail_next -= 1
                    code, body = 503, b"busy, try later"
                elif self.path.startswith("/html"):
                    code, body = 200, b"<html>rate limited</html>"
                else:
                    code, body = 200, FIXTURE
                self.send_response(code)
                self.send_header("Content-Type", "text/xml")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                try:
                    self.wfile.write(body)
                except (BrokenPipeError, ConnectionResetError):
                    pass

            do_GET = do_POST = _answer

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}"
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)
        self.thread.start()

    def close(self):
        self.httpd.shutdown()
        self.httpd.server_close()


@pytest.fixture
def server():
    s = Server()
    yield s
    s.close()


def _params(server, tmp_path, path="/api/0.6/map", **kw):
    base = dict(url=server.url + path, timeout_s=2.0, retries=2, backoff_s=0.05, cache_dir=str(tmp_path / "cache"),
                user_agent="twinkit-tests/1.0", radius_m=100.0)
    base.update(kw)
    return roads.DownloadParams(**base)


def test_osm_api_downloads_retries_and_caches(server, tmp_path):
    plugin = plugin_from_module(roads, "road_source", "osm_api")
    server.fail_next = 2  # two 503 answers, then the data
    out = run_step(plugin, tmp_path / "a", {}, _params(server, tmp_path), site=DEMO_SITE)
    assert read_osm(out["osm.osm"]).count()["highway_ways"] == 2
    assert len(server.hits) == 3
    method, path, agent = server.hits[-1]
    assert method == "GET" and "bbox=24.93" in path and agent == "twinkit-tests/1.0"
    # the same box again: from the on-disk cache, no request
    out2 = run_step(plugin, tmp_path / "b", {}, _params(server, tmp_path), site=DEMO_SITE)
    assert len(server.hits) == 3
    assert out2["osm.osm"].read_bytes() == out["osm.osm"].read_bytes()


def test_overpass_posts_a_query(server, tmp_path):
    plugin = plugin_from_module(roads, "road_source", "overpass")
    out = run_step(plugin, tmp_path / "a", {}, _params(server, tmp_path, "/api/interpreter"), site=DEMO_SITE)
    assert server.hits[-1][0] == "POST"
    assert read_osm(out["osm.osm"]).count()["traffic_signals"] == 1


def test_timeout_gives_up_after_the_retries(server, tmp_path):
    server.delay_s = 1.5
    client = CachedHttp(cache_dir=tmp_path / "c", timeout_s=0.3, retries=1, backoff_s=0.01)
    t0 = time.time()
    with pytest.raises(InputError, match="no answer after 2 attempts"):
        client.request("GET", server.url + "/api/0.6/map")
    assert time.time() - t0 < 3.0
    assert len(server.hits) == 2


def test_client_errors_are_not_retried(server, tmp_path):
    client = CachedHttp(cache_dir=tmp_path / "c", timeout_s=2, retries=3, backoff_s=0.01)
    with pytest.raises(InputError, match="404"):
        client.request("GET", server.url + "/missing")
    assert len(server.hits) == 1


def test_a_non_osm_answer_is_refused_and_not_cached(server, tmp_path):
    plugin = plugin_from_module(roads, "road_source", "osm_api")
    with pytest.raises(InputError, match="not OSM XML"):
        run_step(plugin, tmp_path / "a", {}, _params(server, tmp_path, "/html"), site=DEMO_SITE)
    assert not list((tmp_path / "cache").glob("*.body"))


def test_download_needs_a_georeferenced_site(server, tmp_path):
    plugin = plugin_from_module(roads, "road_source", "overpass")
    with pytest.raises(InputError, match="no georeference"):
        run_step(plugin, tmp_path / "a", {}, _params(server, tmp_path), site={"name": "nowhere"})
    with pytest.raises(InputError, match="antimeridian"):
        run_step(plugin, tmp_path / "b", {}, _params(server, tmp_path, bbox="-17,179.9,-16,-179.9"), site=DEMO_SITE)
    assert server.hits == []


class TricklingServer:
    """Answers 200 at once, then sends one byte every 0.2 s for ever: no single read ever times out."""

    def __init__(self):
        self.stop = threading.Event()
        srv = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *a):
                pass

            def do_GET(self):
                self.send_response(200)
                self.send_header("Content-Type", "text/xml")
                self.send_header("Content-Length", str(10**9))
                self.end_headers()
                try:
                    while not srv.stop.is_set():
                        self.wfile.write(b" ")
                        self.wfile.flush()
                        time.sleep(0.2)
                except (BrokenPipeError, ConnectionResetError):
                    pass

            do_POST = do_GET

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.httpd.daemon_threads = True
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}"
        threading.Thread(target=self.httpd.serve_forever, daemon=True).start()

    def close(self):
        self.stop.set()
        self.httpd.shutdown()
        self.httpd.server_close()


def test_a_trickling_server_hits_the_total_deadline(tmp_path):
    """Per-read timeouts (1 s) never fire against a byte every 0.2 s; the total deadline (2 s) does, with one
    clear line, through the step's own parameters."""
    srv = TricklingServer()
    try:
        params = roads.DownloadParams(url=srv.url + "/api/0.6/map", timeout_s=1.0, retries=2, backoff_s=0.05,
                                      cache_dir=str(tmp_path / "cache"), user_agent="twinkit-tests/1.0",
                                      radius_m=100.0, deadline_s=2.0)
        t0 = time.monotonic()
        with pytest.raises(InputError) as e:
            run_step(plugin_from_module(roads, "road_source", "osm_api"), tmp_path / "out", {}, params,
                     site=DEMO_SITE)
        took = time.monotonic() - t0
        msg = str(e.value)
        assert "total deadline of 2 s" in msg and "road_source.deadline_s" in msg and "\n" not in msg
        assert took < 60, took  # generous: without the deadline this would stream for ~6 years
        client = CachedHttp(cache_dir=tmp_path / "c2", timeout_s=1.0, retries=0, deadline_s=1.0)
        with pytest.raises(InputError, match="total deadline of 1 s"):
            client.request("GET", srv.url + "/x")
    finally:
        srv.close()

"""A small HTTP client for OSM servers: timeouts, retries with back-off, a user agent, an on-disk cache."""
from __future__ import annotations

import hashlib
import json
import logging
import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from twinkit import InputError
from twinkit.manifest import redact

DEFAULT_USER_AGENT = "twinkit-roads/0.1 (+https://github.com/twinkit; digital twins for driving simulation)"
RETRY_STATUS = {408, 429, 500, 502, 503, 504}
log = logging.getLogger("twinkit.roads.http")


def default_cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "twinkit" / "osm"


@dataclass
class HttpResult:
    body: bytes
    from_cache: bool
    attempts: int
    url: str


class _Late(Exception):
    """The total deadline passed during one attempt."""


def _shut(response) -> None:
    """End a read blocked on ``response``'s socket (shutdown wakes a blocked recv; close alone may not)."""
    import socket

    for get in (lambda r: r.raw._connection.sock, lambda r: r.raw._fp.fp.raw._sock):
        try:
            get(response).shutdown(socket.SHUT_RDWR)
            return
        except Exception:  # noqa: BLE001 -- attribute names differ between urllib3 versions
            continue


class CachedHttp:
    """GET/POST with a per-request timeout, bounded retries and a content cache keyed by the request."""

    def __init__(self, cache_dir: Path | str | None = None, timeout_s: float = 60.0, retries: int = 3,
                 backoff_s: float = 1.0, user_agent: str = DEFAULT_USER_AGENT, max_age_days: float = 30.0,
                 max_bytes: int = 512 * 1024 * 1024, deadline_s: float = 120.0):
        self.cache_dir = Path(cache_dir) if cache_dir else default_cache_dir()
        self.timeout_s = float(timeout_s)
        self.retries = int(retries)
        self.backoff_s = float(backoff_s)
        self.user_agent = user_agent or DEFAULT_USER_AGENT
        self.max_age_s = float(max_age_days) * 86400.0
        self.max_bytes = int(max_bytes)
        self.deadline_s = float(deadline_s)

    def _key(self, method: str, url: str, params: dict | None, data: dict | None) -> str:
        """The cache file name of a request: a hash of it with any ``${oc.env:...}`` value (a token in the URL)
        replaced by the variable's name, so nothing on disk derives from a secret (twinkit.manifest.redact)."""
        items = [[list(kv) for kv in sorted((d or {}).items())] for d in (params, data)]  # lists: redact sees in
        blob = json.dumps(redact([method, url, *items]))
        return hashlib.sha256(blob.encode()).hexdigest()

    def cached(self, method: str, url: str, *, params: dict | None = None, data: dict | None = None) -> Path | None:
        """The fresh cached answer of this request (what :meth:`request` would serve without the network), or None."""
        key = self._key(method, url, params, data)
        body_path, meta_path = self.cache_dir / f"{key}.body", self.cache_dir / f"{key}.json"
        if body_path.is_file() and meta_path.is_file() and time.time() - body_path.stat().st_mtime <= self.max_age_s:
            return body_path
        return None

    def request(self, method: str, url: str, *, params: dict | None = None, data: dict | None = None,
                validate=None) -> HttpResult:
        """Fetch ``url``; served from the cache when a fresh copy exists. ``validate(bytes)`` may reject a body."""
        import requests

        key = self._key(method, url, params, data)
        body_path = self.cache_dir / f"{key}.body"
        meta_path = self.cache_dir / f"{key}.json"
        if body_path.is_file() and meta_path.is_file():
            age = time.time() - body_path.stat().st_mtime
            if age <= self.max_age_s:
                log.info("OSM cache hit %s (%s)", url, body_path.name)
                return HttpResult(body_path.read_bytes(), True, 0, url)
        headers = {"User-Agent": self.user_agent, "Accept-Encoding": "gzip, deflate"}
        last = "no attempt"
        attempt = 0
        deadline = time.monotonic() + self.deadline_s
        for attempt in range(1, self.retries + 2):
            wait = 0.0
            try:
                status, resp_headers, body = self._attempt(method, url, params, data, headers, deadline)
                if status == 200:
                    if validate is not None:
                        why = validate(body)
                        if why:
                            raise InputError(f"{url}: {why}")
                    self.cache_dir.mkdir(parents=True, exist_ok=True)
                    tmp = body_path.with_suffix(f".tmp{os.getpid()}")
                    tmp.write_bytes(body)
                    os.replace(tmp, body_path)
                    meta = {"url": url, "method": method, "params": params, "data": data}
                    meta_path.write_text(json.dumps({**redact(meta), "time": time.time(), "bytes": len(body)}, indent=1))
                    return HttpResult(body, False, attempt, url)
                snippet = body[:300].decode("utf-8", "replace").strip().replace("\n", " ")
                last = f"HTTP {status}: {snippet}"
                if status not in RETRY_STATUS:
                    raise InputError(f"{url} refused the request ({last})")
                wait = self.backoff_s * 2 ** (attempt - 1)
                ra = resp_headers.get("Retry-After")
                if ra and ra.isdigit():
                    wait = max(wait, min(float(ra), 60.0))
            except _Late:
                raise self._too_late(url, attempt, "the answer was still arriving") from None
            except (requests.Timeout, requests.ConnectionError) as exc:
                last = f"{type(exc).__name__}: {exc}"
                wait = self.backoff_s * 2 ** (attempt - 1)
            if attempt <= self.retries:
                if time.monotonic() + wait >= deadline:
                    raise self._too_late(url, attempt, last)
                log.warning("%s: %s; retry %d/%d in %.1f s", url, last, attempt, self.retries, wait)
                time.sleep(wait)
        raise InputError(f"{url}: no answer after {attempt} attempts (timeout {self.timeout_s:g} s each); last error: "
                         f"{last}. Check the network, raise road_source.timeout_s, or use a local OSM file")

    def _too_late(self, url: str, attempt: int, last: str) -> InputError:
        return InputError(f"{url}: no complete answer within the total deadline of {self.deadline_s:g} s "
                          f"({attempt} attempt(s); last: {last}); the server is stalled or slow - try later, raise "
                          f"road_source.deadline_s, or use a local OSM file (road_source=file)")

    def _attempt(self, method: str, url: str, params, data, headers: dict, deadline: float):
        """One request, read to the end in a helper thread so that the total deadline holds.

        The per-read timeout of ``requests`` never fires for a server that trickles a byte now and then;
        the deadline does: the caller stops waiting, shuts the socket (which ends the helper's read) and
        fails with one line. Returns ``(status, headers, body)``.
        """
        import requests

        box: dict = {}
        stop = threading.Event()

        def work() -> None:
            try:
                r = requests.request(method, url, params=params, data=data, headers=headers,
                                     timeout=(min(self.timeout_s, 15.0), self.timeout_s), stream=True)
                box["response"] = r
                chunks, size = [], 0
                for chunk in r.iter_content(65536):
                    if stop.is_set():
                        return
                    size += len(chunk)
                    if size > self.max_bytes:
                        raise InputError(f"{url}: answer larger than {self.max_bytes} bytes; use a smaller box")
                    chunks.append(chunk)
                box["result"] = (r.status_code, dict(r.headers), b"".join(chunks))
            except BaseException as exc:  # handed to the caller
                box["error"] = exc
            finally:
                done.set()

        done = threading.Event()
        t = threading.Thread(target=work, name="twinkit-http", daemon=True)
        t.start()
        if not done.wait(max(0.0, deadline - time.monotonic())):
            stop.set()
            _shut(box.get("response"))
            raise _Late(f"{url}: stalled")
        if "error" in box:
            raise box["error"]
        return box["result"]

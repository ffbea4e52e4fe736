"""A small HTTP client for OSM servers: timeouts, retries with back-off, a user agent, an on-disk cache."""
from __future__ import annotations

import hashlib
import json
import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path

from twinkit import InputError

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


class CachedHttp:
    """GET/POST with a per-request timeout, bounded retries and a content cache keyed by the request."""

    def __init__(self, cache_dir: Path | str | None = None, timeout_s: float = 60.0, retries: int = 3,
                 backoff_s: float = 1.0, user_agent: str = DEFAULT_USER_AGENT, max_age_days: float = 30.0,
                 max_bytes: int = 512 * 1024 * 1024):
        self.cache_dir = Path(cache_dir) if cache_dir else default_cache_dir()
        self.timeout_s = float(timeout_s)
        self.retries = int(retries)
        self.backoff_s = float(backoff_s)
        self.user_agent = user_agent or DEFAULT_USER_AGENT
        self.max_age_s = float(max_age_days) * 86400.0
        self.max_bytes = int(max_bytes)

    def _key(self, method: str, url: str, params: dict | None, data: dict | None) -> str:
        blob = json.dumps([method, url, sorted((params or {}).items()), sorted((data or {}).items())])
        return hashlib.sha256(blob.encode()).hexdigest()

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
        for attempt in range(1, self.retries + 2):
            try:
                r = requests.request(method, url, params=params, data=data, headers=headers,
                                     timeout=(min(self.timeout_s, 15.0), self.timeout_s), stream=True)
                chunks, size = [], 0
                for chunk in r.iter_content(65536):
                    size += len(chunk)
                    if size > self.max_bytes:
                        raise InputError(f"{url}: answer larger than {self.max_bytes} bytes; use a smaller box")
                    chunks.append(chunk)
                body = b"".join(chunks)
                if r.status_code == 200:
                    if validate is not None:
                        why = validate(body)
                        if why:
                            raise InputError(f"{url}: {why}")
                    self.cache_dir.mkdir(parents=True, exist_ok=True)
                    tmp = body_path.with_suffix(f".tmp{os.getpid()}")
                    tmp.write_bytes(body)
                    os.replace(tmp, body_path)
                    meta_path.write_text(json.dumps({"url": url, "method": method, "params": params, "data": data,
                                                     "time": time.time(), "bytes": len(body)}, indent=1))
                    return HttpResult(body, False, attempt, url)
                snippet = body[:300].decode("utf-8", "replace").strip().replace("\n", " ")
                last = f"HTTP {r.status_code}: {snippet}"
                if r.status_code not in RETRY_STATUS:
                    raise InputError(f"{url} refused the request ({last})")
                wait = self.backoff_s * 2 ** (attempt - 1)
                ra = r.headers.get("Retry-After")
                if ra and ra.isdigit():
                    wait = max(wait, min(float(ra), 60.0))
            except (requests.Timeout, requests.ConnectionError) as exc:
                last = f"{type(exc).__name__}: {exc}"
                wait = self.backoff_s * 2 ** (attempt - 1)
            if attempt <= self.retries:
                log.warning("%s: %s; retry %d/%d in %.1f s", url, last, attempt, self.retries, wait)
                time.sleep(wait)
        raise InputError(f"{url}: no answer after {attempt} attempts (timeout {self.timeout_s:g} s each); last error: "
                         f"{last}. Check the network, raise road_source.timeout_s, or use a local OSM file")

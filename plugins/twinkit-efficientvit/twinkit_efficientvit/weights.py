"""Finding, checking and (on a machine with internet) downloading model weight files.

Default search for a file name, first hit wins:

1. ``$TWINKIT_MODELS_DIR/<file>`` when the environment variable is set (and only there);
2. ``./../shared/models/<file>`` relative to the current working directory;
3. ``<repo root>/../shared/models/<file>``, the repo root found by walking up from
   this package's folder (works for an editable install in a checkout);
4. ``~/.cache/twinkit/models/<file>`` (where :func:`download` puts files).
"""
from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
import urllib.request
from pathlib import Path

from twinkit.errors import InputError

ENV_MODELS_DIR = "TWINKIT_MODELS_DIR"


def repo_root() -> Path | None:
    """The checkout that contains this package (a folder with ``twinkit/`` and ``plugins/``), if any."""
    here = Path(__file__).resolve()
    for parent in here.parents:
        if (parent / "plugins").is_dir() and (parent / "twinkit" / "__init__.py").is_file():
            return parent
    return None


def cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "twinkit" / "models"


def candidate_dirs() -> list[Path]:
    """Folders searched for weights, in order (see module docstring)."""
    env = os.environ.get(ENV_MODELS_DIR)
    if env:
        return [Path(env).expanduser()]
    dirs = [Path.cwd() / ".." / "shared" / "models"]
    root = repo_root()
    if root is not None:
        dirs.append(root / ".." / "shared" / "models")
    dirs.append(cache_dir())
    out: list[Path] = []
    for d in dirs:
        d = d.resolve()
        if d not in out:
            out.append(d)
    return out


def sha256_of(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _fix_hint(file_name: str, official: str, param: str, url: str) -> str:
    return (
        f"fix: set {param}=/path/to/{file_name} (or the environment variable {ENV_MODELS_DIR} "
        f"to the folder holding it); the official file is {official}"
        + ("; on a machine with internet you can also set download_if_missing=true" if url else "")
    )


def resolve_weights(
    file_name: str,
    weights_path: str,
    sha256: str,
    official_sha256: str,
    official: str,
    url: str,
    download_if_missing: bool,
    param: str = "weights_path",
    hf_repo: str = "",
) -> Path:
    """Return a checked path to a weights file or raise :class:`InputError` naming the file and the fix.

    ``weights_path`` empty = search the default folders for ``file_name`` and check the
    official sha256; given = use that file (a folder means ``<folder>/<file_name>``) and
    check ``sha256`` only if one is given. A given non-empty ``sha256`` is always checked.
    """
    hint = _fix_hint(file_name, official, param, url)
    if weights_path:
        path = Path(weights_path).expanduser()
        if path.is_dir():
            path = path / file_name
        expected = sha256
        if not path.is_file():
            raise InputError(f"weights file {path} does not exist; {hint}")
    else:
        expected = sha256 or official_sha256
        tried = [d / file_name for d in candidate_dirs()]
        path = next((p for p in tried if p.is_file()), None)
        if path is None:
            if download_if_missing and url:
                path = download(file_name, url, expected, hf_repo=hf_repo)
            else:
                listing = ", ".join(str(p) for p in tried)
                raise InputError(f"weights file {file_name} not found (looked at: {listing}); {hint}")
    if expected:
        got = sha256_of(path)
        if got != expected.lower():
            raise InputError(
                f"weights file {path} is corrupt or not the expected file: sha256 {got}, expected {expected} "
                f"({path.stat().st_size} bytes); replace it with the official file or point {param} at a good copy "
                f"(the official file is {official})"
            )
    return path


def download(file_name: str, url: str, sha256: str, hf_repo: str = "") -> Path:
    """Download the official file into :func:`cache_dir` (or ``$TWINKIT_MODELS_DIR``), check its sha256.

    Uses ``huggingface_hub`` when installed and ``hf_repo`` is given, else ``urllib`` on ``url``.
    The tests exercise the ``urllib`` path with a ``file://`` URL only: the test machine has
    no internet, so neither a real HTTPS download nor the Hub path has been run.
    """
    target_dir = Path(os.environ[ENV_MODELS_DIR]).expanduser() if os.environ.get(ENV_MODELS_DIR) else cache_dir()
    target_dir.mkdir(parents=True, exist_ok=True)
    target = target_dir / file_name
    errors = []
    if hf_repo:
        try:
            from huggingface_hub import hf_hub_download

            got = Path(hf_hub_download(repo_id=hf_repo, filename=file_name))
            part = target.with_suffix(target.suffix + ".part")
            shutil.copyfile(got, part)
            os.replace(part, target)
        except Exception as exc:  # not installed, offline, ...: fall back to plain HTTPS
            errors.append(f"huggingface_hub: {exc!r}")
    if not target.is_file():
        tmp_name = None
        try:
            with tempfile.NamedTemporaryFile(dir=target_dir, delete=False, suffix=".part") as tmp:
                tmp_name = tmp.name
                with urllib.request.urlopen(url, timeout=60) as resp:  # noqa: S310 (fixed https URL)
                    shutil.copyfileobj(resp, tmp)
            os.replace(tmp_name, target)
        except Exception as exc:  # network errors of every flavour
            if tmp_name and os.path.exists(tmp_name):
                os.unlink(tmp_name)
            errors.append(f"url: {exc!r}")
            raise InputError(
                f"could not download {file_name} from {url} ({'; '.join(errors)}); download it by hand and set "
                f"weights_path, or put it into {target_dir}"
            ) from exc
    if sha256 and sha256_of(target) != sha256:
        bad = target.with_suffix(target.suffix + ".bad")
        os.replace(target, bad)
        raise InputError(f"downloaded {url} but its sha256 does not match {sha256}; kept it as {bad}")
    return target

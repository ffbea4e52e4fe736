"""A step's cache key: the sha256 of its descriptor (plugin kind, name, version and code hash; resolved
parameters; the configuration of the components it uses; the content hashes of its inputs), and the
reason a key changed, in words, for the log."""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

from twinkit.engine.base import EngineBase
from twinkit.engine.plan import PlannedStep
from twinkit.engine.store import site_fields, with_site
from twinkit.errors import InputError, TwinkitError
from twinkit.hashing import artefact_hash
from twinkit.ranges import path_fields


def _file_content(path: Path, suffixes: tuple[str, ...], cache) -> Any:
    """The content hash of a file or folder a parameter names (None when it is not there: the step's own check
    says so); for a stem, one per suffix."""
    if suffixes:
        return {sfx: _file_content(path.with_suffix(sfx), (), cache) for sfx in suffixes}
    if path.is_dir():
        return artefact_hash(path, cache)
    return cache.hash(path) if path.is_file() else None


def named_files(cls: type | None, values: Any, cache, prefix: str = "") -> dict[str, Any]:
    """``<prefix><field>`` -> content hash of the file or folder named by each non-empty parameter of ``cls``
    declared ``param(path=...)`` (twinkit.ranges.path_fields); relative names from the working directory, as the
    plugins open them."""
    out: dict[str, Any] = {}
    for name, suffixes in path_fields(cls).items():
        value: Any = values
        for part in name.split("."):
            value = value.get(part) if isinstance(value, dict) else None
        if isinstance(value, str) and value.strip():
            out[prefix + name] = _file_content(Path(value).expanduser(), suffixes, cache)
    return out


def missing_input(path: Path, step_id: str) -> str:
    """One line for a site input that is not there (a broken link named as one)."""
    if path.is_symlink():
        return (f"site input {path} is a broken link (to {os.readlink(path)}, which does not exist; needed by "
                f"step '{step_id}'); fix the link or give the file's own path")
    return (f"site input {path} does not exist (needed by step '{step_id}'); fix the path in the site config or "
            f"on the command line")


class KeysMixin(EngineBase):
    """Part of :class:`~twinkit.engine.runner.Engine`: inputs, descriptor and key of a planned step
    (``self.outcomes`` of the steps before it, ``self.hashes``)."""

    def _input_values(self, ps: PlannedStep) -> tuple[dict[str, Any], dict[str, Any]]:
        """Paths and content hashes of a step's inputs."""
        paths: dict[str, Any] = {}
        hashes: dict[str, Any] = {}
        sources = dict(ps.inputs)
        if ps.foreach is not None:
            sources["__foreach__"] = ps.foreach
        for param, src in sources.items():
            if src is None:
                paths[param], hashes[param] = None, None
                continue
            if src.path is not None:
                if not src.path.exists():
                    raise InputError(missing_input(src.path, ps.id))
                paths[param] = src.path
                hashes[param] = artefact_hash(src.path, self.hashes) if src.path.is_dir() else self.hashes.hash(src.path)
            else:
                assert src.step_index is not None  # a Source has a path or a producing step
                prod = self.outcomes[src.step_index - 1]
                paths[param] = prod.outputs[src.filename]
                hashes[param] = prod.hashes[src.filename]
        return paths, hashes

    def _descriptor(self, ps: PlannedStep, input_hashes: dict[str, Any]) -> dict:
        if ps.plugin is None:
            plugin = {"kind": "manual", "instructions": (ps.spec.manual or {}).get("instructions")}
        else:
            plugin = {"kind": ps.plugin.kind, "name": ps.plugin.name, "version": ps.plugin.version,
                      "code": self._code_hash(ps)}
        desc = {
            "plugin": plugin,
            "params": ps.params_dict,
            "components": ps.components,
            "inputs": input_hashes,
            "outputs": [o.filename for o in ps.outputs],
        }
        files = self._param_files(ps)
        if files:  # only then: the keys of steps whose parameters name no file stay as they were
            desc["files"] = files
        return desc

    def _code_hash(self, ps: PlannedStep) -> str:
        """The step's plugin's code hash as it was when the plan was made (``self.code_hashes``)."""
        assert ps.plugin is not None
        pinned = getattr(self, "code_hashes", {})
        if ps.plugin.qualname not in pinned:
            pinned[ps.plugin.qualname] = ps.plugin.code_hash()
        return pinned[ps.plugin.qualname]

    def _param_files(self, ps: PlannedStep) -> dict[str, Any]:
        """The content hashes of the files the step's parameters, and its components' (``image_model``), name
        (``param(path=...)``): a changed map or weights file re-runs the step as a changed input does."""
        files = named_files(ps.plugin.params if ps.plugin else None, ps.params_dict, self.hashes)
        for kind, node in (ps.components or {}).items():
            if isinstance(node, dict) and node.get("plugin"):
                try:
                    plugin = self.registry.get(kind, node["plugin"])
                except TwinkitError:
                    continue  # an unknown component fails where it is built, with its own message
                files.update(named_files(plugin.params, node, self.hashes, f"{kind}."))
        return files

    def _keyed(self, descriptor: dict) -> tuple[str, dict, str, list[str]]:
        """(key, descriptor with the site fields the step reads, the descriptor's own key, those fields)."""
        index = self._key(descriptor)
        fields = site_fields(self.store, index)
        key, desc = with_site(descriptor, self.cfg.get("site"), fields)
        return key, desc, index, fields

    @staticmethod
    def _key(descriptor: dict) -> str:
        return hashlib.sha256(json.dumps(descriptor, sort_keys=True, default=str).encode()).hexdigest()[:32]

    def _why(self, old: dict | None, new: dict) -> str:
        if old is None or "descriptor" not in old:
            return "no earlier result"
        o = old["descriptor"]
        new = self._redacted(new) if hasattr(self, "_redacted") else new  # records keep secrets out
        reasons = []
        if o.get("plugin", {}).get("name") != new["plugin"].get("name"):
            reasons.append(f"plugin {o['plugin'].get('name')} -> {new['plugin'].get('name')}")
        elif o.get("plugin", {}).get("version") != new["plugin"].get("version"):
            reasons.append(f"plugin version {o['plugin'].get('version')} -> {new['plugin'].get('version')}")
        elif o.get("plugin", {}).get("code") != new["plugin"].get("code"):
            reasons.append("plugin code changed")
        for k in sorted(set(o.get("params", {})) | set(new["params"])):
            a, b = o.get("params", {}).get(k), new["params"].get(k)
            if a != b:
                reasons.append(f"{k} {a!r} -> {b!r}")
        changed = [k for k in sorted(set(o.get("inputs", {})) | set(new["inputs"]))
                   if o.get("inputs", {}).get(k) != new["inputs"].get(k)]
        if changed:
            reasons.append("input changed: " + ", ".join(changed))
        if o.get("components") != new["components"]:
            reasons.append("component config changed")
        files = [k for k in sorted(set(o.get("files") or {}) | set(new.get("files") or {}))
                 if (o.get("files") or {}).get(k) != (new.get("files") or {}).get(k)]
        if files:
            reasons.append("file changed: " + ", ".join(files))
        old_site, new_site = o.get("site") or {}, new.get("site") or {}
        for k in sorted(set(old_site) & set(new_site)):
            if old_site[k] != new_site[k]:
                reasons.append(f"site.{k} {_short(old_site[k])} -> {_short(new_site[k])}")
        if set(new_site) - set(old_site) and not reasons:
            reasons.append("reads site field(s) " + ", ".join(f"site.{k}" for k in sorted(set(new_site) - set(old_site))))
        if not reasons and "site_fields" not in old:
            return "recorded by a twinkit that did not yet track the site fields a step reads (runs once)"
        return "; ".join(reasons) or "key changed"


def _short(v: Any, n: int = 60) -> str:
    t = json.dumps(v, sort_keys=True, default=str)
    return t if len(t) <= n else t[: n - 3] + "..."

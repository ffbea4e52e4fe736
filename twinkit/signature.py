"""Reading a step function's signature: which files it reads and writes.

Convention (from the thesis's pipeline engine): a keyword parameter
``in_<name>_<ext>`` reads the artefact ``<name>.<ext>``, ``out_<name>_<ext>``
writes it. ``_dir`` as the extension means a folder ``<name>/``. Without a
known extension (``in_cloud``) an input accepts the artefact ``cloud`` with
any extension. An input whose default is ``None`` is optional. Every other
parameter (``params``, ``ctx``, ``item``) is filled by the engine.
"""
from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Any, Callable

#: extensions recognised at the end of a port name.
KNOWN_EXTS = frozenset(
    """bin ply obj mtl png jpg jpeg npy npz json csv md html txt yaml yml osm pbf bz2 xodr fbx usd usda usdc usdz
    glb gltf e57 las laz tif tiff xyz pts log pkl dir""".split()
)


@dataclass(frozen=True)
class Port:
    """One declared input or output."""

    param: str  # the function parameter, e.g. "in_mesh_ply"
    name: str  # artefact base name, e.g. "mesh"
    ext: str | None  # "ply", "dir", or None (any extension; inputs only)
    optional: bool = False

    @property
    def is_dir(self) -> bool:
        return self.ext == "dir"

    @property
    def filename(self) -> str:
        """File (or folder) name this port writes: ``mesh.ply`` or ``photos``."""
        if self.ext is None:
            raise ValueError(f"{self.param}: an output must name its extension")
        return self.name if self.is_dir else f"{self.name}.{self.ext}"

    def accepts(self, filename: str, is_dir: bool) -> bool:
        """Whether an artefact called ``filename`` can feed this input."""
        if self.ext == "dir":
            return is_dir and filename == self.name
        if is_dir:
            return False
        stem, dot, ext = filename.partition(".")
        if self.ext is None:
            return stem == self.name and bool(dot)
        return filename == f"{self.name}.{self.ext}"


@dataclass(frozen=True)
class Signature:
    inputs: tuple[Port, ...]
    outputs: tuple[Port, ...]
    wants_item: bool


def split_port(param: str, prefix: str) -> tuple[str, str | None]:
    body = param[len(prefix):]
    if "_" in body:
        base, _, last = body.rpartition("_")
        if last.lower() in KNOWN_EXTS and base:
            return base, last.lower()
    return body, None


def parse_signature(fn: Callable[..., Any]) -> Signature:
    """Ports of a step function (raises ValueError on a malformed declaration)."""
    inputs: list[Port] = []
    outputs: list[Port] = []
    sig = inspect.signature(fn)
    for p in sig.parameters.values():
        if p.name.startswith("in_"):
            name, ext = split_port(p.name, "in_")
            inputs.append(Port(p.name, name, ext, optional=p.default is None))
        elif p.name.startswith("out_"):
            name, ext = split_port(p.name, "out_")
            if ext is None:
                raise ValueError(
                    f"{fn.__module__}.{fn.__name__}: output parameter '{p.name}' must end in a known "
                    f"extension (e.g. out_{name}_ply, or out_{name}_dir for a folder)"
                )
            outputs.append(Port(p.name, name, ext))
    names = [o.filename for o in outputs]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise ValueError(f"{fn.__module__}.{fn.__name__}: outputs declared twice: {sorted(dup)}")
    return Signature(tuple(inputs), tuple(outputs), "item" in sig.parameters)

"""The photo steps' own file helpers: a JSON input read with an error that names the file, a PLY point cloud."""
from __future__ import annotations

import json
from pathlib import Path

from twinkit import InputError


def read_json(path: Path, what: str) -> dict:
    """The JSON document at ``path``; an InputError naming the file and ``what`` it should hold when unreadable."""
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: cannot read the {what} ({exc}); re-run the step that made it") from None


def write_cloud(path: Path, xyz, rgb=None, normals=None, comments=()) -> None:
    """A point cloud as PLY: ``xyz`` (N, 3) float, optional ``rgb`` (N, 3) uint8 and ``normals`` (N, 3) float32."""
    from twinkit.mesh import write_ply

    write_ply(path, cloud(xyz, rgb, normals, comments))


def cloud(xyz, rgb=None, normals=None, comments=()):
    """A :class:`twinkit.mesh.Mesh` without faces: ``xyz`` (N, 3) float64, optional ``rgb`` (N, 3) uint8 and
    ``normals`` (N, 3) float32 as attributes."""
    import numpy as np
    from twinkit.mesh import Mesh

    attrs = {}
    if normals is not None:
        attrs["normals"] = np.asarray(normals, np.float32)
    if rgb is not None:
        attrs["colors"] = np.asarray(rgb, np.uint8)
    return Mesh(vertices=np.asarray(xyz, float), attrs=attrs, comments=list(comments))

"""Export a mesh's vertices as an XYZ text file (one "x y z" line per vertex).

CloudCompare, MeshLab and most GIS tools open such point lists. The run report
gets a section with the number of points each export wrote.
"""
from dataclasses import dataclass
from pathlib import Path

from twinkit import StepContext, hookimpl
from twinkit.ranges import param


@dataclass
class XyzParams:
    decimals: int = param(3, ge=0, le=12)  # digits after the point, in metres (3 = millimetres)
    offset_m: float = param(0.0)  # added to z, e.g. to undo a height shift (any value)


def export_xyz(params: XyzParams, ctx: StepContext, *, in_mesh_ply: Path, out_points_xyz: Path) -> dict:
    """Write the vertices of ``mesh.ply`` as ``points.xyz``."""
    import numpy as np
    from twinkit.mesh import read_mesh  # twinkit's PLY reader: an InputError naming the file if unreadable

    xyz = read_mesh(in_mesh_ply).vertices  # (n, 3) float64
    xyz[:, 2] += params.offset_m
    np.savetxt(out_points_xyz, xyz, fmt=f"%.{params.decimals}f")
    ctx.log.info("wrote %d points to %s", len(xyz), out_points_xyz.name)
    return {"points": int(len(xyz))}


@hookimpl
def twinkit_register_exporters(register):
    register("xyz", export_xyz, params=XyzParams)


def points_section(ctx) -> str | None:
    """The report section: the points each of this plugin's steps exported."""
    rows = []
    for step in ctx.own_steps():  # the steps run by this distribution's plugins
        out = ctx.outputs(step).get("points.xyz")  # declared outputs, from step.json
        if out is not None:
            points = (step.get("metrics") or {}).get("points", "?")
            link = ("html", ctx.link(ctx.href(out), out.name))
            rows.append([step["folder"], points, link])
    return ctx.table(["step", "points", "file"], rows) if rows else None  # None: no section


@hookimpl
def twinkit_register_report_sections(register):
    register("xyz_points", points_section, title="Exported points", order=950)

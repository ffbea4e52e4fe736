"""Fixtures: a small synthetic labelled, textured street, split once per session."""
from __future__ import annotations

import importlib.util
import shutil
from pathlib import Path

import numpy as np
import pytest

from twinkit.testing import plugin_from_module, run_step

import twinkit_export.plugin as ep
from twinkit_export import synthetic

SITE = {"name": "teststreet", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 12.0}}
SHARED = Path("/work/shared")
HAS_BPY = importlib.util.find_spec("bpy") is not None


def plugin(kind: str, name: str):
    return plugin_from_module(ep, kind, name)


@pytest.fixture(scope="session")
def street(tmp_path_factory):
    """(folder, obj path, labels path, (verts, faces, uv, labels)); the faces include back-to-back twins,
    a duplicate and degenerate faces (synthetic.BAD_FACES), which the split must drop."""
    d = tmp_path_factory.mktemp("street")
    v, f, uv, lab = synthetic.make_street(nx=40, ny=30, bad_faces=True)
    obj = synthetic.write_obj(d / "textured_mesh.obj", v, f, uv, texture_px=256)
    np.save(d / "labels.npy", lab)
    return d, obj, d / "labels.npy", (v, f, uv, lab)


@pytest.fixture(scope="session")
def class_dir(street, tmp_path_factory):
    d, obj, labels, _ = street
    out = run_step(plugin("step", "split_classes"), tmp_path_factory.mktemp("split"),
                   {"in_labels_npy": labels, "in_textured_mesh_obj": obj}, site=SITE)
    return out["class_meshes"]


@pytest.fixture(scope="session")
def fbx_out(class_dir, tmp_path_factory):
    if not HAS_BPY:
        pytest.skip("bpy (Blender as a module) is not installed")
    out = run_step(plugin("exporter", "fbx"), tmp_path_factory.mktemp("fbx"), {"in_class_meshes_dir": class_dir},
                   site=SITE)
    return out["twin.fbx"]


def straight_xodr(length_m: float = 100.0, y0: float = 5.0, width_m: float = 3.5, x0: float = 0.0) -> str:
    """One straight road along +x from (x0, y0) (site frame) with one driving lane each side."""
    return f"""<?xml version="1.0" standalone="yes"?>
<OpenDRIVE>
  <header revMajor="1" revMinor="4" name="straight" version="1.00" north="0" south="0" east="0" west="0">
    <geoReference><![CDATA[+proj=tmerc +lat_0=60.16945 +lon_0=24.93365 +k=1 +x_0=0 +y_0=0 +ellps=GRS80 +units=m]]></geoReference>
  </header>
  <road name="main" length="{length_m}" id="1" junction="-1">
    <link/>
    <planView>
      <geometry s="0" x="{x0}" y="{y0}" hdg="0" length="{length_m}"><line/></geometry>
    </planView>
    <elevationProfile><elevation s="0" a="0" b="0" c="0" d="0"/></elevationProfile>
    <lateralProfile/>
    <lanes>
      <laneSection s="0">
        <left>
          <lane id="1" type="driving" level="false"><link/><width sOffset="0" a="{width_m}" b="0" c="0" d="0"/></lane>
        </left>
        <center><lane id="0" type="none" level="false"><link/></lane></center>
        <right>
          <lane id="-1" type="driving" level="false"><link/><width sOffset="0" a="{width_m}" b="0" c="0" d="0"/></lane>
          <lane id="-2" type="sidewalk" level="false"><link/><width sOffset="0" a="2.0" b="0" c="0" d="0"/></lane>
        </right>
      </laneSection>
    </lanes>
  </road>
</OpenDRIVE>
"""


@pytest.fixture(scope="session")
def xodr_file(tmp_path_factory):
    p = tmp_path_factory.mktemp("roads") / "aligned.xodr"
    p.write_text(straight_xodr(length_m=36.0, x0=-18.0))  # on the synthetic street's ground (40 m x 30 m)
    return p


def copy_tree(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst

"""Round trips: FBX (read back with ufbx), USD (usd-core + UsdValidation), GLB (pygltflib + Khronos validator)."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from twinkit.testing import run_step

from twinkit_export.classes import BY_ID, palette_lut
from twinkit.mesh import bad_faces
from twinkit.mesh.glb import srgb_to_linear
from twinkit_export.split import load_class_set

from conftest import SITE, plugin


def _corner_sets(uv: np.ndarray) -> np.ndarray:
    return np.unique(np.round(uv.reshape(-1, 2), 5), axis=0)


# ----------------------------------------------------------------------------- FBX

def test_fbx_round_trip(fbx_out, class_dir, tmp_path):
    pytest.importorskip("ufbx")
    cs = load_class_set(class_dir)
    dump = tmp_path / "fbx.json"
    for _attempt in range(3):  # ufbx 0.0.5's Python bindings crash now and then (not the file: it reads fine again)
        proc = subprocess.run([os.sys.executable, str(Path(__file__).with_name("fbx_dump.py")), str(fbx_out),
                               str(dump)], timeout=300, capture_output=True)
        if proc.returncode == 0:
            break
    assert proc.returncode == 0, proc.stderr[-2000:]
    d = json.loads(dump.read_text())
    # metres, Z up, front -Y, right +X: Unreal's FBX target system, so no rotation on import
    assert d["unit_meters"] == pytest.approx(1.0)
    assert d["axes"] == [0, 4, 3]  # ufbx: +X right, +Z up, -Y front
    assert set(d["nodes"]) == {m.name for m in cs.meshes}
    tex = fbx_out.with_suffix(".png")
    # one material, its diffuse colour linked to the texture beside the FBX (per object: see the Blender test)
    assert list(d["materials"]) == ["M_twinkit"]
    assert ["DiffuseColor", tex.name] in d["materials"]["M_twinkit"]
    assert tex.exists()
    for m in cs.meshes:
        n = d["nodes"][m.name]
        assert (n["num_vertices"], n["num_faces"]) == (m.mesh.n_vertices, m.mesh.n_faces), m.name
        assert n["scale"] == [1.0, 1.0, 1.0]
        np.testing.assert_allclose(np.array(n["positions"]), m.mesh.vertices, atol=1e-4)  # site frame, metres
        assert not bad_faces(m.mesh.vertices, m.mesh.faces)[0].any()  # same counts as the clean class mesh: no twins
        got_uv = np.array(n["corner_uv"]).reshape(-1, 3, 2)
        np.testing.assert_allclose(got_uv, m.mesh.corner_uv, atol=1e-5)
        assert n["uv_sets"] == ["UVMap"]
        assert n["n_materials"] == 1
        assert set(n["colors"]) >= {"segmentation", "class_id"}
        np.testing.assert_array_equal(np.array(n["colors"]["segmentation"]), m.mesh.colors)
        np.testing.assert_array_equal(np.array(n["colors"]["class_id"])[:, 0], m.mesh.attrs["class_id"])


def test_fbx_reads_back_in_blender(fbx_out, class_dir, tmp_path):
    """Blender's own FBX importer sees the same names, counts, UV layer and texture link."""
    script = tmp_path / "read.py"
    script.write_text(
        "import bpy, json, sys\n"
        "bpy.ops.wm.read_factory_settings(use_empty=True)\n"
        f"bpy.ops.import_scene.fbx(filepath={str(fbx_out)!r})\n"
        "out = {}\n"
        "for ob in bpy.data.objects:\n"
        "    if ob.type != 'MESH': continue\n"
        "    me = ob.data\n"
        "    imgs = [n.image.filepath for m in me.materials for n in m.node_tree.nodes if n.type == 'TEX_IMAGE' and n.image]\n"
        "    out[ob.name] = {'v': len(me.vertices), 'f': len(me.polygons), 'uv': [u.name for u in me.uv_layers],\n"
        "                    'colors': [c.name for c in me.color_attributes], 'images': imgs, 'class_id': ob.get('class_id'),\n"
        "                    'dims': list(ob.dimensions)}\n"
        f"open({str(tmp_path / 'out.json')!r}, 'w').write(json.dumps(out))\n")
    subprocess.run([os.sys.executable, str(script)], check=True, capture_output=True, timeout=300)
    got = json.loads((tmp_path / "out.json").read_text())
    cs = load_class_set(class_dir)
    assert set(got) == {m.name for m in cs.meshes}
    for m in cs.meshes:
        g = got[m.name]
        assert (g["v"], g["f"]) == (m.mesh.n_vertices, m.mesh.n_faces)
        assert g["uv"] == ["UVMap"] and g["class_id"] == m.class_id
        assert {"segmentation", "class_id"} <= set(g["colors"])
        assert any(Path(p).name == "twin.png" for p in g["images"])
        ext = m.mesh.vertices.max(0) - m.mesh.vertices.min(0)
        np.testing.assert_allclose(g["dims"], ext, atol=1e-3)  # metres in, metres out


# ----------------------------------------------------------------------------- USD

@pytest.fixture(scope="module")
def usd_out(class_dir, tmp_path_factory):
    out = run_step(plugin("exporter", "usd"), tmp_path_factory.mktemp("usd"), {"in_class_meshes_dir": class_dir},
                   site=SITE)
    return out["twin.usd"]


def test_usd_validates_with_zero_errors(usd_out):
    from pxr import UsdValidation  # noqa: F401 -- usd-core >= 24.11 provides it; the exporter falls back otherwise

    from twinkit_export.usd import validation_report

    rep = validation_report(usd_out)
    assert rep["validators"] >= 20
    assert rep["errors"] == 0, rep["messages"]


def test_usd_round_trip(usd_out, class_dir):
    from pxr import Usd, UsdGeom, UsdSemantics, UsdShade

    cs = load_class_set(class_dir)
    stage = Usd.Stage.Open(str(usd_out))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    geo = stage.GetRootLayer().customLayerData["twinkit:georeference"]
    assert geo["crs"] == "EPSG:3067" and geo["lat"] == pytest.approx(60.16945) and "projected_x" in geo
    root = stage.GetDefaultPrim()
    assert root.GetPath().pathString == "/Site" and root.IsA(UsdGeom.Xform)
    meshes = {p.GetName(): p for p in root.GetChildren() if p.IsA(UsdGeom.Mesh)}
    assert set(meshes) == {m.name for m in cs.meshes}
    for m in cs.meshes:
        prim = meshes[m.name]
        mesh = UsdGeom.Mesh(prim)
        pts = np.array(mesh.GetPointsAttr().Get())
        np.testing.assert_allclose(pts, m.mesh.vertices, atol=1e-4)
        idx = np.array(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
        np.testing.assert_array_equal(idx, m.mesh.faces)
        assert not bad_faces(pts, idx)[0].any(), m.name  # the test street's twins and degenerates stay out
        pv = UsdGeom.PrimvarsAPI(prim)
        st = pv.GetPrimvar("st")
        assert st.GetInterpolation() == UsdGeom.Tokens.faceVarying
        np.testing.assert_allclose(np.array(st.ComputeFlattened()).reshape(-1, 3, 2), m.mesh.corner_uv, atol=1e-7)
        np.testing.assert_array_equal(np.array(pv.GetPrimvar("class_id").Get()), m.mesh.attrs["class_id"])
        np.testing.assert_array_equal(np.array(pv.GetPrimvar("source_index").Get()), m.mesh.attrs["source_index"])
        dc = np.array(pv.GetPrimvar("displayColor").Get())
        assert dc.shape == (m.mesh.n_vertices, 3)
        labels = UsdSemantics.LabelsAPI(prim, "class").GetLabelsAttr().Get()
        assert list(labels) == [BY_ID[m.class_id].name]
        assert prim.GetAttribute("twinkit:classId").Get() == m.class_id
        mat, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        assert mat and mat.GetPath().name == "M_twinkit"
    # material -> texture file next to the stage
    tex = stage.GetPrimAtPath("/Site/Looks/M_twinkit/DiffuseTexture")
    asset = UsdShade.Shader(tex).GetInput("file").Get()
    assert (usd_out.parent / Path(asset.path).name).exists()
    assert asset.resolvedPath and Path(asset.resolvedPath).exists()


def test_usd_colliders_on_static_classes_only(usd_out, class_dir):
    """Isaac Sim / PhysX collide with prims that have PhysicsCollisionAPI; a static triangle mesh needs
    MeshCollisionAPI with approximation "none" (the mesh itself). Movable classes get none."""
    from pxr import Usd, UsdGeom, UsdPhysics

    cs = load_class_set(class_dir)
    stage = Usd.Stage.Open(str(usd_out))
    got = {}
    for m in cs.meshes:
        prim = stage.GetPrimAtPath(f"/Site/{m.name}")
        has = prim.HasAPI(UsdPhysics.CollisionAPI)
        got[m.name] = has
        if has:
            assert prim.HasAPI(UsdPhysics.MeshCollisionAPI)
            assert UsdPhysics.MeshCollisionAPI(prim).GetApproximationAttr().Get() == "none"
            assert UsdPhysics.CollisionAPI(prim).GetCollisionEnabledAttr().Get() is True
    # the test street has road, sidewalk, terrain, building, pole (static) and a car (movable)
    assert {k for k, v in got.items() if v} >= {"Road_Road", "Road_Sidewalk", "Terrain", "Building", "Pole"}
    assert got["Car"] is False and got.get("Unlabeled", False) is False
    # a stage without colliders when asked
    from twinkit_export.usd import write_usd

    bare = usd_out.parent / "bare.usda"
    write_usd(cs.meshes, None, bare, {}, colliders=False, old_semantics=False, geo_schemas=False)
    st2 = Usd.Stage.Open(str(bare))
    assert not any(p.HasAPI(UsdPhysics.CollisionAPI) for p in st2.Traverse())
    assert not st2.GetPrimAtPath("/Site/CesiumGeoreference") and not st2.GetPrimAtPath("/CesiumGeoreference")
    # no ENU declared: the stage is the site frame, no transform on the meshes
    assert not any(UsdGeom.Xformable(p).GetOrderedXformOps() for p in st2.Traverse() if p.IsA(UsdGeom.Mesh))


def _authored_api_schemas(prim) -> list[str]:
    # GetAppliedSchemas() lists only schemas this usd-core knows; Isaac's and Omniverse's are not among them
    return list(prim.GetMetadata("apiSchemas").GetAddedOrExplicitItems())


def test_usd_labels_for_current_and_older_isaac_semantics(usd_out, class_dir):
    from pxr import Usd, UsdSemantics

    cs = load_class_set(class_dir)
    stage = Usd.Stage.Open(str(usd_out))
    for m in cs.meshes:
        prim = stage.GetPrimAtPath(f"/Site/{m.name}")
        name = BY_ID[m.class_id].name
        assert list(UsdSemantics.LabelsAPI(prim, "class").GetLabelsAttr().Get()) == [name]
        # the older schema: multiple-apply SemanticsAPI, instance "Semantics" (Isaac's add_update_semantics)
        assert "SemanticsAPI:Semantics" in _authored_api_schemas(prim)
        assert prim.GetAttribute("semantic:Semantics:params:semanticType").Get() == "class"
        assert prim.GetAttribute("semantic:Semantics:params:semanticData").Get() == name


def test_usd_georeference_for_omniverse_and_cesium(usd_out):
    from pxr import Usd

    stage = Usd.Stage.Open(str(usd_out))
    site = stage.GetDefaultPrim()
    assert "OmniWGS84ReferencePositionAPI" in _authored_api_schemas(site)
    lat, lon, h = site.GetAttribute("omni:geospatial:wgs84:reference:referencePosition").Get()  # lat first
    assert (lat, lon, h) == pytest.approx((60.16945, 24.93365, 12.0))
    assert site.GetAttribute("omni:geospatial:wgs84:reference:tangentPlane").Get() == "ENU"
    # the Cesium georeference lives inside the default prim (a reference to the file keeps it)
    assert not stage.GetPrimAtPath("/CesiumGeoreference").IsValid()
    cg = stage.GetPrimAtPath("/Site/CesiumGeoreference")
    assert cg.GetTypeName() == "CesiumGeoreferencePrim"
    assert cg.GetAttribute("cesium:georeferenceOrigin:latitude").Get() == pytest.approx(60.16945)
    assert cg.GetAttribute("cesium:georeferenceOrigin:longitude").Get() == pytest.approx(24.93365)
    assert cg.GetAttribute("cesium:georeferenceOrigin:height").Get() == pytest.approx(12.0)
    # the height is marked as what it is: EPSG:3067 is 2D, so the base point's own height, not ellipsoidal
    for p in (site, cg):
        assert p.GetAttribute("twinkit:heightKind").Get() == "undeclared"
        assert "not converted" in p.GetAttribute("twinkit:heightReference").Get()
    geo = stage.GetRootLayer().customLayerData["twinkit:georeference"]
    # the exact CRS stays; TM35FIN's grid convergence at 24.93 E is what the stage's transforms take out
    assert geo["crs"] == "EPSG:3067" and geo["grid_convergence_deg"] == pytest.approx(-1.79, abs=0.01)
    assert geo["height_kind"] == "undeclared" and geo["site_to_enu"]["rotation_deg"] == pytest.approx(1.79, abs=0.01)


def test_usd_georeference_survives_a_reference(usd_out, tmp_path):
    """A scene that references the twin (its default prim) under /World/Twin keeps both georeferences."""
    from pxr import Usd

    stage = Usd.Stage.CreateInMemory()
    stage.DefinePrim("/World/Twin").GetReferences().AddReference(str(usd_out))
    twin = stage.GetPrimAtPath("/World/Twin")
    assert twin.GetAttribute("omni:geospatial:wgs84:reference:tangentPlane").Get() == "ENU"
    cg = stage.GetPrimAtPath("/World/Twin/CesiumGeoreference")
    assert cg.IsValid() and cg.GetAttribute("cesium:georeferenceOrigin:latitude").Get() == pytest.approx(60.16945)


def test_usd_stage_read_as_enu_lands_on_the_site_crs(usd_out):
    """The geospatial schemas' reading rule (the stage's world coordinates are ENU metres at the reference
    position: ECEF of the reference + the ENU axes, pyproj) on points 150 m from the base point, taken through
    each mesh prim's world transform, against their true lon/lat from the site frame (TM35FIN): within 5 cm.
    Without the site -> ENU transform the grid convergence (1.79 deg) puts them 4.7 m off."""
    from pyproj import Geod
    from pxr import Usd, UsdGeom

    from twinkit.geo import SiteFrame
    from twinkit.geo.enu import enu_to_lonlat

    stage = Usd.Stage.Open(str(usd_out))
    site = stage.GetDefaultPrim()
    lat, lon, h = site.GetAttribute("omni:geospatial:wgs84:reference:referencePosition").Get()
    a = np.linspace(0, 2 * np.pi, 36, endpoint=False)
    pts = np.c_[150 * np.cos(a), 150 * np.sin(a), np.zeros_like(a)]
    truth = SiteFrame.from_site(SITE).local_to_lonlat(pts[:, :2])
    meshes = [p for p in site.GetChildren() if p.IsA(UsdGeom.Mesh)]
    assert meshes
    for prim in meshes:
        m = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default()))
        world = np.c_[pts, np.ones(len(pts))] @ m  # USD: row vectors
        got = enu_to_lonlat(world[:, :3], lat, lon, h)
        err = np.abs(Geod(ellps="WGS84").inv(got[:, 0], got[:, 1], truth[:, 0], truth[:, 1])[2])
        assert err.max() <= 0.05, (prim.GetName(), err.max())


# ----------------------------------------------------------------------------- glTF

@pytest.fixture(scope="module")
def glb_out(class_dir, tmp_path_factory):
    out = run_step(plugin("exporter", "gltf"), tmp_path_factory.mktemp("gltf"), {"in_class_meshes_dir": class_dir},
                   site=SITE)
    return out["twin.glb"]


def _accessor(g, blob, i):
    acc = g.accessors[i]
    bv = g.bufferViews[acc.bufferView]
    dt = {5126: np.float32, 5121: np.uint8, 5125: np.uint32}[acc.componentType]
    n = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc.type]
    stride = bv.byteStride or np.dtype(dt).itemsize * n
    raw = np.frombuffer(blob, np.uint8, bv.byteLength, bv.byteOffset + (acc.byteOffset or 0))
    rows = raw[: acc.count * stride].reshape(acc.count, stride)[:, : np.dtype(dt).itemsize * n]
    return np.ascontiguousarray(rows).view(dt).reshape(acc.count, n)


def test_glb_round_trip(glb_out, class_dir):
    pygltflib = pytest.importorskip("pygltflib")
    from PIL import Image
    import io

    cs = load_class_set(class_dir)
    g = pygltflib.GLTF2().load(str(glb_out))
    blob = g.binary_blob()
    assert g.asset.extras["twinkit:georeference"]["crs"] == "EPSG:3067"
    nodes = {n.name: n for n in g.nodes}
    assert set(nodes) == {m.name for m in cs.meshes}
    lut = palette_lut()
    for m in cs.meshes:
        node = nodes[m.name]
        assert node.extras["class_id"] == m.class_id
        prim = g.meshes[node.mesh].primitives[0]
        pos = _accessor(g, blob, prim.attributes.POSITION)
        # no COLOR_0: it would multiply (darken) the photo texture in every viewer
        assert prim.attributes.COLOR_0 is None
        col = _accessor(g, blob, getattr(prim.attributes, "_CLASS_COLOR"))
        cls = _accessor(g, blob, getattr(prim.attributes, "_CLASS_ID")).ravel()
        uv = _accessor(g, blob, prim.attributes.TEXCOORD_0)
        idx = _accessor(g, blob, prim.indices).ravel()
        assert len(idx) == 3 * m.mesh.n_faces
        # by position (glTF splits vertices at UV seams): no twin or degenerate face reached the GLB
        upos, weld = np.unique(pos, axis=0, return_inverse=True)
        assert not bad_faces(upos.astype(np.float64), weld.ravel()[idx].reshape(-1, 3))[0].any(), m.name
        # back to the site frame: glTF (x, y, z) = site (x, z, -y)
        site = np.column_stack([pos[:, 0], -pos[:, 2], pos[:, 1]])
        np.testing.assert_allclose(site[idx].reshape(-1, 3, 3), m.mesh.vertices[m.mesh.faces].astype(np.float32), atol=1e-4)
        flip = uv.copy()
        flip[:, 1] = 1 - flip[:, 1]
        np.testing.assert_allclose(flip[idx].reshape(-1, 3, 2), m.mesh.corner_uv, atol=1e-6)
        # palette colours and class ids per corner
        lab_corner = m.mesh.attrs["class_id"][m.mesh.faces].ravel()
        np.testing.assert_array_equal(cls[idx], lab_corner)
        # glTF vertex colours are linear: the sRGB palette through the sRGB transfer curve
        np.testing.assert_allclose(col[idx], srgb_to_linear(lut[lab_corner]), atol=1e-6)
        assert col.dtype == np.float32 and 0 <= col.min() and col.max() <= 1
    mat = g.materials[0]
    assert mat.pbrMetallicRoughness.baseColorTexture.index == 0
    assert mat.pbrMetallicRoughness.baseColorFactor in (None, [1, 1, 1, 1])  # the texture as it is
    # KHR_materials_variants: "photo" = the texture material, "segmentation" = flat palette colour per class
    assert [v["name"] for v in g.extensions["KHR_materials_variants"]["variants"]] == ["photo", "segmentation"]
    assert "KHR_materials_variants" in g.extensionsUsed and "KHR_materials_variants" not in (g.extensionsRequired or [])
    for m in cs.meshes:
        prim = g.meshes[nodes[m.name].mesh].primitives[0]
        maps = {tuple(x["variants"]): x["material"] for x in prim.extensions["KHR_materials_variants"]["mappings"]}
        assert prim.material == maps[(0,)] == 0
        seg = g.materials[maps[(1,)]]
        assert seg.pbrMetallicRoughness.baseColorTexture is None
        np.testing.assert_allclose(seg.pbrMetallicRoughness.baseColorFactor[:3],
                                   srgb_to_linear(np.array([BY_ID[m.class_id].color]))[0], atol=1e-6)
    img = g.images[0]
    bv = g.bufferViews[img.bufferView]
    im = Image.open(io.BytesIO(blob[bv.byteOffset: bv.byteOffset + bv.byteLength]))
    assert im.size == Image.open(cs.texture).size


def _gltf_validator() -> Path | None:
    repo = Path(__file__).resolve().parents[3]  # package.json installs it there (scripts/setup.sh: npm ci)
    for base in (os.environ.get("TWINKIT_GLTF_VALIDATOR", ""), str(repo), "/tmp/gv"):
        if base and (Path(base) / "node_modules" / "gltf-validator").exists():
            return Path(base)
    return None


def test_glb_passes_khronos_validator(glb_out, tmp_path):
    base = _gltf_validator()
    if base is None or not shutil.which("node"):
        pytest.skip("Khronos glTF validator not installed (npm install gltf-validator; TWINKIT_GLTF_VALIDATOR=<dir>)")
    js = tmp_path / "val.js"
    js.write_text(
        "const v = require('gltf-validator'); const fs = require('fs');\n"
        "v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2]))).then(r => "
        "console.log(JSON.stringify({e: r.issues.numErrors, w: r.issues.numWarnings, m: r.issues.messages.slice(0, 5)})));\n")
    res = subprocess.run(["node", str(js), str(glb_out)], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "NODE_PATH": str(base / "node_modules")})
    rep = json.loads(res.stdout)
    assert rep["e"] == 0 and rep["w"] == 0, rep


@pytest.fixture(scope="module")
def artifacts_dir() -> Path:
    """Pictures kept for a person to look at: $TWINKIT_TEST_ARTIFACTS/export (default build/test-artifacts)."""
    base = os.environ.get("TWINKIT_TEST_ARTIFACTS") or Path(__file__).resolve().parents[3] / "build" / "test-artifacts"
    d = Path(base) / "export"
    d.mkdir(parents=True, exist_ok=True)
    return d


@pytest.fixture(scope="module")
def glb_driver():
    from glb_render import start_driver, stop_driver

    d = start_driver()
    if isinstance(d, str):
        pytest.skip(d)
    yield d
    stop_driver(d)


def test_glb_renders_as_bright_as_its_texture(glb_out, class_dir, glb_driver, tmp_path, artifacts_dir):
    """three.js's GLTFLoader (a standard viewer) draws the exported GLB as bright as its texture alone;
    the layout before (CityScapes palette in COLOR_0, which multiplies the texture) did not."""
    from PIL import Image

    from glb_render import brightness_ratio
    from twinkit.mesh.glb import GlbPart, write_textured_glb

    now = brightness_ratio(glb_driver, glb_out, tmp_path / "now")
    img, ref = now.pop("images")
    Image.fromarray(img).save(artifacts_dir / "glb_as_loaded.png")
    Image.fromarray(ref).save(artifacts_dir / "glb_texture_only.png")
    assert now["meshes"] == len(load_class_set(class_dir).meshes) and now["vertexColors"] == 0
    assert now["basic"] == now["meshes"]  # KHR_materials_unlit: the texture as captured
    assert now["covered_px"] > 10_000
    assert now["ratio"] == pytest.approx(1.0, abs=0.02), now
    assert now["px_off_by_more_than_8"] < 0.01, now
    # the same class meshes written the old way: palette as COLOR_0
    cs = load_class_set(class_dir)
    old = tmp_path / "old.glb"
    write_textured_glb(old, [GlbPart(m.name, m.mesh.vertices, m.mesh.faces, m.mesh.normals, m.mesh.corner_uv, m.mesh.colors)
                             for m in cs.meshes], cs.texture, generator="old layout")
    before = brightness_ratio(glb_driver, old, tmp_path / "old")
    before.pop("images")
    assert before["vertexColors"] == before["meshes"] and before["ratio"] < 0.8, before  # 0.59 on this street


def test_the_bpy_interpreter_comes_from_the_environment_not_from_a_config(monkeypatch, tmp_path):
    """An executable is never a parameter (a site or recipe file is data): $TWINKIT_BPY_PYTHON picks it."""
    import dataclasses
    import sys

    import pytest

    from twinkit_export import plugin as export_plugin
    from twinkit_export.fbx import FbxExportError, bpy_python

    for cls in (export_plugin.FbxParams, export_plugin.CarlaPackageParams):
        assert "python" not in {f.name for f in dataclasses.fields(cls)}
    monkeypatch.delenv("TWINKIT_BPY_PYTHON", raising=False)
    assert bpy_python() == ""
    monkeypatch.setenv("TWINKIT_BPY_PYTHON", str(tmp_path / "no-such-python"))
    with pytest.raises(FbxExportError, match="TWINKIT_BPY_PYTHON=.*is not an executable file"):
        bpy_python()
    monkeypatch.setenv("TWINKIT_BPY_PYTHON", sys.executable)
    assert bpy_python() == sys.executable

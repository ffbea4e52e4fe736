"""USD export through usd-core (pxr), and validation with usd-core's own validators.

Layout::

    /Site                      Xform, kind=component, defaultPrim; OmniWGS84ReferencePositionAPI
      /Site/Looks/M_twinkit    Material: UsdPreviewSurface <- UsdUVTexture(file=@./<texture>@) <- st reader
      /Site/Road_Road          Mesh per class: points, normals, primvars:st (faceVarying, indexed),
      /Site/Road_Sidewalk ...    primvars:displayColor (vertex, CityScapes palette, linear),
                                 primvars:class_id / primvars:source_index (int, vertex),
                                 SemanticsLabelsAPI:class  semantics:labels:class = ["road"],
                                 twinkit:classId, twinkit:carlaName, material:binding,
                                 + SemanticsAPI:Semantics (the older Isaac schema Isaac Sim < 5.0 reads):
                                   semantic:Semantics:params:semanticType = "class",
                                   semantic:Semantics:params:semanticData = "road"
                                 + static classes: PhysicsCollisionAPI, PhysicsMeshCollisionAPI
                                   (physics:approximation = "none": the triangle mesh itself)
      /Site/CesiumGeoreference CesiumGeoreferencePrim (Cesium for Omniverse): cesium:georeferenceOrigin:
                               latitude / longitude / height of the base point (inside the default prim:
                               a reference to the file keeps it)

Stage metadata: upAxis Z, metersPerUnit 1; the site georeference is the root layer's
``customLayerData["twinkit:georeference"]`` (crs, lat/lon/alt of the base point, projected
base point, frame description, grid convergence and scale at the base point, ``stage_frame``,
``site_to_enu``, ``height_kind``).

The stage is in the frame its georeference declares. /Site carries NVIDIA Omniverse's geospatial
``OmniWGS84ReferencePositionAPI`` (``omni:geospatial:wgs84:reference:referencePosition`` = (lat,
lon, height), ``...:tangentPlane`` = ENU) and /Site/CesiumGeoreference Cesium's origin; both read the
stage's world coordinates as east-north-up metres at that point. Every class mesh prim (and /Site/Movables) keeps its points in the
site frame (grid east / grid north, grid metres: the same numbers as the FBX, GLB and ``source_index``)
and has one transform op, the similarity :func:`twinkit.geo.enu.site_to_enu` fits (rotation by the grid
convergence, 1.79 deg on the demo; scale 1/k), so world positions are ENU: 150 m from the base point the
schemas' reading lands within 0.03 mm of the site CRS's own lon/lat (4.7 m without the transform). The
height is written as the schemas expect it (above the WGS84 ellipsoid) where the site CRS is compound and
PROJ has its geoid grid; otherwise it is the base point's own height and ``twinkit:heightKind``
(``orthometric`` / ``undeclared``) and ``twinkit:heightReference`` on both prims say so.

Colliders: every class except the movable ones (person, rider, car, truck, bus, train,
motorcycle, bicycle: they move or get lifted out of the static map), sky and unlabelled.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .classes import info


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    c = c.astype(np.float32) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def _prim_name(name: str) -> str:
    out = "".join(ch if (ch.isalnum() or ch == "_") else "_" for ch in name)
    return out if out and not out[0].isdigit() else f"_{out}"


#: CityScapes trainIds that get no collider: the movable classes (11 person, 12 rider, 13 car, 14 truck,
#: 15 bus, 16 train, 17 motorcycle, 18 bicycle), sky (10) and unlabelled (255)
NO_COLLIDER = frozenset({10, 11, 12, 13, 14, 15, 16, 17, 18, 255})
#: the older Isaac Sim semantics schema (isaacsim/omni "Semantics" module; Isaac Sim before 5.0 reads it)
OLD_SEMANTICS_INSTANCE = "Semantics"
OMNI_GEO = "omni:geospatial:wgs84:reference:"
CESIUM_GEOREFERENCE_NAME = "CesiumGeoreference"
#: the site frame -> ENU similarity is fitted over this radius about the base point (m)
ENU_RADIUS_M = 150.0
STAGE_FRAME = ("east-north-up at the base point (lat, lon, enu_height_m): every mesh prim's points are in the site "
               "frame and its transform op (site_to_enu) puts them in ENU; world positions are ENU metres")


def geo_anchor(georef: dict) -> dict:
    """The base point's height for a consumer that wants it above the WGS84 ellipsoid, and what that height is.

    Keys: ``height_m``; ``height_kind``: ``"ellipsoidal"`` (converted: the site CRS is compound and PROJ has
    its geoid grid), ``"orthometric"`` (the CRS declares a vertical datum, e.g. N2000, but the geoid grid is
    missing: the height is above the geoid, not the ellipsoid) or ``"undeclared"`` (a 2D CRS: the survey's own
    height, unconverted); ``height_reference`` (the same in words, with the datum); with a georeferenced
    site also ``grid_convergence_deg`` (angle from true north to grid north, positive clockwise) and
    ``point_scale_factor`` of the site CRS at the base point."""
    out: dict = {"height_m": float(georef.get("alt", 0.0)), "height_kind": "undeclared",
                 "height_reference": "the site's base point height as given (not converted to WGS84 ellipsoidal)"}
    frame = _site_frame(georef)
    if frame is None:
        return out
    datum = frame.vertical_datum
    if not datum.startswith("undeclared"):
        out.update(height_kind="orthometric",
                   height_reference=f"height in {datum}, not converted to WGS84 ellipsoidal (no geoid grid at hand)")
    try:
        out["height_m"] = float(frame.ellipsoidal_heights(np.zeros((1, 3)))[0])
        out.update(height_kind="ellipsoidal",
                   height_reference=f"WGS84 ellipsoidal height (converted from {datum})")
    except Exception:
        pass
    try:
        from pyproj import Proj

        fac = Proj(frame.projected).get_factors(georef["lon"], georef["lat"])
        out["grid_convergence_deg"] = float(fac.meridian_convergence)
        out["point_scale_factor"] = float(fac.meridional_scale)
    except Exception:
        pass
    return out


def _site_frame(georef: dict):
    """The :class:`twinkit.geo.SiteFrame` of an export's georeference block, or None without lat/lon/crs."""
    if "lat" not in georef or "lon" not in georef or not georef.get("crs"):
        return None
    try:
        from twinkit.geo.frame import SiteFrame

        return SiteFrame.from_site({"name": "usd", "crs": georef["crs"],
                                    "base_point": {"lat": georef["lat"], "lon": georef["lon"],
                                                   "alt": georef.get("alt", 0.0)}})
    except Exception:
        return None


def enu_frame(georef: dict, anchor: dict):
    """The :class:`twinkit.geo.enu.EnuFrame` the stage is written in (site frame -> east-north-up at the base
    point, fitted over ``ENU_RADIUS_M``), or None when the georeference has no site CRS (the stage stays in
    the site frame and declares no ENU reference)."""
    frame = _site_frame(georef)
    if frame is None:
        return None
    from twinkit.geo.enu import site_to_enu

    return site_to_enu(frame, anchor["height_m"], ENU_RADIUS_M)


def _georeference(stage, root, georef: dict, geo_schemas: bool):
    """The georeference on the stage: layer custom data, and (``geo_schemas``, with a site CRS) the Omniverse
    WGS84 reference position on the default prim and a Cesium georeference prim inside it, both east-north-up
    at the base point with the height marked ellipsoidal / orthometric / undeclared. Returns the
    :class:`EnuFrame` the meshes must be put in by their transform (None: the stage is the site frame)."""
    from pxr import Gf, Sdf

    layer = stage.GetRootLayer()
    anchor = geo_anchor(georef) if geo_schemas else {}
    enu = enu_frame(georef, anchor) if geo_schemas else None
    data = {**georef, **{k: v for k, v in anchor.items() if k != "height_m"}}
    if enu is None:
        data["stage_frame"] = "the site frame (see frame): no ENU reference declared"
    else:
        data.update(stage_frame=STAGE_FRAME, enu_height_m=enu.height_m,
                    site_to_enu={"rotation_deg": math.degrees(enu.rotation_rad), "scale": enu.scale,
                                 "residual_m": enu.residual_m, "radius_m": enu.radius_m})
    layer.customLayerData = {"twinkit:georeference": data}
    if enu is None:
        return None
    # NVIDIA Omniverse geospatial: the reference position of everything below /Site (ENU tangent plane)
    rp = root.GetPrim()
    rp.AddAppliedSchema("OmniWGS84ReferencePositionAPI")
    rp.CreateAttribute(OMNI_GEO + "referencePosition", Sdf.ValueTypeNames.Double3, custom=False).Set(
        Gf.Vec3d(float(georef["lat"]), float(georef["lon"]), enu.height_m))
    rp.CreateAttribute(OMNI_GEO + "tangentPlane", Sdf.ValueTypeNames.Token, custom=False,
                       variability=Sdf.VariabilityUniform).Set("ENU")
    # Cesium for Omniverse: the stage's georeference origin, inside the default prim so a reference keeps it
    cg = stage.DefinePrim(root.GetPath().AppendChild(CESIUM_GEOREFERENCE_NAME), "CesiumGeoreferencePrim")
    for k, v in (("latitude", georef["lat"]), ("longitude", georef["lon"]), ("height", enu.height_m)):
        cg.CreateAttribute(f"cesium:georeferenceOrigin:{k}", Sdf.ValueTypeNames.Double, custom=False).Set(float(v))
    for p in (rp, cg):
        p.CreateAttribute("twinkit:heightKind", Sdf.ValueTypeNames.Token, custom=True).Set(anchor["height_kind"])
        p.CreateAttribute("twinkit:heightReference", Sdf.ValueTypeNames.String, custom=True).Set(
            anchor["height_reference"])
    return enu


def _place(xformable, enu) -> None:
    """The site frame -> ENU similarity as the prim's one transform op (points stay in the site frame)."""
    if enu is None:
        return
    from pxr import Gf

    xformable.AddTransformOp().Set(Gf.Matrix4d(enu.matrix().T.tolist()))  # USD: row vectors, p' = p M


def _material(stage, root_name: str, texture_name: str | None):
    """The one preview-surface material ``/<root>/Looks/M_twinkit``: the texture on st, else mid grey."""
    from pxr import Gf, Sdf, UsdGeom, UsdShade

    looks = UsdGeom.Scope.Define(stage, f"/{root_name}/Looks")
    mat = UsdShade.Material.Define(stage, looks.GetPath().AppendChild("M_twinkit"))
    surf = UsdShade.Shader.Define(stage, mat.GetPath().AppendChild("PreviewSurface"))
    surf.CreateIdAttr("UsdPreviewSurface")
    surf.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(1.0)
    surf.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
    mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
    if texture_name:
        st_in = mat.CreateInput("frame:stPrimvarName", Sdf.ValueTypeNames.String)
        st_in.Set("st")
        reader = UsdShade.Shader.Define(stage, mat.GetPath().AppendChild("stReader"))
        reader.CreateIdAttr("UsdPrimvarReader_float2")
        reader.CreateInput("varname", Sdf.ValueTypeNames.String).ConnectToSource(st_in)
        reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
        tex = UsdShade.Shader.Define(stage, mat.GetPath().AppendChild("DiffuseTexture"))
        tex.CreateIdAttr("UsdUVTexture")
        tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(f"./{texture_name}"))
        tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("sRGB")
        tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("clamp")
        tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set("clamp")
        tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
        tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
        surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(tex.ConnectableAPI(), "rgb")
    else:
        surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.5, 0.5, 0.5))
    return mat


def _mesh_geometry(mesh, cm) -> None:
    """A class mesh's points, extent, triangles, normals and primvars (st faceVarying and indexed,
    displayColor linear, class_id and source_index per vertex) on the UsdGeom.Mesh ``mesh``."""
    from pxr import Gf, Sdf, UsdGeom, Vt

    pts = cm.mesh.vertices.astype(np.float32)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pts))
    mesh.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*pts.min(0).tolist()), Gf.Vec3f(*pts.max(0).tolist())]))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(cm.mesh.n_faces, 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(cm.mesh.faces.astype(np.int32).ravel()))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(cm.mesh.normals.astype(np.float32)))
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    pv = UsdGeom.PrimvarsAPI(mesh.GetPrim())
    # st: faceVarying, indexed (unique UVs)
    uv = cm.mesh.corner_uv.reshape(-1, 2)
    uniq, inv = np.unique(uv, axis=0, return_inverse=True)
    st = pv.CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying)
    st.Set(Vt.Vec2fArray.FromNumpy(uniq.astype(np.float32)))
    st.SetIndices(Vt.IntArray.FromNumpy(inv.astype(np.int32).ravel()))
    dc = pv.CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.vertex)
    dc.Set(Vt.Vec3fArray.FromNumpy(_srgb_to_linear(cm.mesh.colors)))
    cid = pv.CreatePrimvar("class_id", Sdf.ValueTypeNames.IntArray, UsdGeom.Tokens.vertex)
    cid.Set(Vt.IntArray.FromNumpy(cm.mesh.attrs["class_id"].astype(np.int32)))
    src = pv.CreatePrimvar("source_index", Sdf.ValueTypeNames.IntArray, UsdGeom.Tokens.vertex)
    src.Set(Vt.IntArray.FromNumpy(cm.mesh.attrs["source_index"].astype(np.int32)))


def _semantics(prim, cm, semantics_taxonomy: str, old_semantics: bool) -> None:
    """The class on the prim: twinkit attributes, UsdSemantics labels (or a plain attribute on older
    usd-core) and, with ``old_semantics``, Isaac Sim's older SemanticsAPI."""
    from pxr import Sdf, Vt

    try:
        from pxr import UsdSemantics
    except ImportError:  # older usd-core: a documented plain attribute instead
        UsdSemantics = None
    ci = info(cm.class_id)
    prim.CreateAttribute("twinkit:classId", Sdf.ValueTypeNames.Int, custom=True).Set(int(cm.class_id))
    prim.CreateAttribute("twinkit:cityscapesName", Sdf.ValueTypeNames.String, custom=True).Set(ci.name)
    prim.CreateAttribute("twinkit:carlaTag", Sdf.ValueTypeNames.String, custom=True).Set(ci.carla_tag)
    if UsdSemantics is not None:
        labels = UsdSemantics.LabelsAPI.Apply(prim, semantics_taxonomy)
        labels.CreateLabelsAttr().Set(Vt.TokenArray([ci.name]))
    else:
        prim.CreateAttribute("twinkit:semanticLabel", Sdf.ValueTypeNames.Token, custom=True).Set(ci.name)
    if old_semantics:
        inst = OLD_SEMANTICS_INSTANCE
        prim.AddAppliedSchema(f"SemanticsAPI:{inst}")
        prim.CreateAttribute(f"semantic:{inst}:params:semanticType", Sdf.ValueTypeNames.String,
                             custom=False).Set("class")
        prim.CreateAttribute(f"semantic:{inst}:params:semanticData", Sdf.ValueTypeNames.String,
                             custom=False).Set(ci.name)


def write_usd(meshes, texture_name: str | None, out: Path, georef: dict, *, root_name: str = "Site",
              semantics_taxonomy: str = "class", colliders: bool = True, old_semantics: bool = True,
              geo_schemas: bool = True, movables=()) -> dict:
    """Write the stage to ``out`` (.usd = binary crate, .usda = text); ``texture_name`` is relative to ``out``.

    ``movables``: class meshes of the objects lifted out of the static map (``lift_movables``), one
    prim each under ``/<root>/Movables`` (named by the mesh's ``name``, e.g. ``Car_000``), with the
    same semantics and material and never a collider, so they can be moved or deleted."""
    from pxr import Usd, UsdGeom, UsdPhysics, UsdShade

    out = Path(out)
    stage = Usd.Stage.CreateNew(str(out))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, f"/{root_name}")
    stage.SetDefaultPrim(root.GetPrim())
    Usd.ModelAPI(root.GetPrim()).SetKind("component")
    layer = stage.GetRootLayer()
    enu = _georeference(stage, root, georef, geo_schemas)
    layer.documentation = "twinkit digital twin: one Mesh per CityScapes class (site frame, metres, z up)"
    mat = _material(stage, root_name, texture_name)

    stats = {}
    mov_parent = None
    if movables:
        mov_xf = UsdGeom.Xform.Define(stage, root.GetPath().AppendChild("Movables"))
        _place(mov_xf, enu)
        mov_parent = mov_xf.GetPath()
    for cm, parent in [(m, root.GetPath()) for m in meshes] + [(m, mov_parent) for m in movables]:
        if cm.mesh.n_faces == 0:
            continue
        movable = parent != root.GetPath()
        mesh = UsdGeom.Mesh.Define(stage, parent.AppendChild(_prim_name(cm.name)))
        prim = mesh.GetPrim()
        _mesh_geometry(mesh, cm)
        if not movable:
            _place(mesh, enu)
        _semantics(prim, cm, semantics_taxonomy, old_semantics)
        collider = colliders and int(cm.class_id) not in NO_COLLIDER and not movable
        if collider:
            UsdPhysics.CollisionAPI.Apply(prim).CreateCollisionEnabledAttr(True)
            UsdPhysics.MeshCollisionAPI.Apply(prim).CreateApproximationAttr(UsdPhysics.Tokens.none)
        UsdShade.MaterialBindingAPI.Apply(prim).Bind(mat)
        stats[f"Movables/{cm.name}" if movable else cm.name] = {"points": cm.mesh.n_vertices, "faces": cm.mesh.n_faces, "collider": bool(collider)}
    layer.Save()
    return stats


def validate_usd(path: Path) -> list[str]:
    """Run every validator usd-core registers (UsdValidation); returns the error messages.

    Falls back to ``UsdUtils.ComplianceChecker`` only where this usd-core has no UsdValidation.
    """
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    try:
        from pxr import UsdValidation
    except ImportError:
        from pxr import UsdUtils

        checker = UsdUtils.ComplianceChecker(arkit=False, skipARKitRootLayerCheck=True)
        checker.CheckCompliance(str(path))
        return list(checker.GetErrors()) + list(checker.GetFailedChecks())
    reg = UsdValidation.ValidationRegistry()
    validators = reg.GetOrLoadAllValidators()
    ctx = UsdValidation.ValidationContext(validators)
    errors = ctx.Validate(stage)
    return [f"{e.GetName()}: {e.GetMessage()}" for e in errors
            if e.GetType() == UsdValidation.ValidationErrorType.Error]


def validation_report(path: Path) -> dict:
    """{errors, warnings, messages, validators} from UsdValidation (every registered validator).

    On a usd-core without UsdValidation (before 24.11) this falls back to UsdUtils.ComplianceChecker.
    """
    from pxr import Usd

    try:
        from pxr import UsdValidation
    except ImportError:
        errs = validate_usd(path)
        return {"validators": 0, "checker": "UsdUtils.ComplianceChecker", "errors": len(errs), "warnings": 0,
                "messages": errs[:50]}

    stage = Usd.Stage.Open(str(path))
    reg = UsdValidation.ValidationRegistry()
    validators = reg.GetOrLoadAllValidators()
    res = UsdValidation.ValidationContext(validators).Validate(stage)
    T = UsdValidation.ValidationErrorType
    return {
        "validators": len(validators),
        "errors": sum(1 for e in res if e.GetType() == T.Error),
        "warnings": sum(1 for e in res if e.GetType() == T.Warn),
        "messages": [f"{e.GetType()} {e.GetName()}: {e.GetMessage()}" for e in res][:50],
    }

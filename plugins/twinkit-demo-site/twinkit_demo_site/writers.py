"""File writers (deterministic: no timestamps, no random GUIDs)."""
from __future__ import annotations

import datetime as _dt
import hashlib
import json
import uuid
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from twinkit.mesh import Mesh
from twinkit_demo_site.layout import LABELS
from twinkit_demo_site.textures import Atlas

LABEL_NAMES = {v: k for k, v in LABELS.items()}
FIXED_DATE = _dt.date(2024, 6, 1)
SLICE = 2_000_000


def det_guid(*parts) -> str:
    """A GUID derived from ``parts`` (stable across runs)."""
    h = hashlib.sha256(repr(parts).encode()).digest()[:16]
    return "{%s}" % uuid.UUID(bytes=h)


def write_json(path: Path, obj) -> None:
    Path(path).write_text(json.dumps(obj, indent=1, sort_keys=True, default=_json_default) + "\n")


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o))


# ---------------------------------------------------------------- mesh
def _face_order(mesh: Mesh) -> np.ndarray:
    return np.argsort(mesh.face_attrs["label"], kind="stable")


def write_obj(path: Path, mesh: Mesh, atlas: Atlas) -> None:
    """OBJ + MTL + PNG atlas (companions share the OBJ's stem; twinkit.mesh.write_obj). Faces grouped by
    class (``g road_0`` ...)."""
    from PIL import Image

    from twinkit.mesh import write_obj as write_mesh_obj

    path = Path(path)
    png = path.with_suffix(".png")
    Image.fromarray(atlas.image).save(png, optimize=False, compress_level=6)
    order = _face_order(mesh)
    lab = mesh.face_attrs["label"][order]
    ids, counts = np.unique(lab, return_counts=True)  # sorted, as the faces are
    groups = [(f"{LABEL_NAMES.get(int(lb), 'class').replace(' ', '_')}_{int(lb)}", int(c)) for lb, c in zip(ids, counts)]
    write_mesh_obj(path, mesh.vertices, mesh.faces[order], mesh.attrs["uv"], png.name, material="atlas",
                   comment="twinkit demo site: ground-truth mesh, site frame (metres, z up)\n"
                           f"{len(mesh.vertices)} vertices, {len(mesh.faces)} faces; groups are CityScapes classes "
                           "(trainId in name)",
                   mtl_comment="twinkit demo site ground truth", mtl_dissolve=False, decimals=5, uv_decimals=6,
                   groups=groups)


def gt_ply_mesh(mesh: Mesh, atlas: Atlas):
    """The ground truth as the PLY of ``gt_mesh.ply`` (a :class:`twinkit.mesh.Mesh`): vertex x y z (float32)
    u v red green blue label; face vertex_indices label.

    Face order equals the OBJ's (grouped by class); vertex colours are the texture at the vertex UV.
    """
    col = np.clip(atlas.sample(mesh.attrs["uv"]) * 255 + 0.5, 0, 255).astype(np.uint8)
    uv = np.asarray(mesh.attrs["uv"]).astype(np.float32)
    order = _face_order(mesh)
    return Mesh(
        vertices=mesh.vertices, faces=mesh.faces[order],
        attrs={"u": uv[:, 0], "v": uv[:, 1], "colors": col, "label": mesh.attrs["label"].astype(np.uint8, copy=False)},
        face_attrs={"label": mesh.face_attrs["label"][order].astype(np.uint8, copy=False)},
        comments=["twinkit demo site ground truth, site frame (metres, z up); label = CityScapes trainId"])


# ---------------------------------------------------------------- point cloud
def write_cloud_ply(path: Path, cloud: dict) -> None:
    """Binary PLY point cloud in the site frame (twinkit.mesh.write_ply; vertex rows written in slices):
    x y z nx ny nz (float32) red green blue label (uchar) scanner (uint)."""
    from twinkit.mesh import write_ply

    write_ply(path, Mesh(
        vertices=cloud["xyz"],
        attrs={"normals": cloud["normals"], "colors": cloud["rgb"],
               "label": np.asarray(cloud["label"]).astype(np.uint8, copy=False),
               "scanner": np.asarray(cloud["scanner"]).astype(np.uint32, copy=False)},
        comments=["twinkit demo site point cloud, site frame (metres, z up)",
                  "label = CityScapes trainId (11 = ghost points of a passing pedestrian); "
                  "scanner = index into scanners.json"]))


ASPRS = {0: 11, 1: 2, 9: 2, 2: 6, 8: 5}  # trainId -> ASPRS class (road surface, ground, building, high vegetation)


def write_las(path: Path, cloud: dict, geo, gps_time: np.ndarray) -> None:
    """LAS 1.4, point format 7 (RGB, GPS time), CRS WKT in the header, scale 0.001, projected coordinates.

    Extra dimensions: ``label`` (uint8 trainId), ``scanner`` (uint32), ``normal_x/y/z`` (float32).
    """
    import laspy
    from pyproj import CRS

    n = len(cloud["xyz"])
    hdr = laspy.LasHeader(point_format=7, version="1.4")
    hdr.scales = np.array([0.001, 0.001, 0.001])
    hdr.offsets = np.array([np.floor(geo.easting / 1000) * 1000, np.floor(geo.northing / 1000) * 1000, 0.0])
    hdr.add_extra_dims([
        laspy.ExtraBytesParams(name="label", type=np.uint8, description="CityScapes trainId"),
        laspy.ExtraBytesParams(name="scanner", type=np.uint32, description="scanner position index"),
        laspy.ExtraBytesParams(name="normal_x", type=np.float32),
        laspy.ExtraBytesParams(name="normal_y", type=np.float32),
        laspy.ExtraBytesParams(name="normal_z", type=np.float32),
    ])
    hdr.add_crs(CRS.from_user_input(geo.crs))
    hdr.creation_date = FIXED_DATE
    hdr.system_identifier = "twinkit demo site"
    hdr.generating_software = "twinkit-demo-site"
    hdr.global_encoding.gps_time_type = laspy.header.GpsTimeType.STANDARD
    asprs = np.ones(256, np.uint8)
    for k, v in ASPRS.items():
        asprs[k] = v
    with laspy.open(path, mode="w", header=hdr) as w:
        for a in range(0, n, SLICE):
            b = min(n, a + SLICE)
            rec = laspy.ScaleAwarePointRecord.zeros(b - a, header=hdr)
            xyz = cloud["xyz"][a:b]
            rec.x = xyz[:, 0] + geo.easting
            rec.y = xyz[:, 1] + geo.northing
            rec.z = xyz[:, 2] + geo.alt
            rec.red = cloud["rgb"][a:b, 0].astype(np.uint16) * 257
            rec.green = cloud["rgb"][a:b, 1].astype(np.uint16) * 257
            rec.blue = cloud["rgb"][a:b, 2].astype(np.uint16) * 257
            rec.intensity = cloud["intensity"][a:b]
            rec.classification = asprs[cloud["label"][a:b]]
            rec.gps_time = gps_time[a:b]
            rec.label = cloud["label"][a:b]
            rec.scanner = cloud["scanner"][a:b]
            rec.normal_x = cloud["normals"][a:b, 0]
            rec.normal_y = cloud["normals"][a:b, 1]
            rec.normal_z = cloud["normals"][a:b, 2]
            w.write_points(rec)


def write_e57(path: Path, cloud: dict, geo, guid_seed, scanner_xyz: np.ndarray) -> None:
    """ASTM E57 with one scan: cartesianX/Y/Z (float64, projected CRS), RGB, intensity, normals (``nor:`` extension).

    Written with libE57Format (via pye57's bindings) with fixed GUIDs and dates.
    """
    from pye57 import libe57

    path = str(path)
    imf = libe57.ImageFile(path, "w")
    try:
        data3d = _e57_root(imf, geo, guid_seed)
        X = cloud["xyz"][:, 0] + geo.easting
        Y = cloud["xyz"][:, 1] + geo.northing
        Z = cloud["xyz"][:, 2] + geo.alt
        lo = [float(X.min()), float(Y.min()), float(Z.min())]
        hi = [float(X.max()), float(Y.max()), float(Z.max())]
        scan = _e57_scan(imf, geo, guid_seed, lo, hi)
        points = libe57.CompressedVectorNode(imf, _e57_prototype(imf, lo, hi), libe57.VectorNode(imf, True))
        scan.set("points", points)
        data3d.append(scan)
        _e57_write_points(imf, points, (X, Y, Z), cloud)
    finally:
        imf.close()


def _e57_root(imf, geo, guid_seed):
    """Fill the file's root (format, GUID, CRS as WKT, fixed creation date); returns its empty data3D vector."""
    from pye57 import libe57
    from pyproj import CRS

    imf.extensionsAdd("nor", "http://www.libe57.org/E57_NOR_surface_normals.txt")
    root = imf.root()
    root.set("formatName", libe57.StringNode(imf, "ASTM E57 3D Imaging Data File"))
    root.set("guid", libe57.StringNode(imf, det_guid("file", *guid_seed)))
    root.set("versionMajor", libe57.IntegerNode(imf, libe57.E57_FORMAT_MAJOR))
    root.set("versionMinor", libe57.IntegerNode(imf, libe57.E57_FORMAT_MINOR))
    root.set("e57LibraryVersion", libe57.StringNode(imf, libe57.E57_LIBRARY_ID))
    root.set("coordinateMetadata", libe57.StringNode(imf, CRS.from_user_input(geo.crs).to_wkt()))
    cdt = libe57.StructureNode(imf)
    cdt.set("dateTimeValue", libe57.FloatNode(imf, 1401235200.0))  # fixed GPS time (2024-06-01)
    cdt.set("isAtomicClockReferenced", libe57.IntegerNode(imf, 0))
    root.set("creationDateTime", cdt)
    data3d = libe57.VectorNode(imf, True)
    root.set("data3D", data3d)
    root.set("images2D", libe57.VectorNode(imf, True))
    return data3d


def _e57_scan(imf, geo, guid_seed, lo: list[float], hi: list[float]):
    """The scan's header: GUID, name, bounds ``lo``/``hi`` (projected metres), colour and intensity limits, identity
    pose and fixed acquisition times."""
    from pye57 import libe57

    scan = libe57.StructureNode(imf)
    scan.set("guid", libe57.StringNode(imf, det_guid("scan", *guid_seed)))
    scan.set("name", libe57.StringNode(imf, "twinkit demo site mobile mapping"))
    scan.set("description", libe57.StringNode(imf, "simulated mobile mapping, coordinates in " + geo.crs))
    bb = libe57.StructureNode(imf)
    for k, a, b in zip("xyz", lo, hi):
        bb.set(f"{k}Minimum", libe57.FloatNode(imf, a))
        bb.set(f"{k}Maximum", libe57.FloatNode(imf, b))
    scan.set("cartesianBounds", bb)
    cl = libe57.StructureNode(imf)
    for c in ("Red", "Green", "Blue"):
        cl.set(f"color{c}Minimum", libe57.IntegerNode(imf, 0))
        cl.set(f"color{c}Maximum", libe57.IntegerNode(imf, 255))
    scan.set("colorLimits", cl)
    il = libe57.StructureNode(imf)
    il.set("intensityMinimum", libe57.FloatNode(imf, 0.0))
    il.set("intensityMaximum", libe57.FloatNode(imf, 1.0))
    scan.set("intensityLimits", il)
    pose = libe57.StructureNode(imf)
    rot = libe57.StructureNode(imf)
    for k, v in zip("wxyz", (1.0, 0.0, 0.0, 0.0)):
        rot.set(k, libe57.FloatNode(imf, v))
    tr = libe57.StructureNode(imf)
    for k in "xyz":
        tr.set(k, libe57.FloatNode(imf, 0.0))
    pose.set("rotation", rot)
    pose.set("translation", tr)
    scan.set("pose", pose)
    for key, val in (("acquisitionStart", 1401235200.0), ("acquisitionEnd", 1401235200.0 + 600)):
        st = libe57.StructureNode(imf)
        st.set("dateTimeValue", libe57.FloatNode(imf, val))
        st.set("isAtomicClockReferenced", libe57.IntegerNode(imf, 0))
        scan.set(key, st)
    return scan


def _e57_prototype(imf, lo: list[float], hi: list[float]):
    """The point record: cartesianX/Y/Z (float64 within the bounds), 8-bit RGB, float32 intensity and normals."""
    from pye57 import libe57

    proto = libe57.StructureNode(imf)
    for k, a, b in zip(("cartesianX", "cartesianY", "cartesianZ"), lo, hi):
        proto.set(k, libe57.FloatNode(imf, a, libe57.E57_DOUBLE, a, b))
    for c in ("colorRed", "colorGreen", "colorBlue"):
        proto.set(c, libe57.IntegerNode(imf, 0, 0, 255))
    proto.set("intensity", libe57.FloatNode(imf, 0.0, libe57.E57_SINGLE, 0.0, 1.0))
    for k in ("nor:normalX", "nor:normalY", "nor:normalZ"):
        proto.set(k, libe57.FloatNode(imf, 0.0, libe57.E57_SINGLE, -1.0, 1.0))
    return proto


def _e57_write_points(imf, points, XYZ, cloud: dict) -> None:
    """Stream the points into ``points`` in slices of SLICE: projected ``XYZ`` (three (n,) float64 arrays), the
    cloud's rgb, intensity (uint16 -> 0..1) and normals."""
    from pye57 import libe57

    X, Y, Z = XYZ
    n = len(cloud["xyz"])
    cap = min(SLICE, max(n, 1))
    arrs = {
        "cartesianX": np.empty(cap, "d"), "cartesianY": np.empty(cap, "d"), "cartesianZ": np.empty(cap, "d"),
        "colorRed": np.empty(cap, "B"), "colorGreen": np.empty(cap, "B"), "colorBlue": np.empty(cap, "B"),
        "intensity": np.empty(cap, "f"),
        "nor:normalX": np.empty(cap, "f"), "nor:normalY": np.empty(cap, "f"), "nor:normalZ": np.empty(cap, "f"),
    }
    bufs = libe57.VectorSourceDestBuffer()
    for k, a in arrs.items():
        bufs.append(libe57.SourceDestBuffer(imf, k, a, cap, True, True))
    writer = points.writer(bufs)
    for a in range(0, n, cap):
        b = min(n, a + cap)
        m = b - a
        arrs["cartesianX"][:m] = X[a:b]
        arrs["cartesianY"][:m] = Y[a:b]
        arrs["cartesianZ"][:m] = Z[a:b]
        for i, c in enumerate(("colorRed", "colorGreen", "colorBlue")):
            arrs[c][:m] = cloud["rgb"][a:b, i]
        arrs["intensity"][:m] = cloud["intensity"][a:b] / 65535.0
        for i, k in enumerate(("nor:normalX", "nor:normalY", "nor:normalZ")):
            arrs[k][:m] = cloud["normals"][a:b, i]
        writer.write(m)
    writer.close()


# ---------------------------------------------------------------- OSM
def osm_text(nodes: dict[int, tuple[float, float, dict]], ways: list, geo) -> str:
    """OpenStreetMap XML 0.6 (the text of ``roads.osm``); node coordinates are site-frame metres converted
    with ``geo``."""
    ids = sorted(nodes)
    xy = np.array([[nodes[i][0], nodes[i][1]] for i in ids])
    ll = geo.local_to_lonlat(xy)
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', '<osm version="0.6" generator="twinkit-demo-site">']
    lines.append(f'  <bounds minlat="{ll[:, 1].min():.7f}" minlon="{ll[:, 0].min():.7f}" '
                 f'maxlat="{ll[:, 1].max():.7f}" maxlon="{ll[:, 0].max():.7f}"/>')
    for i, (lon, lat) in zip(ids, ll):
        tags = nodes[i][2]
        attrs = f'id="{i}" version="1" visible="true" lat="{lat:.8f}" lon="{lon:.8f}"'
        if tags:
            lines.append(f"  <node {attrs}>")
            for k in sorted(tags):
                lines.append(f"    <tag k={quoteattr(k)} v={quoteattr(str(tags[k]))}/>")
            lines.append("  </node>")
        else:
            lines.append(f"  <node {attrs}/>")
    for wid, refs, tags in ways:
        lines.append(f'  <way id="{wid}" version="1" visible="true">')
        for r in refs:
            lines.append(f'    <nd ref="{r}"/>')
        for k in sorted(tags):
            lines.append(f"    <tag k={quoteattr(k)} v={quoteattr(str(tags[k]))}/>")
        lines.append("  </way>")
    lines.append("</osm>")
    return "\n".join(lines) + "\n"

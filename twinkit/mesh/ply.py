"""The one PLY path of twinkit: read and write a :class:`~twinkit.mesh.core.Mesh` (cloud or triangle mesh).

Binary PLY (little- or big-endian) whose faces are all triangles is parsed directly with numpy
(``np.fromfile``, one pass); anything else (ASCII, polygons, variable lists, extra elements)
goes through the general reader here (numpy too, row by row only where list lengths vary). Files
are written binary little-endian (ASCII on request). No PLY library is needed (plyfile, GPL-3.0,
is only a test tool that checks these files against an independent reader).

Vertex properties map to ``Mesh.attrs``: ``nx ny nz`` -> ``normals`` (n, 3) float32,
``red green blue`` (also ``r g b``, ``diffuse_*``; floats in [0, 1] and 16-bit values rescaled) ->
``colors`` (n, 3) uint8, any other scalar property under its own name. Face list properties
other than the indices (e.g. ``texcoord``, 6 floats per face) map to ``Mesh.face_attrs``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .core import Mesh

_SCALAR_DTYPES = {
    np.dtype("float32"): "f4",
    np.dtype("float64"): "f8",
    np.dtype("uint8"): "u1",
    np.dtype("int8"): "i1",
    np.dtype("uint16"): "u2",
    np.dtype("int16"): "i2",
    np.dtype("uint32"): "u4",
    np.dtype("int32"): "i4",
}


def _ply_scalar(arr):
    """PLY has no 64-bit integers or booleans: narrow them to int32 / uint32 / uint8."""
    if arr.dtype == np.int64:
        return arr.astype(np.int32)
    if arr.dtype == np.uint64:
        return arr.astype(np.uint32)
    if arr.dtype == bool:
        return arr.astype(np.uint8)
    return arr

def _comment(text: str) -> str:
    """A header comment line: ASCII as the format wants (other letters as ``\\xdf`` escapes: ``straße.ply``
    from a file name), one line (a newline as ``\\n``)."""
    return "comment " + str(text).encode("ascii", "backslashreplace").decode().replace("\n", "\\n").replace("\r", "\\r")


def _write_ply_ascii(path: Path | str, mesh: Mesh, *, xyz_dtype: str = "f4") -> None:
    """Write ``mesh`` as ASCII PLY: the header :func:`write_ply` writes, one row per line, values as
    ``%.18g`` (every float32/float64 reads back exactly)."""
    cols = _vertex_columns(mesh, xyz_dtype)
    head = ["ply", "format ascii 1.0"] + [_comment(c) for c in mesh.comments]
    head.append(f"element vertex {mesh.n_vertices}")
    head += [f"property {_PLY_NAMES[t]} {c}" for c, t, _ in cols]
    fcols: list[np.ndarray] = []
    if mesh.faces is not None:
        head += [f"element face {mesh.n_faces}", "property list uchar int vertex_indices"]
        fcols.append(np.full((mesh.n_faces, 1), 3))
        fcols.append(np.asarray(mesh.faces, np.int64).reshape(-1, 3))
        for name, arr in mesh.face_attrs.items():
            arr = np.asarray(arr)
            if arr.ndim == 2:
                head.append(f"property list uchar float {name}")
                fcols += [np.full((len(arr), 1), arr.shape[1]), arr.astype(np.float32)]
            else:
                t = _SCALAR_DTYPES.get(arr.dtype, "f4")
                head.append(f"property {_PLY_NAMES[t]} {name}")
                fcols.append(arr.astype(t).reshape(-1, 1))
    head.append("end_header")

    def rows(columns: list[np.ndarray]) -> str:
        text = [[f"{x:.18g}" for x in np.asarray(c).ravel()] for c in columns]
        widths = [np.asarray(c).reshape(len(np.asarray(c)), -1).shape[1] for c in columns]
        n = len(np.asarray(columns[0])) if columns else 0
        out = []
        for i in range(n):
            out.append(" ".join(t for col, w in zip(text, widths) for t in col[i * w:(i + 1) * w]))
        return "".join(line + "\n" for line in out)

    vcols = [np.asarray(arr).astype(t) for _, t, arr in cols]
    with open(path, "w", encoding="ascii") as fh:
        fh.write("\n".join(head) + "\n")
        fh.write(rows(vcols))
        if fcols:
            fh.write(rows(fcols))


def _element_dtype(props: list[list[str]], end: str, counts: dict[str, int] | None = None) -> np.dtype:
    """The numpy dtype of one element's rows; a list property becomes ``<name>_n`` (its count) and
    ``<name>`` (``counts[name]`` values), so every row must hold lists of those lengths."""
    fields: list[tuple] = []
    for p in props:
        if p[0] == "list":
            fields += [(p[3] + "_n", end + _PLY_TYPES[p[1]]), (p[3], end + _PLY_TYPES[p[2]], ((counts or {})[p[3]],))]
        else:
            fields.append((p[1], end + _PLY_TYPES[p[0]]))
    return np.dtype(fields)


def _as_lists(arr: np.ndarray, props: list[list[str]]) -> np.ndarray:
    """Rows read with fixed list lengths -> the element's structured array (the count fields dropped)."""
    keep = [p[3] if p[0] == "list" else p[1] for p in props]
    return arr[keep]


def _object_rows(rows: list[list], props: list[list[str]], end: str) -> np.ndarray:
    """Rows whose lists vary in length -> a structured array with an object field per list property."""
    fields = [(p[3], object) if p[0] == "list" else (p[1], end + _PLY_TYPES[p[0]]) for p in props]
    out = np.empty(len(rows), dtype=fields)
    for i, row in enumerate(rows):
        out[i] = tuple(row)
    return out


def _read_binary_element(buf: memoryview, pos: int, count: int, props: list[list[str]], end: str):
    """One element of a binary PLY from ``buf`` at byte ``pos``: (structured array, next position).
    Lists of one length in every row are read in one pass; otherwise row by row."""
    has_list = any(p[0] == "list" for p in props)
    if count == 0:
        return np.empty(0, _element_dtype(props, end, {p[3]: 0 for p in props if p[0] == "list"})), pos
    if not has_list:
        dt = _element_dtype(props, end)
        if pos + dt.itemsize * count > len(buf):
            raise ValueError(f"truncated PLY: {count} rows declared, file too short")
        return np.frombuffer(buf, dt, count, pos).copy(), pos + dt.itemsize * count
    # lengths of the first row's lists, then check every row has them
    counts: dict[str, int] = {}
    q = pos
    for p in props:
        if p[0] == "list":
            ct, it = np.dtype(end + _PLY_TYPES[p[1]]), np.dtype(end + _PLY_TYPES[p[2]])
            if q + ct.itemsize > len(buf):
                raise ValueError("truncated PLY: file too short")
            counts[p[3]] = int(np.frombuffer(buf, ct, 1, q)[0])
            q += ct.itemsize + counts[p[3]] * it.itemsize
        else:
            q += np.dtype(_PLY_TYPES[p[0]]).itemsize
    dt = _element_dtype(props, end, counts)
    if pos + dt.itemsize * count <= len(buf):
        arr = np.frombuffer(buf, dt, count, pos)
        if all(np.all(arr[n + "_n"] == c) for n, c in counts.items()):
            return _as_lists(arr, props).copy(), pos + dt.itemsize * count
    rows = []
    for _ in range(count):
        row = []
        for p in props:
            if p[0] == "list":
                ct, it = np.dtype(end + _PLY_TYPES[p[1]]), np.dtype(end + _PLY_TYPES[p[2]])
                if pos + ct.itemsize > len(buf):
                    raise ValueError("truncated PLY: file too short")
                n = int(np.frombuffer(buf, ct, 1, pos)[0])
                pos += ct.itemsize
                if pos + n * it.itemsize > len(buf):
                    raise ValueError("truncated PLY: file too short")
                row.append(np.frombuffer(buf, it, n, pos).copy())
                pos += n * it.itemsize
            else:
                t = np.dtype(end + _PLY_TYPES[p[0]])
                if pos + t.itemsize > len(buf):
                    raise ValueError("truncated PLY: file too short")
                row.append(np.frombuffer(buf, t, 1, pos)[0])
                pos += t.itemsize
        rows.append(row)
    return _object_rows(rows, props, end), pos


def _read_ascii_element(tokens: list[bytes], pos: int, count: int, props: list[list[str]]):
    """One element of an ASCII PLY from the body's ``tokens`` at index ``pos``: (structured array, next
    index). Lists of one length in every row are converted in one pass; otherwise row by row."""
    if count == 0:
        return np.empty(0, _element_dtype(props, "=", {p[3]: 0 for p in props if p[0] == "list"})), pos
    counts: dict[str, int] = {}
    q = pos
    for p in props:  # the first row's list lengths
        if p[0] == "list":
            if q >= len(tokens):
                raise ValueError("truncated PLY: file too short")
            counts[p[3]] = int(float(tokens[q]))
            q += 1 + counts[p[3]]
        else:
            q += 1
    dt = _element_dtype(props, "=", counts)
    width = q - pos
    if pos + width * count > len(tokens):
        raise ValueError(f"truncated PLY: {count} rows declared, file too short")
    block = np.asarray(tokens[pos:pos + width * count]).astype(np.float64).reshape(count, width)
    uniform = True
    col = 0
    for p in props:
        if p[0] == "list":
            uniform &= bool(np.all(block[:, col] == counts[p[3]]))
            col += 1 + counts[p[3]]
        else:
            col += 1
    if uniform:
        arr = np.empty(count, dtype=dt)
        col = 0
        for p in props:
            if p[0] == "list":
                arr[p[3] + "_n"] = block[:, col]
                arr[p[3]] = block[:, col + 1:col + 1 + counts[p[3]]]
                col += 1 + counts[p[3]]
            else:
                arr[p[1]] = block[:, col]
                col += 1
        return _as_lists(arr, props), pos + width * count
    rows = []
    for _ in range(count):
        row: list = []
        for p in props:
            if pos >= len(tokens):
                raise ValueError("truncated PLY: file too short")
            if p[0] == "list":
                n = int(float(tokens[pos]))
                vals = tokens[pos + 1:pos + 1 + n]
                if len(vals) < n:
                    raise ValueError("truncated PLY: file too short")
                row.append(np.asarray(vals).astype(np.float64).astype(_PLY_TYPES[p[2]]))
                pos += 1 + n
            else:
                row.append(float(tokens[pos]))
                pos += 1
        rows.append(row)
    return _object_rows(rows, props, "="), pos


class PlyExtraData(ValueError):
    """More data follows a PLY's last element than its header declares (``read_ply(..., exact=True)``)."""

    def __init__(self, declared: int, extra_rows: int):
        super().__init__(f"the header declares {declared} vertices but the file holds more (about {extra_rows} "
                         f"more rows after them)")
        self.declared, self.extra_rows = declared, extra_rows


def _check_exact(elements: list[list], left: int, row: int) -> None:
    """Raise :class:`PlyExtraData` when ``left`` bytes (ASCII: values) after the last element make a vertex row."""
    if row > 0 and left >= row:
        nv = next((e[1] for e in elements if e[0] == "vertex"), 0)
        raise PlyExtraData(nv, left // row)


def _read_ply_general(path: Path, fmt: str, offset: int, elements: list[list], comments: list[str],
                      exact: bool = False) -> Mesh:
    """Any PLY the fast path does not take: ASCII, polygons, lists of varying length, other elements
    (read past and left out). Polygons are fan-triangulated by :func:`_mesh_from_arrays`."""
    data = path.read_bytes()[offset:]
    found: dict[str, np.ndarray] = {}
    vprops: list = next((e[2] for e in elements if e[0] == "vertex"), [])
    if fmt == "ascii":
        tokens = data.split()
        pos = 0
        for name, count, props in elements:
            found[name], pos = _read_ascii_element(tokens, pos, count, props)
        left, row = len(tokens) - pos, len(vprops)
    elif fmt in ("binary_little_endian", "binary_big_endian"):
        end = "<" if fmt == "binary_little_endian" else ">"
        buf, pos = memoryview(data), 0
        for name, count, props in elements:
            found[name], pos = _read_binary_element(buf, pos, count, props, end)
        fixed = all(p[0] != "list" for p in vprops)
        left, row = len(buf) - pos, (_element_dtype(vprops, end).itemsize if fixed and vprops else 1)
    else:
        raise ValueError(f"unknown PLY format {fmt!r}")
    if "vertex" not in found:
        raise ValueError("no vertex element")
    if exact:
        _check_exact(elements, left, row)
    return _mesh_from_arrays(found["vertex"], found.get("face"), comments)


def _stack_fields(v, names, dtype=None) -> np.ndarray:
    """(n, k) copy of the fields ``names`` of the structured array ``v`` in ``dtype`` (default: theirs).

    When the fields share one dtype they are read through one strided view and converted in a single
    pass (several times faster than stacking the columns one by one); the values are the same."""
    dts = {v.dtype[c] for c in names}
    if len(dts) == 1:
        from numpy.lib.recfunctions import structured_to_unstructured

        sub = structured_to_unstructured(v[list(names)])
        return np.array(sub, dtype=dtype if dtype is not None else sub.dtype.newbyteorder("="), order="C")
    return np.stack([np.asarray(v[c], dtype=dtype) for c in names], axis=1)


def _mesh_from_arrays(v, f, comments) -> Mesh:
    names = v.dtype.names or ()
    vertices = _stack_fields(v, ("x", "y", "z"), np.float64)
    attrs: dict[str, np.ndarray] = {}
    if all(c in names for c in ("nx", "ny", "nz")):
        attrs["normals"] = _stack_fields(v, ("nx", "ny", "nz"), np.float32)
    col = _find_colour_fields(names)
    if col is not None:
        attrs["colors"] = _colours_to_u8(_stack_fields(v, col))
    skip = {"x", "y", "z", "nx", "ny", "nz", "alpha"} | set(col or ())
    for c in names:
        if c not in skip and v[c].dtype.kind in "fiub" and v[c].ndim == 1:
            attrs[c] = _native(np.asarray(v[c]))
    faces = None
    face_attrs: dict[str, np.ndarray] = {}
    if f is not None and len(f) > 0:
        key = "vertex_indices" if "vertex_indices" in f.dtype.names else "vertex_index"
        raw = f[key]
        try:
            arr = np.stack(raw).astype(np.int64) if raw.dtype == object else np.asarray(raw, np.int64)
        except ValueError:
            arr = None
        if arr is None or arr.ndim != 2 or arr.shape[1] != 3:
            # polygons: fan-triangulate
            tris = []
            for poly in raw:
                for k in range(1, len(poly) - 1):
                    tris.append((poly[0], poly[k], poly[k + 1]))
            arr = np.asarray(tris, dtype=np.int64).reshape(-1, 3)
        faces = arr
        for c in f.dtype.names:
            if c == key:
                continue
            col_ = f[c]
            try:
                face_attrs[c] = _native(np.stack(col_) if col_.dtype == object else np.asarray(col_))
            except ValueError:
                pass
    elif f is not None:
        faces = np.zeros((0, 3), np.int64)
    return Mesh(vertices=vertices, faces=faces, attrs=attrs, face_attrs=face_attrs, comments=comments)


def _native(a: np.ndarray) -> np.ndarray:
    """The array in the machine's byte order (big-endian files)."""
    return a if a.dtype.isnative else a.astype(a.dtype.newbyteorder("="))


def _find_colour_fields(names) -> tuple[str, str, str] | None:
    for trip in (("red", "green", "blue"), ("r", "g", "b"), ("diffuse_red", "diffuse_green", "diffuse_blue")):
        if all(c in names for c in trip):
            return trip
    return None


def _colours_to_u8(rgb: np.ndarray) -> np.ndarray:
    """Colour channels of any dtype -> (n, 3) uint8. Floats in [0, 1] and 16-bit values are rescaled."""
    if rgb.dtype == np.uint8:
        return rgb
    if rgb.dtype.kind == "f":
        mx = float(np.nanmax(rgb)) if rgb.size else 0.0
        scale = 255.0 if mx <= 1.0 + 1e-6 else (255.0 / 65535.0 if mx > 255.0 else 1.0)
        return np.clip(np.rint(rgb * scale), 0, 255).astype(np.uint8)
    mx = int(rgb.max()) if rgb.size else 0
    if mx > 255:
        return np.clip(np.rint(rgb.astype(np.float64) / 257.0), 0, 255).astype(np.uint8)
    return rgb.astype(np.uint8)


# ----------------------------------------------------------------------------- fast binary PLY

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
_PLY_NAMES = {"i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort", "i4": "int", "u4": "uint",
              "f4": "float", "f8": "double"}


def _vertex_columns(mesh: Mesh, xyz_dtype: str):
    cols: list[tuple[str, str, np.ndarray]] = [(c, xyz_dtype, mesh.vertices[:, i]) for i, c in enumerate("xyz")]
    for name, arr in mesh.attrs.items():
        arr = np.asarray(arr)
        if name == "normals":
            cols += [(c, "f4", arr[:, i]) for i, c in enumerate(("nx", "ny", "nz"))]
        elif name == "colors":
            cols += [(c, "u1", arr[:, i]) for i, c in enumerate(("red", "green", "blue"))]
        else:
            arr = _ply_scalar(arr)
            cols.append((name, _SCALAR_DTYPES.get(arr.dtype, "f4"), arr))
    return cols


_WRITE_SLICE = 2_000_000  # vertex rows per write


def write_ply(path: Path | str, mesh: Mesh, *, xyz_dtype: str = "f4", text: bool = False) -> None:
    """Write ``mesh`` as binary little-endian PLY (vertex properties from ``attrs``; faces as
    ``uchar int`` lists; fixed-size face attributes such as ``texcoord`` (m, 6) as ``uchar float`` lists).
    ``xyz_dtype``: "f4" (float32, default) or "f8"."""
    if text:
        return _write_ply_ascii(path, mesh, xyz_dtype=xyz_dtype)
    cols = _vertex_columns(mesh, xyz_dtype)
    vdt = np.dtype([(c, "<" + t) for c, t, _ in cols])
    head = ["ply", "format binary_little_endian 1.0"] + [_comment(c) for c in mesh.comments]
    head.append(f"element vertex {mesh.n_vertices}")
    head += [f"property {_PLY_NAMES[t]} {c}" for c, t, _ in cols]
    face = None
    if mesh.faces is not None:
        fcols = [("n", "<u1"), ("v", "<i4", (3,))]
        head.append(f"element face {mesh.n_faces}")
        head.append("property list uchar int vertex_indices")
        for name, arr in mesh.face_attrs.items():
            arr = np.asarray(arr)
            if arr.ndim == 2:
                fcols += [(name + "_n", "<u1"), (name, "<f4", (arr.shape[1],))]
                head.append(f"property list uchar float {name}")
            else:
                t = _SCALAR_DTYPES.get(arr.dtype, "f4")
                fcols.append((name, "<" + t))
                head.append(f"property {_PLY_NAMES[t]} {name}")
        face = np.empty(mesh.n_faces, dtype=fcols)
        face["n"] = 3
        face["v"] = mesh.faces
        for name, arr in mesh.face_attrs.items():
            arr = np.asarray(arr)
            if arr.ndim == 2:
                face[name + "_n"] = arr.shape[1]
            face[name] = arr
    head.append("end_header")
    n = mesh.n_vertices
    with open(path, "wb") as fh:
        fh.write(("\n".join(head) + "\n").encode("ascii"))
        # vertex rows in slices: bounded memory for big clouds, same bytes as one array
        for a in range(0, n, _WRITE_SLICE):
            b = min(n, a + _WRITE_SLICE)
            vert = np.empty(b - a, dtype=vdt)
            for c, _, arr in cols:
                vert[c] = arr[a:b]
            vert.tofile(fh)
        if face is not None:
            face.tofile(fh)


def read_ply(path: Path | str, *, exact: bool = False) -> Mesh:
    """Read a PLY (cloud or triangle mesh) into a :class:`Mesh`; float64 vertices.

    Binary files (either byte order) whose faces are all triangles are parsed directly with numpy;
    anything else goes through the general reader (polygons are fan-triangulated). ``exact``: raise
    :class:`PlyExtraData` when at least one more vertex row's worth of data follows the last element
    (a header that declares fewer vertices than the file holds), instead of leaving the rest unread."""
    path = Path(path)
    lines, offset = _ply_header(path)
    fmt, elements, comments = _ply_elements(lines)
    names = [e[0] for e in elements]
    end = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(fmt)
    simple = (end is not None and names[:1] == ["vertex"]
              and all(p[0] != "list" for p in elements[0][2])
              and all(n == "face" for n in names[1:]) and len(names) <= 2)
    if not simple or end is None:
        return _read_ply_general(path, fmt, offset, elements, comments, exact)
    vdt = np.dtype([(p[1], end + _PLY_TYPES[p[0]]) for p in elements[0][2]])
    nv = elements[0][1]
    size = path.stat().st_size
    face_arr = None
    if len(elements) == 2:
        face_dtype = _face_dtype(path, offset + vdt.itemsize * nv, elements[1][2], end)
        if face_dtype is None:
            return _read_ply_general(path, fmt, offset, elements, comments, exact)
        fdt = face_dtype
        nf = elements[1][1]
        if offset + vdt.itemsize * nv + fdt.itemsize * nf != size:
            return _read_ply_general(path, fmt, offset, elements, comments, exact)  # polygons or variable lists
    elif offset + vdt.itemsize * nv > size:
        raise ValueError(f"truncated PLY: {nv} vertices declared, file too short")
    elif exact:
        _check_exact(elements, size - offset - vdt.itemsize * nv, vdt.itemsize)
    with open(path, "rb") as fh:
        fh.seek(offset)
        v = np.fromfile(fh, dtype=vdt, count=nv)
        if len(elements) == 2:
            face_arr = np.fromfile(fh, dtype=fdt, count=nf)
            fnames = fdt.names or ()
            key = "vertex_indices" if "vertex_indices" in fnames else "vertex_index"
            if key not in fnames or face_arr[key].shape[1:] != (3,):
                return _read_ply_general(path, fmt, offset, elements, comments, exact)
            for n in fnames:
                if n.endswith("_n") and n[:-2] in fnames and not np.all(face_arr[n] == fdt[n[:-2]].shape[0]):
                    return _read_ply_general(path, fmt, offset, elements, comments, exact)
    if len(v) < nv:
        raise ValueError(f"truncated PLY: {nv} vertices declared, {len(v)} present")
    if face_arr is not None:
        keep = [n for n in face_arr.dtype.names or () if not n.endswith("_n")]
        face_arr = face_arr[keep]
    return _mesh_from_arrays(v, face_arr, comments)


def _ply_header(path: Path) -> tuple[list[str], int]:
    """The header lines between the 'ply' magic and 'end_header' (stripped) and the byte offset of the data;
    ValueError when the magic or the end of the header is missing."""
    with open(path, "rb") as fh:
        first = fh.readline()
        if first.strip() != b"ply":
            raise ValueError("not a PLY file (no 'ply' magic)")
        lines = []
        while True:
            raw = fh.readline()
            if not raw:
                raise ValueError("truncated PLY header (no end_header)")
            ln = raw.decode("ascii", "replace").strip()
            if ln == "end_header":
                break
            lines.append(ln)
        return lines, fh.tell()


def _ply_elements(lines: list[str]) -> tuple[str, list[list], list[str]]:
    """The header's format name, elements as [name, count, [property words]] and comments."""
    fmt = next((ln.split()[1] for ln in lines if ln.startswith("format")), "")
    elements: list[list] = []
    comments = []
    for ln in lines:
        parts = ln.split()
        if parts[0] == "comment":
            comments.append(ln[len("comment "):])
        elif parts[0] == "element":
            elements.append([parts[1], int(parts[2]), []])
        elif parts[0] == "property" and elements:
            elements[-1][2].append(parts[1:])
    return fmt, elements, comments


def _face_dtype(path: Path, face_offset: int, props: list[list[str]], end: str) -> np.dtype | None:
    """The fixed record of the face element whose properties are ``props`` (byte order ``end``), assuming every
    list has the length it has in the first face (verified by the caller); None when the first face is not there."""
    with open(path, "rb") as fh:
        fh.seek(face_offset)
        first_face = fh.read(4096)
    fields: list[tuple] = []
    pos = 0
    for p in props:
        if p[0] == "list":
            ct, it = np.dtype(end + _PLY_TYPES[p[1]]), np.dtype(end + _PLY_TYPES[p[2]])
            if pos + ct.itemsize > len(first_face):
                return None
            cnt = int(np.frombuffer(first_face[pos:pos + ct.itemsize], ct)[0])
            fields += [(p[3] + "_n", ct), (p[3], it, (cnt,))]
            pos += ct.itemsize + cnt * it.itemsize
        else:
            t = np.dtype(end + _PLY_TYPES[p[0]])
            fields.append((p[1], t))
            pos += t.itemsize
    return np.dtype(fields)


def read_mesh(path: Path | str) -> Mesh:
    """Read a triangle mesh PLY for a pipeline step, with checks that name the file: a
    :class:`twinkit.InputError` when it is not a readable PLY, has non-triangle faces or
    indices out of range. The texture (``Mesh.texture``) is the file named by the PLY's
    ``comment TextureFile``, else, when faces carry ``texcoord``, a PNG with the same stem beside it."""
    from twinkit.errors import InputError

    path = Path(path)
    if path.suffix.lower() != ".ply":
        raise InputError(f"{path}: expected a .ply mesh")
    try:
        mesh = read_ply(path)
    except Exception as exc:
        raise InputError(f"{path}: not a readable PLY mesh ({exc}); re-export it from the previous step") from None
    if mesh.faces is None:
        mesh.faces = np.zeros((0, 3), np.int64)
    if "texcoord" in mesh.face_attrs and np.asarray(mesh.face_attrs["texcoord"]).shape[1:] != (6,):
        raise InputError(f"{path}: only triangle meshes are supported")
    for c in mesh.comments:
        if c.startswith("TextureFile"):
            cand = path.parent / c.split(None, 1)[1].strip()
            if cand.is_file():
                mesh.texture = cand
    if mesh.texture is None and "texcoord" in mesh.face_attrs and path.with_suffix(".png").is_file():
        mesh.texture = path.with_suffix(".png")
    if len(mesh.faces) and (mesh.faces.min() < 0 or mesh.faces.max() >= mesh.n_vertices):
        raise InputError(f"{path}: face indices out of range")
    return mesh


def write_colored_ply(path: Path | str, vertices: np.ndarray, faces: np.ndarray, colors: np.ndarray,
                      labels: np.ndarray | None = None, extra: dict[str, np.ndarray] | None = None,
                      comment: str = "") -> None:
    """Binary PLY of a triangle mesh with vertex colours ((n, 3) uint8), an optional uchar ``label``
    ((n,) trainIds) and other scalar vertex properties (``extra``, written in their own dtype)."""
    attrs: dict[str, np.ndarray] = {"colors": np.asarray(colors).astype(np.uint8, copy=False)}
    if labels is not None:
        attrs["label"] = np.asarray(labels).astype(np.uint8, copy=False)
    attrs.update(extra or {})
    write_ply(path, Mesh(vertices=vertices, faces=np.asarray(faces), attrs=attrs,
                         comments=[comment] if comment else []))


def ply_vertex_count(path: Path | str) -> int:
    """The vertex count a PLY's header declares, without reading the body (0 if it cannot be read).

    Cheap enough to match per-vertex arrays (``labels.npy``) to a mesh before deciding to load it."""
    try:
        with open(path, "rb") as f:
            for _ in range(200):
                line = f.readline()
                if not line or line.startswith(b"end_header"):
                    break
                t = line.split()
                if len(t) == 3 and t[0] == b"element" and t[1] == b"vertex":
                    return int(t[2])
    except (OSError, ValueError):
        pass
    return 0

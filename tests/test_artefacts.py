"""The artefact catalogue (twinkit.artefacts): round trips, the engine's check of a step's outputs, and the
meta-test that no plugin reads or writes a catalogued file by hand."""
from __future__ import annotations

import ast
import json
from pathlib import Path

import numpy as np
import pytest

from twinkit import artefacts as A
from twinkit.artefacts import CATALOGUE, ArtefactError

ROOT = Path(__file__).resolve().parents[1]

# ----------------------------------------------------------------------------- round trips


def _cloud(n=400, seed=0):
    from twinkit.mesh import Mesh

    rng = np.random.default_rng(seed)
    xyz = rng.uniform(0, 10, (n, 3))
    xyz[:, 2] *= 0.05
    return Mesh(vertices=xyz, attrs={"colors": rng.integers(0, 255, (n, 3)).astype(np.uint8)})


def _tri_mesh(label=False):
    from twinkit.mesh import Mesh

    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.5]], float)
    f = np.array([[0, 1, 2], [1, 3, 2]])
    m = Mesh(vertices=v, faces=f, face_attrs={"texcoord": np.zeros((2, 6), np.float32)})
    if label:
        m.face_attrs = {"label": np.array([0, 8], np.uint8)}
    return m


POINTS_META = {
    "source": {"file": "cloud.e57", "format": "E57", "fields": ["x", "y", "z"]},
    "counts": {"read": 400, "dropped_invalid": 0, "written": 400},
    "fields": {"normals": None, "colors": True, "intensity": False, "classification": False, "scanner": False,
               "extra": []},
    "frame": {"shift_m": [1.0, 2.0, 3.0]},
    "bounds_m": [[0, 0, 0], [10, 10, 0.5]],
    "density": {"points": 400, "spacing_m": 0.25, "spacing_p90_m": 0.4, "capture": "terrestrial"},
    "notes": [], "time": {"seconds": 0.1},
}
JSON_DOCS = {
    "points_meta.json": POINTS_META,
    "cameras_site.json": {"cameras": [{"image": "a.jpg", "K": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
                                       "R_world_from_camera": np.eye(3).tolist(), "center": [0, 0, 1.6],
                                       "width": 64, "height": 48}],
                          "convention": "opencv", "frame": "site", "scaled": True},
    "cameras.json": {"cameras": [{"image": "a.jpg", "center": [0, 0, 1.6]}],
                     "intrinsics": {"K": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "width": 64, "height": 48}},
    "gcp.json": {"format": "twinkit", "points": [{"id": "Z01", "site_xyz": [0, 0, 0], "observations": []}]},
    "roads_truth.json": {"roads": [{"name": "a", "centerline": [[0, 0], [1, 0]], "polygon": [], "width_m": 7.0}],
                         "lanes": [{"road": "a", "points": [[0, 0], [1, 0]], "direction": "forward"}],
                         "frame": "site"},
    "site.json": {"crs": "EPSG:25832", "base_point": {"lat": 55.7, "lon": 13.2, "alt": 0.0}, "frame": "site",
                  "label_names": {"0": "road"}},
}


@pytest.mark.parametrize("name", sorted(JSON_DOCS))
def test_json_round_trip(tmp_path, name):
    art = CATALOGUE[name]
    p = tmp_path / name
    art.write(p, JSON_DOCS[name])
    doc = art.read(p)
    assert doc.to_json() == json.loads(json.dumps(JSON_DOCS[name]))
    art.write(tmp_path / "again.json", doc)  # written back from the schema object: the same bytes
    assert (tmp_path / "again.json").read_bytes() == p.read_bytes()
    art.check(p)
    assert art.version >= 1


@pytest.mark.parametrize("name", sorted(JSON_DOCS))
def test_json_missing_field_names_file_field_and_fix(tmp_path, name):
    art = CATALOGUE[name]
    data = dict(JSON_DOCS[name])
    first = next(f for f, k in art.schema.KINDS.items() if not k.endswith("?"))
    data.pop(first)
    p = tmp_path / name
    p.write_text(json.dumps(data))
    with pytest.raises(ArtefactError) as e:
        art.read(p)
    msg = str(e.value)
    assert str(p) in msg and f"'{first}'" in msg and f"schema v{art.version}); " in msg
    with pytest.raises(ArtefactError):
        art.write(tmp_path / "w.json", data)


def test_the_demo_sites_json_keeps_its_indent(tmp_path):
    A.write_site_info(tmp_path / "site.json", JSON_DOCS["site.json"])
    assert (tmp_path / "site.json").read_text() == json.dumps(JSON_DOCS["site.json"], indent=1, sort_keys=True) + "\n"
    A.write_points_meta(tmp_path / "points_meta.json", POINTS_META)
    assert (tmp_path / "points_meta.json").read_text() == json.dumps(POINTS_META, indent=2, sort_keys=True) + "\n"


def test_points_meta_without_density_is_said_or_measured(tmp_path):
    from twinkit.surface import density

    old = {k: v for k, v in POINTS_META.items() if k != "density"}
    p = tmp_path / "points_meta.json"
    p.write_text(json.dumps(old))
    with pytest.raises(ArtefactError, match="no 'density' block.*spacing is unknown"):
        A.read_points_meta(p)
    cloud = _cloud()
    A.write_points(tmp_path / "points.ply", cloud)
    meta = A.read_points_meta(p, points=tmp_path / "points.ply")
    want = density.measure(A.read_points(tmp_path / "points.ply").vertices)
    assert meta.density == dict(want, filled_from_points=True)
    assert meta.spacing_m == want["spacing_m"]
    # the writer measures it when the step gives the points
    A.write_points_meta(tmp_path / "m2.json", old, points=cloud.vertices)
    assert A.read_points_meta(tmp_path / "m2.json").density == density.measure(cloud.vertices)
    with pytest.raises(ArtefactError, match="'density' is missing"):
        A.write_points_meta(tmp_path / "m3.json", old)


def test_labels_round_trip_and_checks(tmp_path):
    lab = np.array([0, 1, 8, 255], np.int64)
    for name in ("labels.npy", "gt_labels.npy"):
        art = CATALOGUE[name]
        art.write(tmp_path / name, lab)
        back = art.read(tmp_path / name, n_vertices=4)
        assert back.dtype == np.uint8 and np.array_equal(back, lab)
        art.check(tmp_path / name)
        with pytest.raises(ArtefactError, match="4 labels for the 5 vertices"):
            art.read(tmp_path / name, n_vertices=5)
    with pytest.raises(ArtefactError, match="0-255"):
        A.write_labels(tmp_path / "x.npy", np.array([300]))
    np.save(tmp_path / "labels.npy", np.zeros((3, 2), np.uint8))
    with pytest.raises(ArtefactError, match="1-D uint8"):
        CATALOGUE["labels.npy"].check(tmp_path / "labels.npy")


def test_meshes_and_clouds_round_trip(tmp_path):
    cloud = _cloud()
    A.write_points(tmp_path / "points.ply", cloud)
    back = A.read_points(tmp_path / "points.ply")
    assert np.allclose(back.vertices, cloud.vertices.astype(np.float32)) and np.array_equal(back.colors, cloud.colors)
    CATALOGUE["points.ply"].check(tmp_path / "points.ply")
    with pytest.raises(ArtefactError, match="no faces"):
        CATALOGUE["textured_mesh.ply"].check(tmp_path / "points.ply")
    m = _tri_mesh()
    A.write_textured_mesh(tmp_path / "textured_mesh.ply", m)
    assert np.array_equal(A.read_textured_mesh(tmp_path / "textured_mesh.ply").faces, m.faces)
    CATALOGUE["textured_mesh.ply"].check(tmp_path / "textured_mesh.ply")
    with pytest.raises(ArtefactError, match="label"):
        CATALOGUE["gt_mesh.ply"].check(tmp_path / "textured_mesh.ply")
    A.write_clean_mesh(tmp_path / "clean_mesh.ply", m)
    assert np.array_equal(A.read_clean_mesh(tmp_path / "clean_mesh.ply").faces, m.faces)
    CATALOGUE["clean_mesh.ply"].check(tmp_path / "clean_mesh.ply")
    with pytest.raises(ArtefactError, match="no faces"):
        A.read_clean_mesh(tmp_path / "points.ply")
    g = _tri_mesh(label=True)
    A.write_gt_mesh(tmp_path / "gt_mesh.ply", g)
    assert np.array_equal(A.read_gt_mesh(tmp_path / "gt_mesh.ply").face_attrs["label"], [0, 8])
    CATALOGUE["gt_mesh.ply"].check(tmp_path / "gt_mesh.ply")
    uv = np.zeros((2, 3, 2))
    A.write_textured_obj(tmp_path / "textured_mesh.obj", m.vertices, m.faces, uv, "t.png")
    o = A.read_textured_obj(tmp_path / "textured_mesh.obj")
    assert np.array_equal(o.faces, m.faces) and np.allclose(o.vertices, m.vertices)
    CATALOGUE["textured_mesh.obj"].check(tmp_path / "textured_mesh.obj")


def test_xml_and_photos_round_trip(tmp_path):
    xodr = '<?xml version="1.0"?>\n<OpenDRIVE><header/></OpenDRIVE>\n'
    A.write_opendrive(tmp_path / "aligned.xodr", xodr)
    assert A.read_opendrive(tmp_path / "aligned.xodr") == xodr
    CATALOGUE["aligned.xodr"].check(tmp_path / "aligned.xodr")
    osm = '<?xml version="1.0"?>\n<osm version="0.6"></osm>\n'
    A.write_osm(tmp_path / "roads.osm", osm)
    assert A.read_osm(tmp_path / "roads.osm") == tmp_path / "roads.osm"
    assert (tmp_path / "roads.osm").read_text() == osm
    with pytest.raises(ArtefactError, match="<osm>, not <OpenDRIVE>"):
        CATALOGUE["aligned.xodr"].check(tmp_path / "roads.osm")
    with pytest.raises(ArtefactError, match="holds no photo"):
        (tmp_path / "photos").mkdir()
        CATALOGUE["photos"].check(tmp_path / "photos")
    p = A.write_photo(tmp_path / "photos", "b.jpg", b"\xff\xd8")
    A.write_photo(tmp_path / "photos", "a.png", b"\x89PNG")
    assert A.list_photos(tmp_path / "photos") == [tmp_path / "photos" / "a.png", p]
    CATALOGUE["photos"].check(tmp_path / "photos")
    # a folder left empty on purpose says why, and passes; it lists no photo
    A.write_no_photos(tmp_path / "none", "the recipe reads no photos")
    CATALOGUE["photos"].check(tmp_path / "none")
    assert A.list_photos(tmp_path / "none") == []
    assert A.why_no_photos(tmp_path / "none") == "the recipe reads no photos"
    assert A.why_no_photos(tmp_path / "photos") is None


def test_every_entry_is_complete():
    assert len(CATALOGUE) >= 14
    for name, art in CATALOGUE.items():
        assert art.name == name and art.format and art.writers and art.readers
        assert isinstance(art.schema.VERSION, int) and art.schema.__doc__
        assert callable(art.read) and callable(art.write) and art.read.__doc__ and art.write.__doc__


def test_the_docs_table_lists_every_artefact():
    text = (ROOT / "docs" / "engine.md").read_text()
    section = text.split("## Artefacts between plugins", 1)[1].split("\n## ", 1)[0]
    for name, art in CATALOGUE.items():
        row = next((ln for ln in section.splitlines() if ln.startswith(f"| `{name}`")), None)
        assert row is not None, f"docs/engine.md 'Artefacts between plugins' lacks a row for {name}"
        assert f"| {art.version} |" in row, f"{name}: the docs row should give schema version {art.version}"


#: files that cross a plugin boundary but are not catalogued, and why
NOT_CATALOGUED = {
    "cloud.e57": "the user's own scan in a standard format (E57), read by read_cloud's format readers",
    "cloud.las": "the user's own scan in a standard format (LAS), read by read_cloud's format readers",
    "cloud.ply": "the user's own scan in a standard format (PLY), read by read_cloud's format readers",
}


def _recipe_renames():
    """(step name, output parameter, file name) of every ``outputs:`` rename in recipes/*.yaml."""
    import yaml

    for path in sorted((Path(__file__).resolve().parents[1] / "recipes").glob("*.yaml")):
        for st in (yaml.safe_load(path.read_text()).get("recipe") or {}).get("steps") or []:
            if isinstance(st, dict) and st.get("outputs") and str(st.get("uses", "")).startswith("step/"):
                for port, filename in st["outputs"].items():
                    yield st["uses"].split("/", 1)[1], port, filename


def _ports_by_plugin():
    """{file name: (writer tags, reader tags)} over every registered plugin (``plugin:step``)."""
    from collections import defaultdict

    from twinkit.plugins import load_registry
    from twinkit.signature import parse_signature

    plugins = list(load_registry().all())
    assert len(plugins) > 30, "the registry looks empty: this test would pass on nothing"

    def tag(p):
        return f"{p.distribution.replace('twinkit-', '')}:{p.name if p.kind == 'step' else p.kind + '/' + p.name}"

    writers, readers = defaultdict(set), defaultdict(set)
    for p in plugins:
        for o in parse_signature(p.run).outputs:
            writers[o.filename].add(tag(p))
    for step, port, filename in _recipe_renames():  # a recipe step's 'outputs:' (export_demo's labels.npy)
        p = next(p for p in plugins if p.kind == "step" and p.name == step)
        writers[filename].add(tag(p))
        assert port in {o.param for o in parse_signature(p.run).outputs}
    for p in plugins:
        for i in parse_signature(p.run).inputs:
            for name in writers:
                if i.accepts(name, "." not in name):
                    readers[name].add(tag(p))
    return {n: (writers[n], readers[n]) for n in writers}


def test_every_file_between_plugins_is_catalogued_with_its_true_writers_and_readers():
    ports = _ports_by_plugin()
    crossing = {n for n, (w, r) in ports.items()
                if any(a.split(":")[0] != b.split(":")[0] for a in w for b in r)}
    missing = crossing - set(CATALOGUE) - set(NOT_CATALOGUED)
    assert not missing, f"files that cross a plugin boundary and are not in twinkit.artefacts.CATALOGUE: {missing}"
    for name, art in CATALOGUE.items():
        w, r = ports.get(name, (set(), set()))
        assert set(art.writers) == w, f"{name}: the catalogue says written by {art.writers}, the plugins by {sorted(w)}"
        assert set(art.readers) == r, f"{name}: the catalogue says read by {art.readers}, the plugins by {sorted(r)}"


# ----------------------------------------------------------------------------- the engine's check


def _run_one(tmp_path, fn):
    from twinkit.engine.store import compute_into_store
    from twinkit.signature import parse_signature

    sig = parse_signature(fn)
    return compute_into_store(lambda params, ctx, **kw: fn(**kw), None, {}, sig.outputs, "k" * 32,
                              tmp_path / "store", {"step_id": "demo", "site": {}, "config": {}})


def test_a_wrong_schema_fails_its_step(tmp_path):
    from twinkit.errors import StepError

    def bad_meta(out_points_meta_json):
        meta = {k: v for k, v in POINTS_META.items() if k != "density"}
        Path(out_points_meta_json).write_text(json.dumps(meta))

    with pytest.raises(StepError) as e:
        _run_one(tmp_path, bad_meta)
    msg = str(e.value)
    assert "step 'demo' wrote points_meta.json" in msg and "no 'density' block" in msg
    assert "Artefacts between plugins" in msg and str(tmp_path) not in msg
    assert not (tmp_path / "store" / ("k" * 32)).exists()
    assert not any((tmp_path / "store" / ".tmp").iterdir())

    def bad_labels(out_labels_npy):
        np.save(out_labels_npy, np.zeros(4, np.float32))

    with pytest.raises(StepError, match="1-D uint8"):
        _run_one(tmp_path, bad_labels)


def test_a_good_output_and_an_uncatalogued_one_pass(tmp_path):
    def good(out_labels_npy, out_anything_json):
        A.write_labels(out_labels_npy, np.array([1, 2, 3]))
        Path(out_anything_json).write_text("[]")

    rec = _run_one(tmp_path, good)
    assert set(rec["artefacts"]) == {"labels.npy", "anything.json"}


# ----------------------------------------------------------------------------- no hand reads or writes

#: Files whose owners (other helpers of issue 43) move their reads and writes onto the catalogue at their
#: end; each line says whose it is. A path matches when it starts with the prefix.
ALLOWLIST: tuple[str, ...] = ()

#: calls that read or write a file by themselves
HAND_IO = {"load", "loads", "save", "savez", "savez_compressed", "open", "read_text", "write_text", "read_bytes",
           "write_bytes", "read_ply", "read_mesh", "write_ply", "read_obj", "write_obj", "write_json", "dump",
           "fromfile", "loadtxt", "tofile", "parse", "iterparse", "imread", "read_labelled_ply", "_read_json",
           "_read_mesh_input", "write_colored_ply", "write_mesh_ply", "write_osm"}
_WRAPPERS = {"Path", "str", "fspath", "expanduser", "resolve", "absolute"}
_PORTS = {p for art in CATALOGUE.values() for p in art.ports}
_NAMES = set(CATALOGUE)


def _mentions(node: ast.AST, tainted: set[str]) -> bool:
    """Whether an expression is (a path of) a catalogued artefact: a port parameter, a name assigned from
    one, the file name as a literal, ``folder / "points_meta.json"``."""
    if isinstance(node, ast.Name):
        return node.id in tainted
    if isinstance(node, ast.Constant):
        return isinstance(node.value, str) and node.value in _NAMES
    if isinstance(node, ast.Call):
        f = node.func
        name = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""
        if name in _WRAPPERS:
            inner = list(node.args) + ([f.value] if isinstance(f, ast.Attribute) else [])
            return any(_mentions(a, tainted) for a in inner)
        return False
    if isinstance(node, ast.BinOp):  # a file in a catalogued folder (in_photos_dir / name) is the folder's content
        inner = node.left.args[0] if isinstance(node.left, ast.Call) and node.left.args else node.left
        in_folder = isinstance(inner, ast.Name) and inner.id.endswith("_dir")
        return (_mentions(node.left, tainted) and not in_folder) or _mentions(node.right, tainted)
    if isinstance(node, (ast.BoolOp,)):
        return any(_mentions(v, tainted) for v in node.values)
    if isinstance(node, ast.IfExp):
        return _mentions(node.body, tainted) or _mentions(node.orelse, tainted)
    if isinstance(node, ast.Subscript):
        return _mentions(node.value, tainted)
    if isinstance(node, ast.Dict):
        return any(v is not None and _mentions(v, tainted) for v in node.values)
    return False


def _scope(node: ast.AST):
    """The nodes of one scope: a function's body (or the module's top level) without the functions in it."""
    todo = list(ast.iter_child_nodes(node))
    while todo:
        n = todo.pop()
        yield n
        if not isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda, ast.ClassDef)):
            todo.extend(ast.iter_child_nodes(n))
        elif isinstance(n, ast.ClassDef):
            todo.extend(c for c in n.body if not isinstance(c, (ast.FunctionDef, ast.AsyncFunctionDef)))


def _catalogue_names(tree: ast.AST) -> tuple[set[str], set[str]]:
    """(module aliases of twinkit.artefacts, functions imported from it): calls through them are the catalogue."""
    mods, funcs = set(), set()
    for n in ast.walk(tree):
        if isinstance(n, ast.ImportFrom) and n.module == "twinkit":
            mods |= {a.asname or a.name for a in n.names if a.name == "artefacts"}
        elif isinstance(n, ast.ImportFrom) and (n.module or "").startswith("twinkit.artefacts"):
            funcs |= {a.asname or a.name for a in n.names}
        elif isinstance(n, ast.Import):
            mods |= {a.asname for a in n.names if a.name == "twinkit.artefacts" and a.asname}
    return mods, funcs


def hand_io(source: str, where: str = "<source>") -> list[str]:
    """Hand reads and writes of catalogued artefacts in a module's source: ``file:line: call``."""
    tree = ast.parse(source)
    mods, funcs = _catalogue_names(tree)
    found = []
    scopes = [tree] + [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
    for scope in scopes:
        nodes = list(_scope(scope))
        tainted = set(_PORTS)
        for _ in range(3):  # names assigned from a port (src = in_labels_npy or ...), a few levels deep
            for node in nodes:
                if isinstance(node, ast.Assign) and _mentions(node.value, tainted):
                    tainted |= {t.id for t in node.targets if isinstance(t, ast.Name)}
        for node in nodes:
            if not isinstance(node, ast.Call):
                continue
            f = node.func
            name = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""
            through_catalogue = (isinstance(f, ast.Name) and f.id in funcs) or (
                isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) and f.value.id in mods)
            if name not in HAND_IO or through_catalogue:
                continue
            args = list(node.args) + [k.value for k in node.keywords]
            if isinstance(f, ast.Attribute) and name in ("read_text", "write_text", "read_bytes", "write_bytes",
                                                          "open", "tofile"):
                args.append(f.value)
            if any(_mentions(a, tainted) for a in args):
                found.append(f"{where}:{node.lineno}: {ast.unparse(node)[:100]}")
    return sorted(set(found))


def _plugin_sources():
    for path in sorted((ROOT / "plugins").glob("twinkit-*/twinkit_*/**/*.py")):
        rel = path.relative_to(ROOT).as_posix()
        yield rel, path


def test_the_hand_io_scan_finds_plugin_sources():
    assert sum(1 for _ in _plugin_sources()) > 30


def test_no_plugin_reads_or_writes_a_catalogued_file_by_hand():
    found = []
    for rel, path in _plugin_sources():
        if rel.startswith(ALLOWLIST):
            continue
        found += hand_io(path.read_text(), rel)
    assert not found, ("read and write catalogued artefacts through twinkit.artefacts (docs/engine.md, "
                       "'Artefacts between plugins'), not by hand:\n" + "\n".join(found))


def test_the_allowlist_names_existing_code():
    for prefix in ALLOWLIST:
        assert any(rel.startswith(prefix) for rel, _ in _plugin_sources()), prefix


FAKE_PLUGIN = '''
import json
from twinkit import artefacts as A
from pathlib import Path
import numpy as np

def scan(params, ctx, *, in_labels_npy, in_points_meta_json=None, in_aligned_xodr, out_labels_npy, in_gt_labels_npy=None,
         in_photos_dir=None):
    src = {"predicted": in_labels_npy, "gt": in_gt_labels_npy}[params.which]
    labels = np.load(src)
    meta = json.loads(Path(in_points_meta_json).read_text())
    text = in_aligned_xodr.read_text(encoding="utf-8")
    np.save(out_labels_npy, labels)
    with open(ctx.workdir / "points_meta.json") as fh:
        fh.read()
    ok = np.load(ctx.workdir / "something_else.npy")
    photo = open(Path(in_photos_dir) / "photo_0001.jpg", "rb")
    A.write_osm(in_roads_osm, "<osm/>")
    return {}
'''


def test_the_meta_test_catches_hand_reads_in_a_fake_plugin():
    found = hand_io(FAKE_PLUGIN, "fake.py")
    lines = sorted(int(f.split(":")[1]) for f in found)
    assert lines == [10, 11, 12, 13, 14], found
    clean = FAKE_PLUGIN.replace("np.load(src)", "A.read_labels(src)").replace(
        "json.loads(Path(in_points_meta_json).read_text())", "A.read_points_meta(in_points_meta_json)")
    assert sorted(int(f.split(":")[1]) for f in hand_io(clean, "fake.py")) == [12, 13, 14]

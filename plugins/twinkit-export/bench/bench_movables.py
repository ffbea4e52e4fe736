"""Movable objects out of the static map, measured on a finished site run (default outputs/demo).

    python plugins/twinkit-export/bench/bench_movables.py [outputs/<site>] [--main /work/main/outputs/<site>]

1. Lane waypoints under static geometry: the CARLA package's OpenDRIVE parsed by carla.Map (offline),
   waypoints every 0.5 m on driving lanes, and for each a vertical ray from 0.15 m to 2 m above it
   against the static geometry of the package (every class mesh: map + props), in the package's frame
   (``carla_frame.json``). Rows: the static geometry with the objects lifted (default), the same with the
   lifted objects put back (what lift: false gives), and, with --main, another run's class meshes.
   Also: waypoints with no static surface within 0.3 m of the lane (no road under them).
2. Objects found vs ground truth: the ground-truth mesh's movable classes (01_site/gt_mesh.ply, vertices
   of one class within 2 m are one object: the demo labels wheels and frame) and site.json's car count, matched by centre (<= 1.5 m);
   and the actors whose truth class (the majority ground-truth label of their vertices) is not theirs.
3. Open border near the objects before / after, faces lifted, loops filled (the step's report).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT / "plugins" / "twinkit-export"))


def _latest(out: Path, suffix: str) -> Path | None:
    c = sorted(p for p in out.glob(f"[0-9][0-9]_{suffix}") if p.is_dir())
    return c[-1] if c else None


def waypoints(xodr_text: str, step_m: float = 0.5) -> np.ndarray:
    """(n, 3) driving-lane waypoints in the package frame (x, y north, z)."""
    from twinkit.street.lanes import LaneMap

    wp = LaneMap(xodr_text, "bench").waypoints(step_m)
    return wp.xyz[wp.is_type("driving")].reshape(-1, 3)


def blocked(meshes: list[tuple[np.ndarray, np.ndarray]], wp: np.ndarray, lo: float = 0.15, hi: float = 2.0):
    """(blocked (n,) bool: geometry lo..hi above the waypoint, no_ground (n,) bool: nothing within 0.3 m)."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    for v, f in meshes:
        if len(f):
            scene.add_triangles(o3d.core.Tensor(v.astype(np.float32)), o3d.core.Tensor(f.astype(np.uint32)))
    up = np.c_[wp + [0, 0, lo], np.tile([0, 0, 1.0], (len(wp), 1))].astype(np.float32)
    t = scene.cast_rays(o3d.core.Tensor(up))["t_hit"].numpy()
    blk = t <= (hi - lo)
    q = o3d.core.Tensor(wp.astype(np.float32))
    d = scene.compute_distance(q).numpy()
    return blk, d > 0.3


def gt_objects(out: Path) -> list[tuple[int, np.ndarray]]:
    """Ground-truth objects: the textured mesh's vertices with a movable ground-truth label (the gt_labels
    step: the ground-truth mesh's labels moved onto the reconstruction), 0.5 m apart at most = one object;
    pieces under 0.3 m tall (label bleeding on the ground) are left out."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    from twinkit.mesh import read_obj

    lab_p = next(iter(sorted(out.glob("[0-9][0-9]_gt_labels/gt_labels.npy"))), None)
    tex = _latest(out, "texture")
    if lab_p is None or tex is None:
        return []
    v = read_obj(tex / "textured_mesh.obj").vertices
    lab = np.load(lab_p)
    res = []
    for c in range(11, 19):
        vid = np.nonzero(lab == c)[0]
        if len(vid) == 0:
            continue
        p = cKDTree(v[vid]).query_pairs(0.5, output_type="ndarray")
        n, cl = connected_components(coo_matrix((np.ones(len(p)), (p[:, 0], p[:, 1])), shape=(len(vid),) * 2),
                                     directed=False)
        for k in range(n):
            w = v[vid[cl == k]]
            if np.ptp(w[:, 2]) >= 0.3 and len(w) >= 20:
                res.append((c, (w.min(0) + w.max(0)) / 2))
    return res


def truth_class_mismatch(out: Path, mov_dir: Path, actors: list[dict]) -> list[str]:
    """The actors whose truth class (the majority ground-truth label of their mesh's source vertices, gt_labels
    step) is not their class: ``["Person_010(255)", ...]``; [] without ground truth."""
    from twinkit_export.classmesh import read_class_ply

    lab_p = next(iter(sorted(out.glob("[0-9][0-9]_gt_labels/gt_labels.npy"))), None)
    if lab_p is None:
        return []
    lab = np.load(lab_p)
    wrong = []
    for a in actors:
        src = np.asarray(read_class_ply(mov_dir / a["file"]).mesh.attrs["source_index"])
        u, k = np.unique(lab[src[src < len(lab)]], return_counts=True)
        if len(u) and int(u[np.argmax(k)]) != int(a["class_id"]):
            wrong.append(f"{a['name']}({int(u[np.argmax(k)])})")
    return wrong


def main() -> int:
    from twinkit_export.classmesh import read_class_ply
    from twinkit_export.split import load_class_set

    args = sys.argv[1:]
    main_out = None
    if "--main" in args:
        i = args.index("--main")
        main_out = Path(args[i + 1])
        del args[i:i + 2]
    out = Path(args[0]) if args else ROOT / "outputs" / "demo"
    carla_dir, split_dir, lift_dir = _latest(out, "carla"), _latest(out, "split"), _latest(out, "lift_movables")
    if not (carla_dir and split_dir and lift_dir):
        print(f"{out}: needs a finished pointcloud_site run with lift_movables (twinkit recipe=pointcloud_site)")
        return 0
    imp = carla_dir / "carla_import"
    frame = json.loads((imp / "carla_frame.json").read_text())
    mat = np.asarray(frame.get("matrix_site_to_package", np.eye(3)), float)
    xodr = next((imp / "Import").glob("*/*.xodr"))
    wp = waypoints(xodr.read_text())

    def pkg(v):
        return np.asarray(v, float) @ mat.T

    static = [(pkg(m.mesh.vertices), m.mesh.faces) for m in load_class_set(split_dir / "class_meshes").meshes]
    mov_dir = lift_dir / "movables"
    acts = json.loads((mov_dir / "actors.json").read_text())
    movs = [read_class_ply(mov_dir / a["file"]) for a in acts.get("actors", [])]
    rows = [("lifted (default)", static), ("objects put back (lift: false)",
                                          static + [(pkg(m.mesh.vertices), m.mesh.faces) for m in movs])]
    if main_out is not None and _latest(main_out, "split"):
        rows.append((f"{main_out} class meshes", [(pkg(m.mesh.vertices), m.mesh.faces) for m in
                                                  load_class_set(_latest(main_out, "split") / "class_meshes").meshes]))
    print(f"## Driving-lane waypoints (0.5 m, carla.Map on {xodr.name}: {len(wp)}) under static geometry\n")
    print("| static geometry | waypoints with geometry 0.15-2 m above | waypoints with no surface within 0.3 m |")
    print("|---|---:|---:|")
    for name, meshes in rows:
        b, ng = blocked(meshes, wp)
        print(f"| {name} | {int(b.sum())} | {int(ng.sum())} |")
    # objects vs ground truth
    site = out / "01_site"
    print("\n## Objects found vs ground truth\n")
    gt = gt_objects(out)
    if gt:
        sj = json.loads((site / "site.json").read_text())
        found = [(a["class_id"], np.asarray(a["box"]["center"])) for a in acts.get("actors", [])]
        used, match, cls_ok = set(), 0, 0
        for c, p in gt:
            d = [np.linalg.norm(q[:2] - p[:2]) if j not in used else np.inf for j, (_, q) in enumerate(found)]
            if d and min(d) <= 1.5:
                j = int(np.argmin(d))
                used.add(j)
                match += 1
                cls_ok += int(found[j][0] == c)
        wrong = truth_class_mismatch(out, mov_dir, acts.get("actors", []))
        print("| ground-truth objects (site.json cars) | found | matched (<= 1.5 m) | matched with the right class | "
              "false objects | actors whose truth class is not theirs |")
        print("|---:|---:|---:|---:|---:|---:|")
        print(f"| {len(gt)} ({sj.get('counts', {}).get('cars', '?')}) | {len(found)} | {match} | {cls_ok} | "
              f"{len(found) - len(used)} | {len(wrong)} {' '.join(wrong)} |")
    rep = acts.get("report", {})
    print("\n## The lift\n")
    print("| faces lifted | loops filled | fill faces | open border near objects before (m) | after (m) | "
          "new open border (m) | labels moved to the surrounding class |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    print(f"| {rep.get('faces_lifted', 0)} | {rep.get('loops_filled', 0)} | {rep.get('faces_added', 0)} | "
          f"{rep.get('open_border_near_objects_before_m', 0)} | {rep.get('open_border_near_objects_after_m', 0)} | "
          f"{rep.get('new_open_border_m', 0)} | {rep.get('relabelled_vertices', 0)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

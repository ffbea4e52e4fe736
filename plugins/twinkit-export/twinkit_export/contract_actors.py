"""The package checker's rule on where the actors stand: none inside the static geometry, none floating.

CARLA spawns an actor with Unreal's ``UWorld::SpawnActor``; when that returns nothing because the
actor's collision overlaps blocking geometry, the factory reports ``EActorSpawnResultStatus::Collision``
(``Unreal/CarlaUE4/Plugins/Carla/Source/Carla/Actor/Factory/VehicleActorFactory.cpp`` and
``WalkerActorFactory.cpp``, ``SpawnActor``), which the client raises as "Spawn failed because of collision
at spawn position" (``Actor/ActorSpawnResult.cpp``, ``FActorSpawnResult::StatusToString``). An actor that
does spawn there stands in a wall or a tree, and one spawned over nothing falls. A lifted object whose box
holds static geometry (a "pedestrian" that is part of a tree: the rest of the tree is still in the map) or
whose scanned mesh hangs above the ground under it is no object the street had.

:func:`check_actor_geometry` reads ``actors.json`` beside ``Import/`` (its ``site`` boxes, put into the
package frame by ``carla_frame.json``'s ``matrix_site_to_package``) and the package's FBX meshes (vertices
in metres, package frame, z up; the scanned props are the actors' own meshes, the rest is static), and
reports rule ``actors_geometry``:

- **inside**: more than ``INSIDE_MIN_POINTS`` points of the static surface (sampled every
  ``SAMPLE_M``) inside the actor's box shrunk by ``INSIDE_SHRINK_M`` on every side, from
  ``INSIDE_ABOVE_GROUND_M`` above its ground to its top;
- **floating**: no static surface under its footprint, or its scanned mesh's lowest point more than
  ``FLOAT_GAP_M`` above the highest static surface under it (below that point).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

SRC_SPAWN = ("Unreal/CarlaUE4/Plugins/Carla/Source/Carla/Actor/Factory/VehicleActorFactory.cpp, WalkerActorFactory.cpp "
             "(SpawnActor: UWorld::SpawnActor returns null -> EActorSpawnResultStatus::Collision); "
             "Actor/ActorSpawnResult.cpp (StatusToString)")
#: the rule's id and its entry in carla_contract.RULES
RULE_ID = "actors_geometry"
ACTORS_GEOMETRY_RULE = ("an actor spawns only where its collision overlaps no blocking geometry (else 'Spawn failed "
                        "because of collision at spawn position') and falls when nothing is under it: no lifted "
                        "actor's box holds static geometry, and every actor's scanned mesh stands on the static "
                        "surface under it", SRC_SPAWN)

SAMPLE_M = 0.05
INSIDE_SHRINK_M = 0.1
INSIDE_ABOVE_GROUND_M = 0.3
INSIDE_MIN_POINTS = 20
FLOAT_GAP_M = 0.3
GROUND_MARGIN_M = 0.3


def fbx_meshes(path: Path) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(geometry name, vertices (n, 3) float64, triangles (m, 3) int64) of every mesh of a binary FBX, as stored
    (twinkit's FBX files carry metres in the package frame, z up, no node transform)."""
    from .fbxbin import _fans, _object_name, array_values, read_tree

    _, nodes = read_tree(Path(path))
    objects = next((n for n in nodes if n.name == "Objects"), None)
    out = []
    for o in objects.children if objects is not None else []:
        if o.name != "Geometry" or len(o.props) < 3 or o.props[2] != "Mesh":
            continue
        vn, pn = o.child("Vertices"), o.child("PolygonVertexIndex")
        if vn is None or pn is None:
            continue
        v = array_values(vn.props[0]).astype(float).reshape(-1, 3)
        out.append((_object_name(o.props[1]), v, _fans(array_values(pn.props[0]))))
    return out


def surface_points(v: np.ndarray, f: np.ndarray, lo: np.ndarray, hi: np.ndarray, step: float = SAMPLE_M) -> np.ndarray:
    """Points every ~``step`` metres on the triangles ``f`` of ``v`` whose bounding box meets the box
    ``lo``..``hi`` (3,), vertices included; (k, 3)."""
    if len(f) == 0:
        return np.zeros((0, 3))
    t = v[f]
    near = np.all(t.max(axis=1) >= lo, axis=1) & np.all(t.min(axis=1) <= hi, axis=1)
    t = t[near]
    if len(t) == 0:
        return np.zeros((0, 3))
    pts = [t.reshape(-1, 3)]
    edge = np.linalg.norm(t - t[:, [1, 2, 0]], axis=2).max(axis=1)
    for n in np.unique(np.clip(np.ceil(edge / step), 1, 60).astype(int)):
        sel = t[np.ceil(np.clip(edge / step, 1, 60)).astype(int) == n]
        a, b = np.meshgrid(np.arange(n + 1), np.arange(n + 1))
        keep = a + b <= n
        w = np.c_[a[keep], b[keep]] / n
        bary = np.c_[1 - w.sum(1), w]
        pts.append(np.einsum("kj,tjc->tkc", bary, sel).reshape(-1, 3))
    return np.vstack(pts)


def _in_footprint(p: np.ndarray, box: dict, margin: float) -> np.ndarray:
    d = p[:, :2] - box["xy"]
    c, s = math.cos(box["yaw"]), math.sin(box["yaw"])
    u, w = d @ [c, s], d @ [-s, c]
    return (np.abs(u) <= max(box["length"] / 2 + margin, 0.05)) & (np.abs(w) <= max(box["width"] / 2 + margin, 0.05))


def actor_boxes(actors: list[dict], matrix) -> list[dict]:
    """Each actor's box in the package frame: ``xy`` (2,), ``yaw`` (rad, counter-clockwise from +x), ``length``,
    ``width``, ``height``, ``ground`` (z of its base), from its ``site`` entry and the site -> package matrix."""
    m = np.asarray(matrix if matrix is not None else np.eye(3), float)
    rot = math.atan2(m[1, 0], m[0, 0])
    out = []
    for a in actors:
        s = a.get("site") or {}
        cx, cy, _ = s.get("center", (0.0, 0.0, 0.0))
        p = m @ [cx, cy, float(s.get("ground_z", 0.0))]
        length, width, height = (float(x) for x in a.get("size_m", (0.0, 0.0, 0.0)))
        out.append({"name": a.get("name", "?"), "xy": p[:2], "ground": float(p[2]), "yaw": math.radians(
            float(s.get("yaw_deg", 0.0))) + rot, "length": length, "width": width, "height": height,
                    "mesh": a.get("scanned_prop_name")})
    return out


def actor_geometry_problems(boxes: list[dict], static: list[tuple[str, np.ndarray, np.ndarray]],
                            scanned: dict[str, np.ndarray]) -> list[str]:
    """The ``actors_geometry`` findings for the ``boxes`` (:func:`actor_boxes`) against the ``static`` meshes
    (name, vertices, triangles; package frame) and the actors' own mesh vertices by prop name (``scanned``)."""
    out = []
    for b in boxes:
        top = b["ground"] + b["height"]
        r = math.hypot(b["length"], b["width"]) / 2 + GROUND_MARGIN_M
        lo = np.array([b["xy"][0] - r, b["xy"][1] - r, b["ground"] - 1.0])
        hi = np.array([b["xy"][0] + r, b["xy"][1] + r, top + 0.1])
        own = scanned.get(b["mesh"] or "")
        bottom = float(own[:, 2].min()) if own is not None and len(own) else b["ground"]
        inside: dict[str, int] = {}
        under = []
        for name, v, f in static:
            p = surface_points(v, f, lo, hi)
            if not len(p):
                continue
            k = int((_in_footprint(p, b, -INSIDE_SHRINK_M) & (p[:, 2] > b["ground"] + INSIDE_ABOVE_GROUND_M)
                     & (p[:, 2] < top - 0.05)).sum())
            if k:
                inside[name] = inside.get(name, 0) + k
            under.append(p[_in_footprint(p, b, GROUND_MARGIN_M) & (p[:, 2] <= bottom + 0.05), 2])
        n_in = sum(inside.values())
        if n_in > INSIDE_MIN_POINTS:
            what = ", ".join(f"{k} ({n})" for k, n in sorted(inside.items(), key=lambda kv: -kv[1]))
            out.append(f"{b['name']}: {n_in} points of static geometry inside its box "
                       f"({b['length']:.2f} x {b['width']:.2f} x {b['height']:.2f} m): {what}")
        zs = np.concatenate(under) if under else np.zeros(0)
        if not len(zs):
            out.append(f"{b['name']}: no static surface under it (floating)")
        elif bottom - float(zs.max()) > FLOAT_GAP_M:
            out.append(f"{b['name']}: its mesh's lowest point is {bottom - float(zs.max()):.2f} m above the static "
                       f"surface under it (floating)")
    return out


def check_actor_geometry(rep, root: Path) -> None:
    """Add the ``actors_geometry`` findings of the package at ``root`` (the folder holding ``Import/``,
    ``actors.json`` and ``carla_frame.json``) to the contract report ``rep``."""
    root = Path(root)
    path = root / "actors.json"
    if not path.exists():
        return
    try:
        actors = json.loads(path.read_text()).get("actors") or []
    except (ValueError, AttributeError):
        return  # the 'actors' rule reports an unreadable file
    if not actors:
        return
    frame = root / "carla_frame.json"
    matrix = json.loads(frame.read_text()).get("matrix_site_to_package") if frame.exists() else None
    own_names = {a.get("scanned_prop_name") for a in actors}
    static, scanned = [], {}
    for fbx in sorted((root / "Import").rglob("*.fbx")):
        try:
            meshes = fbx_meshes(fbx)
        except Exception:  # noqa: BLE001 -- an unreadable FBX is reported by the json rule
            continue
        if fbx.stem in own_names:
            scanned[fbx.stem] = np.vstack([v for _, v, _ in meshes]) if meshes else np.zeros((0, 3))
        else:
            static += [(f"{fbx.stem}:{n}", v, f) for n, v, f in meshes]
    for msg in actor_geometry_problems(actor_boxes(actors, matrix), static, scanned):
        rep.add(RULE_ID, msg)

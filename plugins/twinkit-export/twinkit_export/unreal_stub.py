"""A stand-in for Unreal's editor ``unreal`` Python module: the few calls ``place_in_map.py`` makes.

CARLA 0.9.16's editor (UE 4.26, ``CarlaUE4.uproject`` enables ``PythonScriptPlugin`` and
``EditorScriptingUtilities``) runs the package's editor script; Unreal cannot run here, so
:class:`EditorState` models the project after ``make import`` (the static-mesh assets by object
path, the saved levels with their static-mesh actors) and :func:`make_module` returns a module
object with the same names and call shapes as the real API (``EditorAssetLibrary.load_asset``,
``EditorLevelLibrary.load_level / get_all_level_actors / spawn_actor_from_object /
save_current_level``, ``StaticMesh.get_editor_property("body_setup")``,
``CollisionTraceFlag.CTF_USE_COMPLEX_AS_SIMPLE`` ...). Only what is *saved* counts: a level is
what ``reload_world`` loads again from disk, and a mesh's collision setting is what the saved
asset holds. Every call is recorded in ``EditorState.calls``.
"""
from __future__ import annotations

import types
from dataclasses import dataclass, field


class _Enum:
    def __init__(self, name: str):
        self.name = name

    def __repr__(self) -> str:
        return self.name


class CollisionTraceFlag:
    CTF_USE_DEFAULT = _Enum("CTF_USE_DEFAULT")
    CTF_USE_SIMPLE_AND_COMPLEX = _Enum("CTF_USE_SIMPLE_AND_COMPLEX")
    CTF_USE_SIMPLE_AS_COMPLEX = _Enum("CTF_USE_SIMPLE_AS_COMPLEX")
    CTF_USE_COMPLEX_AS_SIMPLE = _Enum("CTF_USE_COMPLEX_AS_SIMPLE")


class ComponentMobility:
    STATIC = _Enum("STATIC")
    STATIONARY = _Enum("STATIONARY")
    MOVABLE = _Enum("MOVABLE")


class _Props:
    """get_editor_property / set_editor_property over a dict, unknown names raising like Unreal."""

    _props: dict

    def get_editor_property(self, name: str):
        if name not in self._props:
            raise Exception(f"{type(self).__name__}: no property {name!r}")
        return self._props[name]

    def set_editor_property(self, name: str, value) -> None:
        if name not in self._props:
            raise Exception(f"{type(self).__name__}: no property {name!r}")
        self._props[name] = value


class BodySetup(_Props):
    def __init__(self):
        self._props = {"collision_trace_flag": CollisionTraceFlag.CTF_USE_DEFAULT}


class StaticMeshAsset(_Props):
    """``unreal.StaticMesh``."""

    def __init__(self, path: str):
        self._path = path
        self._props = {"body_setup": BodySetup()}

    def get_path_name(self) -> str:
        return self._path

    def get_name(self) -> str:
        return self._path.rsplit(".", 1)[-1]


class StaticMeshComponent(_Props):
    def __init__(self, mesh: StaticMeshAsset | None):
        self._props = {"static_mesh": mesh, "mobility": ComponentMobility.MOVABLE}

    def set_mobility(self, mobility) -> None:
        self._props["mobility"] = mobility


class Actor(_Props):
    def __init__(self):
        self._props = {}
        self._label = ""

    def set_actor_label(self, label: str, mark_dirty: bool = True) -> None:
        self._label = label

    def get_actor_label(self) -> str:
        return self._label


class StaticMeshActor(Actor):
    def __init__(self, mesh: StaticMeshAsset | None):
        super().__init__()
        self._props = {"static_mesh_component": StaticMeshComponent(mesh)}
        self.static_mesh_component = self._props["static_mesh_component"]
        self._location: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._rotation: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass
class Vector:
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


@dataclass
class Rotator:
    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0


@dataclass
class SavedActor:
    """A static-mesh actor as a saved level holds it."""

    label: str
    mesh: str  # the mesh's object path
    location: tuple[float, float, float]
    rotation: tuple[float, float, float]
    mobility: str


@dataclass
class EditorState:
    """The project as the editor script finds it, and what the script saved.

    meshes: object path -> saved collision trace flag name; levels: level path -> saved actors."""

    meshes: dict[str, str] = field(default_factory=dict)
    levels: dict[str, list[SavedActor]] = field(default_factory=dict)
    calls: list[tuple] = field(default_factory=list)
    log: list[str] = field(default_factory=list)

    def object_path(self, path: str) -> str | None:
        """The object path a load of ``path`` resolves to: ``/Game/A/B.B`` or the package name ``/Game/A/B``."""
        if path in self.meshes:
            return path
        full = f"{path}.{path.rsplit('/', 1)[-1]}"
        return full if full in self.meshes else None


class _Assets:
    """``unreal.EditorAssetLibrary`` over an EditorState."""

    def __init__(self, state: EditorState):
        self.state = state
        self.loaded: dict[str, StaticMeshAsset] = {}

    def mesh(self, path: str) -> StaticMeshAsset | None:
        obj = self.state.object_path(path)
        if obj is None:
            return None
        if obj not in self.loaded:
            self.loaded[obj] = StaticMeshAsset(obj)
            flag = getattr(CollisionTraceFlag, self.state.meshes[obj], CollisionTraceFlag.CTF_USE_DEFAULT)
            self.loaded[obj].get_editor_property("body_setup").set_editor_property("collision_trace_flag", flag)
        return self.loaded[obj]

    def load_asset(self, path: str):
        self.state.calls.append(("load_asset", path))
        return self.mesh(path)

    def does_asset_exist(self, path: str) -> bool:
        return self.state.object_path(path) is not None

    def save_loaded_asset(self, asset, only_if_is_dirty: bool = True) -> bool:
        self.state.calls.append(("save_loaded_asset", asset.get_path_name()))
        self.state.meshes[asset.get_path_name()] = repr(
            asset.get_editor_property("body_setup").get_editor_property("collision_trace_flag"))
        return True


class _Levels:
    """``unreal.EditorLevelLibrary`` over an EditorState: one open level, saved on request."""

    def __init__(self, state: EditorState, assets: _Assets):
        self.state, self.assets = state, assets
        self.path: str | None = None
        self.actors: list[StaticMeshActor] = []

    def load_level(self, path: str) -> bool:
        self.state.calls.append(("load_level", path))
        if path not in self.state.levels:
            return False
        self.path, self.actors = path, []
        for a in self.state.levels[path]:
            act = StaticMeshActor(self.assets.mesh(a.mesh))
            act.set_actor_label(a.label)
            act.static_mesh_component.set_mobility(getattr(ComponentMobility, a.mobility))
            act._location, act._rotation = a.location, a.rotation
            self.actors.append(act)
        return True

    def get_all_level_actors(self) -> list:
        return list(self.actors)

    def spawn_actor_from_object(self, obj, location, rotation=None):
        self.state.calls.append(("spawn_actor_from_object", obj.get_path_name() if obj else None))
        if self.path is None or not isinstance(obj, StaticMeshAsset):
            return None
        act = StaticMeshActor(obj)
        r = rotation or Rotator()
        act._location, act._rotation = (location.x, location.y, location.z), (r.roll, r.pitch, r.yaw)
        self.actors.append(act)
        return act

    def save_current_level(self) -> bool:
        self.state.calls.append(("save_current_level", self.path))
        if self.path is None:
            return False
        self.state.levels[self.path] = [_saved(a) for a in self.actors]
        return True


def _saved(a: StaticMeshActor) -> SavedActor:
    comp = a.static_mesh_component
    mesh = comp.get_editor_property("static_mesh")
    return SavedActor(a.get_actor_label(), mesh.get_path_name() if mesh else "", a._location, a._rotation,
                      repr(comp.get_editor_property("mobility")))


def make_module(state: EditorState) -> types.ModuleType:
    """A module object named ``unreal`` whose editor libraries act on ``state``."""
    assets = _Assets(state)
    mod = types.ModuleType("unreal")
    for name, obj in {"EditorAssetLibrary": assets, "EditorLevelLibrary": _Levels(state, assets),
                      "StaticMesh": StaticMeshAsset, "StaticMeshActor": StaticMeshActor, "Actor": Actor,
                      "StaticMeshComponent": StaticMeshComponent, "BodySetup": BodySetup, "Vector": Vector,
                      "Rotator": Rotator, "CollisionTraceFlag": CollisionTraceFlag,
                      "ComponentMobility": ComponentMobility}.items():
        setattr(mod, name, obj)
    mod.log = lambda msg: state.log.append(str(msg))  # type: ignore[attr-defined]
    mod.log_warning = lambda msg: state.log.append("warning: " + str(msg))  # type: ignore[attr-defined]
    mod.log_error = lambda msg: state.log.append("error: " + str(msg))  # type: ignore[attr-defined]
    return mod

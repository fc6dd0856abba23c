"""Scenes: what to feel. Objects made of materials, the devices to render them on, and
settings; compiled into render plans by :mod:`hapticsdk.compiler`.

A scene (JSON, ``schemas/scene.schema.json``) lists objects and their materials --
by library name (``"S7"``), or by target intensities (``{"hardness": 0.3}``), or a
library material with extra or overridden intensities (a warmth added to ``S7``) --
the devices to render on (channel role -> actuator plugin name and options), and
settings (importance threshold, solver, servo period).

:func:`hapticsdk.compiler.compile_scene` turns it into a
:class:`~hapticsdk.plan.RenderPlan` (solve, leave out, map roles to actuators).

A scene is plain data: reading one imports no plugin.

Spatial scenes (``schema_version`` 2): every object has a ``geometry`` (plane patch,
box or sphere; :mod:`hapticsdk.scene.geometry`) and a ``pose`` in the device
workspace (mm); :meth:`Scene.hit_tester` gives the servo loop's per-tick hit test.
Version-1 files have no geometry: each of their objects is read as the infinite plane
y = 0 (normal +y), the surface every version-1 scene rendered on. Several version-1
objects therefore share that plane; the hit test's tie rule (lower index) gives it to
the first object, and the others are felt only once the application gives them a pose
or a geometry of their own (``HitTester.set_pose``, or a version-2 file).
:meth:`Scene.to_dict` writes version 2.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

from ..errors import ValidationError
from .geometry import HitTester, PlanePatch, Pose, Shape, shape_from_dict

#: scene-file versions this module reads; :meth:`Scene.to_dict` writes the last
SCHEMA_VERSIONS = (1, 2)

if TYPE_CHECKING:
    from ..plan import RenderPlan

#: Default settings of a scene; a scene's ``settings`` are merged into these.
DEFAULT_SETTINGS: dict[str, Any] = {
    "importance": {
        "enabled": True,
        "model": "paper",
        # Project choice (not from the paper): leave a dimension out when leaving it out
        # is predicted to cost less than 10 % of the realism. The paper's mean losses
        # were 18.4 % (roughness) and 29.1 % (hardness).
        "threshold_percent": 10.0,
        "thresholds": {},
    },
    "solver": {"method": "ga-polish", "seed": 0, "options": {}, "tolerance": 0.01, "penalty": "paper",
               "data_support": True},
    "model": None,
    "servo": {"period_s": 0.001, "realtime": False, "passivity": True},
    "dimensions": None,
    "renderer_options": {},
}


def _merge(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(dict(base))
    for k, v in over.items():
        if isinstance(v, Mapping) and isinstance(out.get(k), Mapping) and k not in ("thresholds", "options"):
            out[k] = _merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def _check_names(value: Any, field: str) -> None:
    """``None`` or a list of dimension names (a string is one name, not a list of letters)."""
    if value is None:
        return
    if isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple)):
        raise ValidationError(f"must be a list of dimension names, got {type(value).__name__} {value!r:.60}",
                              field=field)
    for i, n in enumerate(value):
        if not isinstance(n, str) or not n:
            raise ValidationError(f"must be a dimension name, got {n!r:.60}", field=f"{field}[{i}]")


def _check_settings(settings: Mapping[str, Any], where: str = "scene.settings") -> None:
    """The merged settings, checked as ``schemas/scene.schema.json`` checks a file's (a scene
    built in code gets no schema; a plan's settings, which its schema leaves open, are the
    scene's settings merged): every key known, every group an object, every number a
    finite number in range (an int beyond the float range included), every flag a bool;
    the error names the field (``scene.settings.solver.tolerance``, ``where`` first)."""
    from .. import argcheck
    from ..argcheck import number
    from ..checks import check_seed
    from .limits import check_period

    for key, default in DEFAULT_SETTINGS.items():
        if isinstance(default, Mapping):
            group = settings[key]
            if not isinstance(group, Mapping):
                raise ValidationError(f"must be an object, got {type(group).__name__} {group!r:.60}",
                                      field=f"{where}.{key}")
            if key != "renderer_options":
                unknown = sorted(map(str, set(group) - set(default)))
                if unknown:
                    raise ValidationError(f"unknown setting(s) {unknown}; valid: {sorted(default)}",
                                          field=f"{where}.{key}")
    unknown = sorted(map(str, set(settings) - set(DEFAULT_SETTINGS)))
    if unknown:
        raise ValidationError(f"unknown setting(s) {unknown}; valid: {sorted(DEFAULT_SETTINGS)}", field=where)

    def flag(value: Any, field: str) -> None:
        argcheck.flag(value, f"{where}.{field}")

    def name(value: Any, field: str) -> None:
        if not isinstance(value, str) or not value:
            raise ValidationError(f"must be a non-empty string, got {value!r:.60}", field=f"{where}.{field}")

    imp, sol, servo = settings["importance"], settings["solver"], settings["servo"]
    flag(imp["enabled"], "importance.enabled")
    name(imp["model"], "importance.model")
    number(imp["threshold_percent"], f"{where}.importance.threshold_percent")
    if not isinstance(imp["thresholds"], Mapping):
        raise ValidationError(f"must be an object (dimension -> %), got {type(imp['thresholds']).__name__}",
                              field=f"{where}.importance.thresholds")
    for d, v in imp["thresholds"].items():
        number(v, f"{where}.importance.thresholds.{d}")
    name(sol["method"], "solver.method")
    check_seed(sol["seed"], f"{where}.solver.seed")
    if not isinstance(sol["options"], Mapping):
        raise ValidationError(f"must be an object of solver options, got {type(sol['options']).__name__}",
                              field=f"{where}.solver.options")
    number(sol["tolerance"], f"{where}.solver.tolerance", lo=0.0, lo_open=True)
    if sol["penalty"] not in ("paper", "normalised"):
        raise ValidationError(f"must be 'paper' or 'normalised', got {sol['penalty']!r:.60}",
                              field=f"{where}.solver.penalty")
    flag(sol["data_support"], "solver.data_support")
    if settings["model"] is not None:
        name(settings["model"], "model")
    check_period(servo["period_s"], f"{where}.servo.period_s")
    flag(servo["realtime"], "servo.realtime")
    flag(servo["passivity"], "servo.passivity")
    _check_names(settings["dimensions"], f"{where}.dimensions")
    for role, opts in settings["renderer_options"].items():
        if not isinstance(opts, Mapping):
            raise ValidationError(f"must be an object of renderer options, got {type(opts).__name__}",
                                  field=f"{where}.renderer_options.{role}")


@dataclass
class DeviceSpec:
    """The actuator serving one channel role: plugin name and keyword options."""

    actuator: str
    options: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def parse(cls, value: Any, role: str) -> "DeviceSpec":
        """A device spec from scene JSON for ``role``: an actuator name, or ``{"actuator":
        ..., "options": {...}}`` (a :class:`DeviceSpec` is returned as is); raises
        :class:`~hapticsdk.errors.ValidationError` otherwise.
        """
        if isinstance(value, DeviceSpec):
            return value
        if isinstance(value, str) and value:
            return cls(actuator=value)
        if isinstance(value, Mapping) and isinstance(value.get("actuator"), str):
            opts = value.get("options", {})
            if not isinstance(opts, Mapping):
                raise ValidationError("options must be an object", field=f"scene.devices.{role}.options")
            return cls(actuator=value["actuator"], options=dict(opts))
        raise ValidationError(f"expected an actuator name or {{'actuator': name, 'options': {{}}}}, "
                              f"got {value!r}", field=f"scene.devices.{role}")

    def to_dict(self) -> dict[str, Any]:
        """The spec as scene JSON (``actuator`` and ``options``)."""
        return {"actuator": self.actuator, "options": dict(self.options)}


@dataclass
class SceneObject:
    """One object of a scene.

    Attributes:
        name: object name.
        material: a library material name, or ``{"name": ..., "intensities": {...}}``.
        intensities: intensities added to / overriding the material's (0..1).
        dimensions: if given, only these dimensions of the material are rendered.
        geometry: the object's shape (:class:`~hapticsdk.scene.geometry.PlanePatch`,
            ``Box``, ``Sphere``, or the scene-file form ``{"shape": "sphere",
            "radius_mm": 20}``); default the infinite plane y = 0 (a version-1 object).
        pose: where the shape is (:class:`~hapticsdk.scene.geometry.Pose` or
            ``{"position_mm": [x, y, z], "rotation": {...}}``, mm); default the
            geometry's own pose (the origin, unrotated, for the scene-file form).
    """

    name: str
    material: str | dict[str, Any]
    intensities: dict[str, float] = field(default_factory=dict)
    dimensions: list[str] | None = None
    geometry: Any = None
    pose: Any = None

    def __post_init__(self) -> None:
        self._coerce_geometry(f"objects.{self.name}")

    def _coerce_geometry(self, where: str) -> None:
        """Turn the scene-file forms into a :class:`Shape` and a :class:`Pose`."""
        g, p = self.geometry, self.pose
        if p is not None and not isinstance(p, Pose):
            p = Pose.from_dict(p, field=f"{where}.pose")
        if g is None:
            g = PlanePatch()
        elif not isinstance(g, Shape):
            g = shape_from_dict(g, p, field=f"{where}.geometry")
        if p is None:
            p = g.pose
        self.geometry: Shape = g if g.pose == p else g.with_pose(p)
        self.pose: Pose = p

    def shape(self) -> Shape:
        """The object's geometry at its pose (world coordinates, mm)."""
        g = self.geometry
        return g if g.pose == self.pose else g.with_pose(self.pose)

    def to_dict(self) -> dict[str, Any]:
        """The object as scene JSON (only the optional fields that are set)."""
        d: dict[str, Any] = {"name": self.name, "material": copy.deepcopy(self.material)}
        if self.intensities:
            d["intensities"] = dict(self.intensities)
        if self.dimensions is not None:
            d["dimensions"] = list(self.dimensions)
        d["geometry"] = self.geometry.geometry_dict()
        d["pose"] = self.pose.to_dict()
        return d


@dataclass
class Scene:
    """A scene: objects, devices (role -> :class:`DeviceSpec`) and settings."""

    objects: list[SceneObject]
    devices: dict[str, DeviceSpec] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    name: str = "scene"

    def __post_init__(self) -> None:
        if isinstance(self.objects, (str, bytes, Mapping)) or not isinstance(self.objects, Sequence):
            raise ValidationError(f"must be a list of SceneObject, got {type(self.objects).__name__}",
                                  field="scene.objects")
        if not self.objects:
            raise ValidationError("a scene needs at least one object", field="scene.objects")
        for i, o in enumerate(self.objects):
            if not isinstance(o, SceneObject):
                raise ValidationError(f"expected a SceneObject, got {o!r:.60}", field=f"scene.objects[{i}]")
            if not isinstance(o.name, str) or not o.name:
                raise ValidationError(f"must be a non-empty string, got {o.name!r:.60}", field=f"scene.objects[{i}].name")
            _check_names(o.dimensions, f"scene.objects[{i}].dimensions")
        if not isinstance(self.devices, Mapping):
            raise ValidationError(f"must be an object (role -> actuator), got {type(self.devices).__name__}",
                                  field="scene.devices")
        from ..schemas_io import check_depth
        check_depth(self.devices, "scene.devices")
        self.devices = {r: DeviceSpec.parse(v, r) for r, v in dict(self.devices).items()}
        if not isinstance(self.settings or {}, Mapping):
            raise ValidationError(f"must be an object, got {type(self.settings).__name__}", field="scene.settings")
        check_depth(self.settings, "scene.settings")   # before _merge copies it (recursively)
        self.settings = _merge(DEFAULT_SETTINGS, self.settings or {})
        _check_settings(self.settings)
        names = [o.name for o in self.objects]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValidationError(f"duplicate object names {dup}", field="scene.objects")
        for i, o in enumerate(self.objects):
            if not isinstance(o.geometry, Shape) or not isinstance(o.pose, Pose):
                o._coerce_geometry(f"scene.objects[{i}]")
        self._check_bounds()

    def _check_bounds(self) -> None:
        """Every object's pose and size inside the workspace plus margin
        (:mod:`hapticsdk.scene.bounds`; the workspace the force device declares, else the
        default)."""
        from ..plugins import registry
        from .bounds import check_shape, workspace_of
        ws = None
        spec = self.devices.get("force")
        if spec is not None and spec.actuator in registry("actuator"):
            try:
                ws = workspace_of(registry("actuator").load(spec.actuator))
            except Exception:  # noqa: BLE001 - the compiler reports a plugin that does not load
                ws = None
        for i, o in enumerate(self.objects):
            shape = o.shape()
            check_shape(shape.geometry_dict(), shape.pose.to_dict(), f"scene.objects[{i}]", workspace=ws)

    # -- construction ------------------------------------------------------
    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Scene":
        """Build from the JSON form; validated against ``schemas/scene.schema.json``.

        Version 1 (no ``schema_version`` or 1): objects without geometry, each read as
        the infinite plane y = 0. Version 2: objects may have ``geometry`` and ``pose``
        (checked: positive sizes, unit quaternions and normals, finite numbers; errors
        name the field, e.g. ``scene.objects[2].geometry.radius_mm``)."""
        from ..devices.device_options import check_data_model, check_data_settings
        from ..schemas_io import check_depth, validate
        check_depth(data, "scene")   # as read_json bounds a file: 5000 levels exhaust no stack
        shapes: dict[int, Shape] = {}
        if isinstance(data, Mapping):
            # safety is not data: before the schema, so the error names the field and says why
            check_data_settings(data.get("settings"), field="scene.settings")
            check_data_model(data.get("settings"), field="scene.settings")   # files are data
            version = data.get("schema_version", 1)
            if isinstance(version, bool) or version not in SCHEMA_VERSIONS:
                raise ValidationError(f"unknown scene schema_version {version!r}; this hapticsdk reads "
                                      f"{list(SCHEMA_VERSIONS)}", field="scene.schema_version")
            objects = data.get("objects")
            if isinstance(objects, list):
                # geometry first: these checks name the exact field and cover what JSON
                # Schema cannot (finite numbers, unit lengths)
                for i, o in enumerate(objects):
                    if not isinstance(o, Mapping) or ("geometry" not in o and "pose" not in o):
                        continue
                    where = f"scene.objects[{i}]"
                    if version < 2:
                        key = "geometry" if "geometry" in o else "pose"
                        raise ValidationError(f"{key} needs \"schema_version\": 2 (this file is version "
                                              f"{version})", field=f"{where}.{key}")
                    pose = Pose.from_dict(o["pose"], field=f"{where}.pose") if "pose" in o else None
                    shapes[i] = (shape_from_dict(o["geometry"], pose, field=f"{where}.geometry")
                                 if "geometry" in o else PlanePatch(pose=pose))
        validate(data, "scene")
        objs = []
        for i, o in enumerate(data["objects"]):
            shape = shapes.get(i)
            objs.append(SceneObject(name=o.get("name", f"object{i}"), material=copy.deepcopy(o["material"]),
                                    intensities=dict(o.get("intensities", {})),
                                    dimensions=list(o["dimensions"]) if "dimensions" in o else None,
                                    geometry=shape, pose=shape.pose if shape is not None else None))
        return cls(objects=objs, devices=dict(data.get("devices", {})),
                   settings=dict(data.get("settings", {})), name=data.get("name", "scene"))

    @classmethod
    def load(cls, path: str | Path) -> "Scene":
        """Read and validate a scene JSON file (``schemas/scene.schema.json``)."""
        from ..schemas_io import read_json
        from ..argcheck import file_path
        p = file_path(path, "scene")
        data = read_json(p, field="scene")
        if isinstance(data, dict) and "name" not in data:
            data["name"] = p.stem
        return cls.from_dict(data)

    @classmethod
    def for_material(cls, material: str | Mapping[str, float], devices: Mapping[str, Any] | None = None,
                     *, dimensions: Sequence[str] | None = None, seed: int | None = None,
                     **settings: Any) -> "Scene":
        """A one-object scene: ``material`` is a library name (``"S7"``) or target
        intensities (``{"hardness": 0.4, "roughness": 0.8}``). ``seed`` seeds the solver;
        ``settings`` override :data:`DEFAULT_SETTINGS` keys (``importance=``, ``solver=``,
        ``servo=`` ...)."""
        if seed is not None:
            from ..checks import check_seed
            solver = settings.get("solver", {})
            if not isinstance(solver, Mapping):
                raise ValidationError(f"must be an object, got {type(solver).__name__} {solver!r:.60}",
                                      field="scene.settings.solver")
            settings = {**settings, "solver": {**solver, "seed": check_seed(seed)}}
        if isinstance(material, str):
            mat: str | dict[str, Any] = material
            name = material
        elif isinstance(material, Mapping):
            # named after its targets: "hardness 0.8, roughness 0.3"; each checked (True is no intensity)
            from ..perception.dimensions import check_intensity
            its = {k: check_intensity(v, f"targets.{k}") for k, v in material.items()}
            name = ", ".join(f"{k} {v:g}" for k, v in its.items()) or "intensities"
            mat = {"name": name, "intensities": its}
        else:
            raise ValidationError(f"expected a material name or intensities, got {material!r}",
                                  field="material")
        # dimensions and devices as given (a string is not a list of names): checked by the scene
        dims: Any = list(dimensions) if isinstance(dimensions, (list, tuple)) else dimensions
        devs: Any = dict(devices) if isinstance(devices, Mapping) else ({} if devices is None else devices)
        if isinstance(dims, list) and not dims:
            dims = None
        return cls(objects=[SceneObject(name="object", material=mat, dimensions=dims)],
                   devices=devs, settings=settings, name=name)

    def hit_tester(self) -> HitTester:
        """A fresh :class:`~hapticsdk.scene.geometry.HitTester` over the objects, in order
        (object index = index in :attr:`objects`)."""
        return HitTester([(o.name, o.shape()) for o in self.objects])

    def to_dict(self) -> dict[str, Any]:
        """The scene-file form, ``schema_version`` 2 (every object's geometry and pose
        written out, also for objects read from a version-1 file)."""
        return {"schema_version": SCHEMA_VERSIONS[-1], "name": self.name,
                "objects": [o.to_dict() for o in self.objects],
                "devices": {r: d.to_dict() for r, d in self.devices.items()},
                "settings": copy.deepcopy(self.settings)}

    def compile(self) -> "RenderPlan":
        """Deprecated since 0.2 (removed in 0.3): use
        :func:`hapticsdk.compiler.compile_scene` (a scene does not reach up to the
        compiler, the next stage)."""
        from .._deprecation import moved_function
        return moved_function("hapticsdk.scene.Scene.compile", "hapticsdk.compiler", "compile_scene")(self)


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene JSON file (``schemas/scene.schema.json``)."""
    return Scene.load(path)

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
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from ..errors import ValidationError

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


@dataclass
class DeviceSpec:
    """The actuator serving one channel role: plugin name and keyword options."""

    actuator: str
    options: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def parse(cls, value: Any, role: str) -> "DeviceSpec":
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
        return {"actuator": self.actuator, "options": dict(self.options)}


@dataclass
class SceneObject:
    """One object of a scene.

    Attributes:
        name: object name.
        material: a library material name, or ``{"name": ..., "intensities": {...}}``.
        intensities: intensities added to / overriding the material's (0..1).
        dimensions: if given, only these dimensions of the material are rendered.
    """

    name: str
    material: str | dict[str, Any]
    intensities: dict[str, float] = field(default_factory=dict)
    dimensions: list[str] | None = None

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"name": self.name, "material": copy.deepcopy(self.material)}
        if self.intensities:
            d["intensities"] = dict(self.intensities)
        if self.dimensions is not None:
            d["dimensions"] = list(self.dimensions)
        return d


@dataclass
class Scene:
    """A scene: objects, devices (role -> :class:`DeviceSpec`) and settings."""

    objects: list[SceneObject]
    devices: dict[str, DeviceSpec] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    name: str = "scene"

    def __post_init__(self) -> None:
        if not self.objects:
            raise ValidationError("a scene needs at least one object", field="scene.objects")
        self.devices = {r: DeviceSpec.parse(v, r) for r, v in dict(self.devices).items()}
        self.settings = _merge(DEFAULT_SETTINGS, self.settings or {})
        thr = self.settings["importance"]["threshold_percent"]
        if not isinstance(thr, (int, float)) or not np.isfinite(thr):
            raise ValidationError(f"threshold must be a finite number (%), got {thr!r}",
                                  field="scene.settings.importance.threshold_percent")
        period = self.settings["servo"]["period_s"]
        if not isinstance(period, (int, float)) or not 0 < period <= 0.1:
            raise ValidationError(f"servo period must be in (0, 0.1] s, got {period!r}",
                                  field="scene.settings.servo.period_s")
        names = [o.name for o in self.objects]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValidationError(f"duplicate object names {dup}", field="scene.objects")

    # -- construction ------------------------------------------------------
    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Scene":
        """Build from the JSON form; validated against ``schemas/scene.schema.json``."""
        from ..schemas_io import validate
        validate(data, "scene")
        objs = []
        for i, o in enumerate(data["objects"]):
            objs.append(SceneObject(name=o.get("name", f"object{i}"), material=copy.deepcopy(o["material"]),
                                    intensities=dict(o.get("intensities", {})),
                                    dimensions=list(o["dimensions"]) if "dimensions" in o else None))
        return cls(objects=objs, devices=dict(data.get("devices", {})),
                   settings=dict(data.get("settings", {})), name=data.get("name", "scene"))

    @classmethod
    def load(cls, path: str | Path) -> "Scene":
        from ..schemas_io import read_json
        p = Path(path)
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
            settings = _merge({"solver": {}}, settings)
            settings["solver"]["seed"] = int(seed)
        if isinstance(material, str):
            mat: str | dict[str, Any] = material
            name = material
        elif isinstance(material, Mapping):
            mat = {"name": "material", "intensities": {k: float(v) for k, v in material.items()}}
            name = "material"
        else:
            raise ValidationError(f"expected a material name or intensities, got {material!r}",
                                  field="material")
        return cls(objects=[SceneObject(name="object", material=mat,
                                        dimensions=list(dimensions) if dimensions else None)],
                   devices=dict(devices or {}), settings=settings, name=name)

    def to_dict(self) -> dict[str, Any]:
        return {"schema_version": 1, "name": self.name,
                "objects": [o.to_dict() for o in self.objects],
                "devices": {r: d.to_dict() for r, d in self.devices.items()},
                "settings": copy.deepcopy(self.settings)}

    def compile(self) -> "RenderPlan":
        """Shortcut for :func:`hapticsdk.compiler.compile_scene`."""
        from ..compiler import compile_scene
        return compile_scene(self)


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene JSON file (``schemas/scene.schema.json``)."""
    return Scene.load(path)

"""Scenes: what to feel (objects, their materials, the devices, settings).

Objects have a shape and a pose in the device workspace (:mod:`.geometry`); the
servo loop's per-tick hit test is :class:`~.geometry.HitTester`.

The first stage of a request: scene -> :mod:`hapticsdk.compiler` -> :mod:`hapticsdk.plan`
-> :mod:`hapticsdk.runtime` -> actuators.
"""

from typing import TYPE_CHECKING

from .geometry import Box, HitTester, PlanePatch, Pose, Shape, Sphere, shape_from_dict
from .model import DEFAULT_SETTINGS, DeviceSpec, Scene, SceneObject, load_scene

__all__ = ["DEFAULT_SETTINGS", "DeviceSpec", "Scene", "SceneObject", "load_scene",
           "Box", "HitTester", "PlanePatch", "Pose", "Shape", "Sphere", "shape_from_dict"]


if not TYPE_CHECKING:  # moved names, deprecated since 0.2 (a type checker sees only the new places)
    from .._deprecation import moved_names
    __getattr__ = moved_names(__name__, {"compile_scene": "hapticsdk.compiler"})

"""Scenes: what to feel (objects, their materials, the devices, settings).

Objects have a shape and a pose in the device workspace (:mod:`.geometry`); the
servo loop's per-tick hit test is :class:`~.geometry.HitTester`.

The first stage of a request: scene -> :mod:`hapticsdk.compiler` -> :mod:`hapticsdk.plan`
-> :mod:`hapticsdk.runtime` -> actuators.
"""

from .geometry import Box, HitTester, PlanePatch, Pose, Shape, Sphere, shape_from_dict
from .model import DEFAULT_SETTINGS, DeviceSpec, Scene, SceneObject, load_scene

__all__ = ["DEFAULT_SETTINGS", "DeviceSpec", "Scene", "SceneObject", "load_scene",
           "Box", "HitTester", "PlanePatch", "Pose", "Shape", "Sphere", "shape_from_dict"]

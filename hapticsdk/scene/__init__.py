"""Scenes: what to feel (objects, their materials, the devices, settings).

The first stage of a request: scene -> :mod:`hapticsdk.compiler` -> :mod:`hapticsdk.plan`
-> :mod:`hapticsdk.runtime` -> actuators.
"""

from .model import DEFAULT_SETTINGS, DeviceSpec, Scene, SceneObject, load_scene

__all__ = ["DEFAULT_SETTINGS", "DeviceSpec", "Scene", "SceneObject", "load_scene"]

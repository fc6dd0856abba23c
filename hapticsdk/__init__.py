"""hapticsdk: multi-modal haptic rendering from perceptual targets.

An application asks for a material (``"S7"``, or ``{"hardness": 0.8, "roughness": 0.3}``);
the SDK inverts a perception model to find the stimulus features a person perceives that
way, and renders them on the actuators that are installed (simulated by default).

Quick start::

    import hapticsdk as hs
    res = hs.solve({"hardness": 0.8, "roughness": 0.3}, seed=1)
    print(res.success, res.error, res.x_dict)
    report = hs.render("S7", seconds=2.0)
    print(report.to_dict()["tick"])

Names are imported lazily, so ``import hapticsdk`` loads no plugin and no device library.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

__version__ = "0.1.0"

_LAZY = {
    "solve": "hapticsdk.problems",
    "build_problem": "hapticsdk.problems",
    "get_solver": "hapticsdk.problems",
    "load_model": "hapticsdk.problems",
    "load_dimension": "hapticsdk.problems",
    "load_library": "hapticsdk.materials",
    "Material": "hapticsdk.materials",
    "Feature": "hapticsdk.features",
    "FeatureSpace": "hapticsdk.features",
    "PerceptionDimension": "hapticsdk.dimensions",
    "PerceptionModel": "hapticsdk.models",
    "Solver": "hapticsdk.solvers",
    "SolveProblem": "hapticsdk.solvers",
    "SolveResult": "hapticsdk.solvers",
    "Actuator": "hapticsdk.actuators",
    "HapticDevice": "hapticsdk.actuators",
    "create_actuator": "hapticsdk.actuators",
    "list_plugins": "hapticsdk.plugins",
    "Scene": "hapticsdk.scene",
    "load_scene": "hapticsdk.scene",
    "compile_scene": "hapticsdk.compiler",
    "render_plan": "hapticsdk.runtime.render",
    "HapticSDKError": "hapticsdk.errors",
}

__all__ = sorted(_LAZY) + ["render", "__version__"]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'hapticsdk' has no attribute {name!r}")


def render(material: Any, *, seconds: float = 3.0, seed: int | None = 0, devices: Any = None) -> Any:
    """Solve and render one material (a library name or ``{dimension: intensity}``) on the
    scene's devices (simulated by default); returns the render report."""
    from .compiler import compile_scene
    from .runtime.render import render_plan
    from .scene import Scene

    scene = Scene.for_material(material, devices=devices, seed=seed)
    return render_plan(compile_scene(scene), seconds=seconds)

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
from typing import TYPE_CHECKING, Any, Mapping

__version__ = "0.1.0"

#: the plugin API range of the core's own plugins (probe-virtual, playback-virtual, the MLP
#: model): this core's (hapticsdk.plugin_api.PLUGIN_API_VERSION)
hapticsdk_api = ">=1.2,<2"

if TYPE_CHECKING:  # what type checkers and IDEs see; at run time names load lazily
    from .actuators import Actuator, HapticDevice, create_actuator
    from .compiler import compile_scene
    from .dimensions import PerceptionDimension
    from .errors import HapticSDKError
    from .features import Feature, FeatureSpace
    from .materials import Material, load_library
    from .models import PerceptionModel
    from .plugins import list_plugins
    from .problems import build_problem, get_solver, load_dimension, load_model, solve
    from .runtime.render import RenderReport, render_plan
    from .runtime.session import Session, session
    from .scene import Scene, load_scene
    from .solvers import BatchSolveResult, SolveProblem, SolveResult, Solver

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
    "BatchSolveResult": "hapticsdk.solvers",
    "RenderReport": "hapticsdk.runtime.render",
    "Actuator": "hapticsdk.actuators",
    "HapticDevice": "hapticsdk.actuators",
    "create_actuator": "hapticsdk.actuators",
    "list_plugins": "hapticsdk.plugins",
    "Scene": "hapticsdk.scene",
    "load_scene": "hapticsdk.scene",
    "compile_scene": "hapticsdk.compiler",
    "render_plan": "hapticsdk.runtime.render",
    "Session": "hapticsdk.runtime.session",
    "session": "hapticsdk.runtime.session",
    "HapticSDKError": "hapticsdk.errors",
}

__all__ = sorted(_LAZY) + ["render", "__version__"]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name]), name)
        globals()[name] = value  # resolved once; later lookups skip __getattr__
        return value
    raise AttributeError(f"module 'hapticsdk' has no attribute {name!r}")


def render(material: str | Mapping[str, float], *, seconds: float = 3.0, seed: int | None = 0,
           devices: Mapping[str, Any] | None = None, realtime: bool | None = None) -> RenderReport:
    """Solve and render one material on the scene's devices (simulated by default).

    Args:
        material: a library name (``"S7"``) or target intensities in 0..1
            (``{"hardness": 0.8, "roughness": 0.3}``).
        seconds: servo time to render [s].
        seed: solver seed (``None``: fresh entropy).
        devices: role -> actuator name or spec, overriding the dimensions' defaults.
        realtime: pace the servo loop on the machine clock (``None``: the plan's setting).

    Returns:
        the :class:`~hapticsdk.runtime.render.RenderReport` (what was solved, kept and
        dropped, the actuators used, servo tick statistics).
    """
    from .compiler import compile_scene
    from .runtime.render import render_plan
    from .scene import Scene

    scene = Scene.for_material(material, devices=devices, seed=seed)
    return render_plan(compile_scene(scene), seconds=seconds, realtime=realtime)

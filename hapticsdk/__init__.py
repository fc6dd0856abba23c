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

from ._version import __version__

#: the plugin API range of the core's own plugins (probe-virtual, playback-virtual, the MLP
#: model): this core's (hapticsdk.plugin_api.PLUGIN_API_VERSION)
hapticsdk_api = ">=1.2,<2"

if TYPE_CHECKING:  # what type checkers and IDEs see; at run time names load lazily
    # ``import x as x``: an explicit re-export, so ``mypy --strict`` accepts ``hs.solve``
    from .devices.actuators import Actuator as Actuator
    from .devices.actuators import HapticDevice as HapticDevice
    from .devices.actuators import create_actuator as create_actuator
    from .compiler import compile_scene as compile_scene
    from .perception.dimensions import PerceptionDimension as PerceptionDimension
    from .errors import HapticSDKError as HapticSDKError
    from .perception.features import Feature as Feature
    from .perception.features import FeatureSpace as FeatureSpace
    from .perception.materials import Material as Material
    from .perception.materials import load_library as load_library
    from .perception.models import PerceptionModel as PerceptionModel
    from .plugins import list_plugins as list_plugins
    from .solvers.problems import build_problem as build_problem
    from .solvers.problems import get_solver as get_solver
    from .solvers.problems import load_dimension as load_dimension
    from .solvers.problems import load_model as load_model
    from .solvers.problems import solve as solve
    from .runtime.render import RenderReport as RenderReport
    from .runtime.render import render_plan as render_plan
    from .runtime.session import Session as Session
    from .runtime.session import session as session
    from .scene import Scene as Scene
    from .scene import load_scene as load_scene
    from .solvers import BatchSolveResult as BatchSolveResult
    from .solvers import SolveProblem as SolveProblem
    from .solvers import SolveResult as SolveResult
    from .solvers import Solver as Solver

#: name -> module it is loaded from on first use
_LAZY = {
    "solve": "hapticsdk.solvers.problems",
    "build_problem": "hapticsdk.solvers.problems",
    "get_solver": "hapticsdk.solvers.problems",
    "load_model": "hapticsdk.solvers.problems",
    "load_dimension": "hapticsdk.solvers.problems",
    "load_library": "hapticsdk.perception.materials",
    "Material": "hapticsdk.perception.materials",
    "Feature": "hapticsdk.perception.features",
    "FeatureSpace": "hapticsdk.perception.features",
    "PerceptionDimension": "hapticsdk.perception.dimensions",
    "PerceptionModel": "hapticsdk.perception.models",
    "Solver": "hapticsdk.solvers",
    "SolveProblem": "hapticsdk.solvers",
    "SolveResult": "hapticsdk.solvers",
    "BatchSolveResult": "hapticsdk.solvers",
    "RenderReport": "hapticsdk.runtime.render",
    "Actuator": "hapticsdk.devices.actuators",
    "HapticDevice": "hapticsdk.devices.actuators",
    "create_actuator": "hapticsdk.devices.actuators",
    "list_plugins": "hapticsdk.plugins",
    "Scene": "hapticsdk.scene",
    "load_scene": "hapticsdk.scene",
    "compile_scene": "hapticsdk.compiler",
    "render_plan": "hapticsdk.runtime.render",
    "Session": "hapticsdk.runtime.session",
    "session": "hapticsdk.runtime.session",
    "HapticSDKError": "hapticsdk.errors",
}

# a literal list (tools read it without running this file); a test checks it equals
# the lazy table plus the names defined here
__all__ = [
    "Actuator",
    "BatchSolveResult",
    "Feature",
    "FeatureSpace",
    "HapticDevice",
    "HapticSDKError",
    "Material",
    "PerceptionDimension",
    "PerceptionModel",
    "RenderReport",
    "Scene",
    "Session",
    "SolveProblem",
    "SolveResult",
    "Solver",
    "__version__",
    "build_problem",
    "compile_scene",
    "create_actuator",
    "get_solver",
    "list_plugins",
    "load_dimension",
    "load_library",
    "load_model",
    "load_scene",
    "render",
    "render_plan",
    "session",
    "solve",
]


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

"""Compilation: a scene's materials solved, dimensions left out where they matter
little (:mod:`hapticsdk.compiler.importance`), roles mapped to actuators; the result is
a :class:`~hapticsdk.plan.RenderPlan`.
"""

from .compile import compile_scene

__all__ = ["compile_scene"]

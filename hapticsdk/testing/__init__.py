"""Conformance kit for hapticsdk plugins.

Functions (no pytest needed): :func:`check` and ``check_actuator`` / ``check_device`` /
``check_dimension`` / ``check_model`` / ``check_solver`` return a :class:`KitResult` (a
list of :class:`Violation` naming the plugin and the broken rule, with ``notes`` and the
declared ``api``; :func:`format_report` prints it); ``check("hooks", module_or_name)``
checks a hook module; :func:`check_installed` checks
every installed plugin.

pytest classes (subclass in a plugin's tests): :class:`ActuatorConformance`,
:class:`DeviceConformance`, :class:`DimensionConformance`, :class:`ModelConformance`,
:class:`SolverConformance` (in :mod:`hapticsdk.testing.suites`, imported on first use).
The pytest plugin (:mod:`hapticsdk.testing.pytest_plugin`, entry point ``pytest11``)
adds the ``hapticsdk_conformance`` fixture.
"""

from __future__ import annotations

from typing import Any

from .conformance import (RULES, KitResult, Violation, assert_conforms, check, check_actuator, check_device,
                          check_dimension, check_installed, check_model, check_solver, format_report,
                          format_violations, reference_problem)

_SUITES = ("ActuatorConformance", "DeviceConformance", "DimensionConformance", "ModelConformance",
           "SolverConformance", "ImportConformance")

__all__ = ["RULES", "KitResult", "Violation", "assert_conforms", "check", "check_actuator", "check_device",
           "check_dimension", "check_installed", "check_model", "check_solver", "format_report",
           "format_violations", "reference_problem", *_SUITES]


def __getattr__(name: str) -> Any:
    if name in _SUITES:
        from . import suites
        return getattr(suites, name)
    raise AttributeError(f"module 'hapticsdk.testing' has no attribute {name!r}")

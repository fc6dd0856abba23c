"""All pluggy hook specifications of hapticsdk, in one module.

Hooks carry what *many* plugins answer at once. Choosing *one* object by name (an
actuator, a solver, a model, a dimension) is not a hook: it is a lookup in a lazy
entry-point table (:mod:`hapticsdk.plugins`). A plugin distribution publishes a module
of ``@hookimpl`` functions under the entry-point group ``hapticsdk.hooks``.
"""

from __future__ import annotations

from typing import Any

import pluggy

PROJECT = "hapticsdk"

hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)


@hookspec
def hapticsdk_materials() -> list[dict[str, Any]]:
    """Return extra materials, each a dict in the format of ``schemas/materials.schema.json``
    (``name``, ``intensities`` and optionally ``label``, ``features``, ``generated``)."""


@hookspec
def hapticsdk_dimension_info() -> list[dict[str, Any]]:
    """Describe dimensions without importing their implementation: a list of
    ``{"name", "description", "features": [names]}``."""


@hookspec
def hapticsdk_render_started(plan: Any) -> None:
    """Called once before the servo loop starts (not from the servo thread)."""


@hookspec
def hapticsdk_render_finished(plan: Any, report: Any) -> None:
    """Called once after the servo loop stopped, with its report."""


@hookspec
def hapticsdk_device_fault(device: str, error: BaseException) -> None:
    """Called (outside the tick) after a device fault caused a safe stop."""

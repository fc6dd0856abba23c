"""pluggy hooks of hapticsdk-warmth (entry point group ``hapticsdk.hooks``).

Registered by hapticsdk only when a rendered scene uses this distribution. ``EVENTS``
keeps what the render hooks saw (for tests and the docs).
"""

from __future__ import annotations

from typing import Any

from hapticsdk.hookspecs import hookimpl

EVENTS: list[tuple[str, str]] = []


@hookimpl
def hapticsdk_render_started(plan: Any) -> None:
    EVENTS.append(("started", ",".join(plan.materials)))


@hookimpl
def hapticsdk_render_finished(plan: Any, report: Any) -> None:
    EVENTS.append(("finished", report.material))


@hookimpl
def hapticsdk_materials() -> list[dict[str, Any]]:
    return [{"name": "warm-felt", "label": "felt at 30 degC (example plugin)", "generated": True,
             "intensities": {"hardness": 0.1, "roughness": 0.3, "warmth": 0.8}, "features": {}}]


@hookimpl
def hapticsdk_dimension_info() -> list[dict[str, Any]]:
    return [{"name": "warmth", "description": "perceived warmth on contact (Peltier)",
             "features": ["Tsurf", "Eff"]}]

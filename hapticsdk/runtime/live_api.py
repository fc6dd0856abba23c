"""Argument checks of the live session's API (:class:`~hapticsdk.runtime.session.Session`):
kept apart from the session so its methods call one function each.

* intensities are numbers in 0..1 (``"0.5"`` is refused: the live API takes values from
  the application's code, where a string is a bug; the command line parses its own text);
* poses and sizes are finite and inside the sensing device's workspace plus a margin
  (:mod:`hapticsdk.scene.bounds`).
"""

from __future__ import annotations

from typing import Any, Mapping

from ..errors import ValidationError

__all__ = ["intensities", "check_object", "session_workspace"]


def intensities(material: Mapping[Any, Any], field: str) -> dict[str, float]:
    """``{dimension: intensity}`` with every intensity a real number in 0..1."""
    from ..argcheck import number
    out: dict[str, float] = {}
    for d, v in material.items():
        if not isinstance(d, str) or not d:
            raise ValidationError(f"dimension names must be non-empty strings, got {d!r}", field=field)
        out[d] = number(v, f"{field}.{d}", lo=0.0, hi=1.0)
    return out


def session_workspace(devices: Mapping[str, str]) -> Any:
    """The workspace (mm) declared by the class of a session's sensing device (the actuator
    on the ``force`` role, else any with ``workspace_mm``), or ``None`` (the default)."""
    from ..plugins import registry
    from ..scene.bounds import workspace_of
    names = [devices["force"]] if "force" in devices else []
    names += [n for r, n in sorted(devices.items()) if r != "force"]
    for name in names:
        try:
            ws = workspace_of(registry("actuator").load(name))
        except Exception:  # noqa: BLE001 - a plugin that does not load declares nothing here
            continue
        if ws is not None:
            return ws
    return None


def check_object(shape: Any, field: str, workspace: Any = None) -> None:
    """Refuse a shape whose pose or size lies outside the workspace plus margin."""
    from ..scene.bounds import check_shape
    check_shape(shape.geometry_dict(), shape.pose.to_dict(), field, workspace=workspace)

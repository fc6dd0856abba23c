"""Bounds on object poses and sizes: inside the device workspace plus a margin.

A pose or a size far outside what the probe can reach renders nothing useful, and a huge
one (``1e308`` mm) overflows the contact arithmetic (a penetration of 1e308 mm times a
stiffness is an infinite force before the safety layer clamps it, published in the
state as such). Every pose and size -- from a scene file and from the live API
(:meth:`Session.add_object`, :meth:`Session.move_object`) -- is checked here.

The workspace is the sensing device's ``workspace_mm`` class attribute when it declares
one (``((x_min, x_max), (y_min, y_max), (z_min, z_max))``, mm); otherwise
:data:`DEFAULT_WORKSPACE_MM`, a 1 m cube centred on the origin: the reach of a seated
person's arm (about 0.6-0.7 m from the shoulder) rounded up, which covers every desktop
haptic device (a Phantom Omni's force-feedback workspace is about 160 x 120 x 70 mm).

The margin is one workspace extent on every side (:func:`limits`): an object may lie
partly or wholly outside the reachable region (a floor plane, a wall behind the device),
and may be as large as the workspace plus that margin, but not more.
"""

from __future__ import annotations

from typing import Any, Mapping

from ..errors import ValidationError

__all__ = ["DEFAULT_WORKSPACE_MM", "limits", "check_shape"]

#: default workspace (mm) when the device declares none: a 1 m cube centred on the origin
DEFAULT_WORKSPACE_MM: tuple[tuple[float, float], ...] = ((-500.0, 500.0), (-500.0, 500.0), (-500.0, 500.0))


def limits(workspace: Any = None) -> tuple[list[tuple[float, float]], float]:
    """``(position range per axis, largest size)`` (mm) for ``workspace`` (default
    :data:`DEFAULT_WORKSPACE_MM`): each axis widened by the largest workspace extent on
    both sides, sizes up to twice that extent."""
    ws = DEFAULT_WORKSPACE_MM if workspace is None else workspace
    try:
        box = [(float(lo), float(hi)) for lo, hi in ws]
    except (TypeError, ValueError):
        raise ValidationError(f"workspace_mm must be three (min, max) pairs in mm, got {ws!r}",
                              field="workspace_mm") from None
    if len(box) != 3 or not all(lo < hi for lo, hi in box):
        raise ValidationError(f"workspace_mm must be three (min, max) pairs with min < max, got {ws!r}",
                              field="workspace_mm")
    extent = max(hi - lo for lo, hi in box)
    return [(lo - extent, hi + extent) for lo, hi in box], 2.0 * extent


def workspace_of(device_cls: Any) -> Any:
    """The ``workspace_mm`` a device class declares, or ``None``."""
    return getattr(device_cls, "workspace_mm", None)


def check_shape(geometry: Mapping[str, Any], pose: Mapping[str, Any], field: str, *, workspace: Any = None) -> None:
    """Refuse a shape (``geometry_dict()``) and pose (``to_dict()``) outside the workspace
    plus margin, naming the field (``objects[2].pose.position_mm[0]``)."""
    from ..argcheck import number

    box, max_size = limits(workspace)
    pos = list((pose or {}).get("position_mm", (0.0, 0.0, 0.0)))
    for i, (v, (lo, hi)) in enumerate(zip(pos, box)):
        number(v, f"{field}.pose.position_mm[{i}]", lo=lo, hi=hi)
    for key in ("radius_mm", "thickness_mm"):
        if key in geometry and geometry[key] is not None:
            number(geometry[key], f"{field}.geometry.{key}", lo=0.0, hi=max_size)
    for i, v in enumerate(geometry.get("half_size_mm") or ()):
        number(v, f"{field}.geometry.half_size_mm[{i}]", lo=0.0, hi=max_size)

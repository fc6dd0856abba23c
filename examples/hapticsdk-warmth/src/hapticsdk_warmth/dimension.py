"""The warmth dimension: features, the skin-safety constraint and the Peltier renderer."""

from __future__ import annotations

from typing import Any, ClassVar, Mapping

import numpy as np

from hapticsdk.perception.dimensions import (ChannelCommand, Constraint, DimensionRenderer, PerceptionDimension, RoleSpec,
                                  TickInput)
from hapticsdk.errors import ValidationError
from hapticsdk.perception.features import Feature

from .model import FEATURES
from .thermal import T_SKIN_C, contact_temperature

#: hottest contact temperature rendered (°C): below the ~43 °C heat-pain threshold
MAX_CONTACT_C = 42.0


class SkinSafeConstraint(Constraint):
    """Contact temperature T_c(Tsurf, Eff) <= 42 °C (value 42 >= bound T_c)."""

    name: ClassVar[str] = "warmth.skin-safe"
    features: ClassVar[tuple[str, ...]] = ("Tsurf", "Eff")

    def _bound_and_value(self, cols: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        tc = contact_temperature(cols["Tsurf"], cols["Eff"])
        return tc, np.full_like(tc, MAX_CONTACT_C)


class WarmthRenderer(DimensionRenderer):
    """Holds the Peltier at the material's contact temperature while touched (role
    ``thermal``; ``amplitude`` is the target surface temperature in °C) and at skin
    temperature (neutral) otherwise."""

    roles = ("thermal",)

    def __init__(self, t_surface_c: float, effusivity: float, *, idle_c: float = T_SKIN_C) -> None:
        self.t_contact_c = float(contact_temperature(t_surface_c, effusivity))
        self.t_surface_c = float(t_surface_c)
        self.effusivity = float(effusivity)
        self.idle_c = float(idle_c)
        self.contact_ticks = 0

    def tick(self, inp: TickInput) -> list[ChannelCommand]:
        if inp.in_contact:
            self.contact_ticks += 1
            return [ChannelCommand(role="thermal", amplitude=self.t_contact_c)]
        return [ChannelCommand(role="thermal", amplitude=self.idle_c)]

    def describe(self) -> dict:
        return {"Tsurf_c": self.t_surface_c, "Eff": self.effusivity, "contact_temperature_c": self.t_contact_c,
                "idle_c": self.idle_c, "contact_ticks": self.contact_ticks}


class WarmthDimension(PerceptionDimension):
    """Perceived warmth (0 cold .. 1 warm) on touch, rendered by a Peltier element."""

    hapticsdk_api: ClassVar[str] = ">=1.0,<2"
    name: ClassVar[str] = "warmth"
    description: ClassVar[str] = "perceived warmth on contact; a Peltier holds the material's contact temperature"
    features: ClassVar[tuple[Feature, ...]] = FEATURES
    default_actuators: ClassVar[dict[str, str]] = {"thermal": "peltier-virtual"}
    roles: ClassVar[dict[str, RoleSpec]] = {
        "thermal": RoleSpec("thermal", {"amplitude": "degC"}, "Peltier surface temperature set-point")}
    render_features: ClassVar[tuple[str, ...]] = ("Tsurf", "Eff")
    default_model: ClassVar[str] = "warmth"

    def constraints(self, **context: float) -> list[Constraint]:
        return [SkinSafeConstraint()]

    def renderer(self, features: Mapping[str, float], **options: Any) -> WarmthRenderer:
        vals = {}
        for f in FEATURES:
            if f.name not in features:
                raise ValidationError(f"missing feature {f.name!r}", field=f"features.{f.name}")
            v = float(features[f.name])
            if not np.isfinite(v):
                raise ValidationError("NaN or infinite", field=f"features.{f.name}")
            if not f.lower <= v <= f.upper:
                raise ValidationError(f"{v:g} {f.unit} outside [{f.lower:g}, {f.upper:g}]", field=f"features.{f.name}")
            vals[f.name] = v
        return WarmthRenderer(vals["Tsurf"], vals["Eff"], **options)

"""Renderers that stand in for a dropped dimension (the plan's ``replacement``), e.g. the
paper's "No Hardness" condition: a constant 1 N force while in contact."""

from __future__ import annotations

from typing import Any, Mapping

from ..perception.dimensions import ChannelCommand, DimensionRenderer, TickInput
from ..errors import ValidationError


class ConstantForceRenderer(DimensionRenderer):
    """A constant normal force while the probe is in contact, 0 outside (role ``force``).

    Renders a dropped hardness the way the paper's "No Hardness" condition did (1 N).
    """

    def __init__(self, force_n: float = 1.0, *, role: str = "force", replaces: str | None = None) -> None:
        f = float(force_n)
        if not (f >= 0 and f < 1e3):
            raise ValidationError(f"force must be a finite number >= 0 N, got {force_n!r}",
                                  field="replacement.force_n")
        self.force_n = f
        self.roles = (role,)
        self.role = role
        self.replaces = replaces

    def tick(self, inp: TickInput) -> list[ChannelCommand]:
        return [ChannelCommand(role=self.role, force_n=self.force_n if inp.in_contact else 0.0)]

    def describe(self) -> dict:
        return {"renderer": "constant-force", "force_n": self.force_n, "role": self.role,
                "replaces": self.replaces}


def make_replacement(rep: Mapping[str, Any], dimension: str) -> DimensionRenderer:
    """Build the renderer a plan names as ``replacement`` of the dropped ``dimension``."""
    kind = rep.get("renderer")
    if kind == "constant-force":
        return ConstantForceRenderer(rep.get("force_n", 1.0), role=rep.get("role", "force"),
                                     replaces=dimension)
    raise ValidationError(f"unknown replacement renderer {kind!r} (known: constant-force)",
                          field=f"plan.dropped.{dimension}.replacement")

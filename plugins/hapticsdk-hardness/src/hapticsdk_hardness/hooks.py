"""pluggy hook implementations of the hardness plugin (entry-point group ``hapticsdk.hooks``)."""

from __future__ import annotations

from typing import Any

from hapticsdk.hookspecs import hookimpl


@hookimpl
def hapticsdk_dimension_info() -> list[dict[str, Any]]:
    """Describe the hardness dimension for hook callers (name, description, features)."""
    return [{"name": "hardness",
             "description": "perceived hardness while pressing (GS rendered by the Omni up to 2.3 N/mm, "
                            "the rest by a voice coil, formula (8))",
             "features": ["GS", "W"]}]

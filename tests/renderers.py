"""Renderers shared by the runtime tests and the servo-path benchmark, and the run that
measures what a loop gave the finger (:func:`largest_energy`).

Importable as ``renderers`` through ``tests/conftest.py`` (the benchmark puts ``tests/`` on
its path itself)."""

from __future__ import annotations

from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer


class Spring(DimensionRenderer):
    """``F = K x penetration`` on the force role while in contact, nothing else (no voice
    coil, no fast law): a plain wall of ``k`` N/mm."""
    roles = ("force",)

    def __init__(self, k: float) -> None:
        self.k = k

    def tick(self, inp):
        return [ChannelCommand("force", force_n=self.k * inp.penetration_mm if inp.in_contact else 0.0)]


def largest_energy(loop, dev, seconds: float) -> float:
    """Run ``loop`` for ``seconds``; the largest energy the arm gave the finger (J,
    ``dev.energy_to_user_j()`` after each tick)."""
    loop.start(seconds)
    worst = -float("inf")
    while True:
        more = loop.tick()
        worst = max(worst, dev.energy_to_user_j())
        if not more:
            break
    loop.finish()
    return float(worst)

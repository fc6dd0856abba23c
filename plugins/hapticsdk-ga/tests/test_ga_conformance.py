"""hapticsdk-ga solvers against the hapticsdk conformance kit."""

from __future__ import annotations

from hapticsdk.testing import SolverConformance


class TestGA(SolverConformance):
    plugin_name = "ga"


class TestDE(SolverConformance):
    plugin_name = "de"


class TestGAPolish(SolverConformance):
    plugin_name = "ga-polish"

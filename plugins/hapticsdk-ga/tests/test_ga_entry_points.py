"""The distribution's entry points resolve to Solver classes with their documented names."""

from hapticsdk.plugins import registry
from hapticsdk.solvers import Solver

NAMES = {"ga", "de", "de-scipy", "polish", "ga-polish", "amortised"}


def test_entry_points_load():
    reg = registry("solver")
    assert NAMES <= set(reg.names())
    for n in NAMES:
        cls = reg.load(n)
        assert issubclass(cls, Solver) and cls.name == n
        assert reg.info(n).distribution == "hapticsdk-ga"

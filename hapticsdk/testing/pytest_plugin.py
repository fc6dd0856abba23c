"""pytest plugin of hapticsdk (entry point ``pytest11``: ``hapticsdk``).

Adds the fixture ``hapticsdk_conformance``: ``hapticsdk_conformance("actuator",
"piezo-virtual")`` runs the conformance kit and fails the test with the list of
violations (plugin and rule named). The subclassable test classes are in
:mod:`hapticsdk.testing` (``ActuatorConformance`` ...). This module imports no plugin.
"""

from __future__ import annotations

from typing import Any, Callable

import pytest


@pytest.fixture
def hapticsdk_conformance() -> Callable[..., list]:
    """``check(kind, target, *, options=None, rules=None)`` that fails the test on violations
    and returns the (empty) list otherwise."""
    from .conformance import assert_conforms, check

    def run(kind: str, target: Any, *, options: Any = None, rules: Any = None) -> list:
        v = check(kind, target, options=options, rules=rules)
        assert_conforms(v)
        return v
    return run


def pytest_configure(config: pytest.Config) -> None:
    """Register the ``hapticsdk_conformance`` marker."""
    config.addinivalue_line("markers", "hapticsdk_conformance: a hapticsdk plugin conformance test")

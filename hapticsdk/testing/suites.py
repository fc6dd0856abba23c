"""pytest classes of the conformance kit: subclass one in a plugin's tests.

::

    from hapticsdk.testing import ActuatorConformance

    class TestPiezoVirtual(ActuatorConformance):
        plugin_name = "piezo-virtual"          # entry-point name

Each class runs every rule of its kind as one parametrised test (``test_rule[limits-
enforced]`` ...); a failure lists the violations, naming the plugin and the rule. To
build the plugin yourself (options, a test double), override the fixture of the class
(``actuator_factory``, ``device_factory``, ``dimension_factory``, ``model_factory``) or,
for solvers, the class attribute ``solver_options``.
"""

from __future__ import annotations

from typing import Any, Callable, ClassVar

import pytest

from .conformance import RULES, assert_conforms, check


class _Conformance:
    kind: ClassVar[str] = ""
    #: entry-point name of the plugin under test
    plugin_name: ClassVar[str] = ""
    #: keyword options the plugin is created with
    plugin_options: ClassVar[dict[str, Any]] = {}

    def _target(self, factory: Callable[[], Any] | None) -> Any:
        if not self.plugin_name and factory is None:
            pytest.fail(f"{type(self).__name__}: set plugin_name or override the factory fixture")
        return factory if factory is not None else self.plugin_name


class ActuatorConformance(_Conformance):
    """Contract of an output actuator (entry-point group ``hapticsdk.actuators``)."""

    kind = "actuator"

    @pytest.fixture
    def actuator_factory(self) -> Callable[[], Any] | None:
        """Zero-argument callable returning a new, unopened actuator (default: by name)."""
        return None

    @pytest.mark.parametrize("rule", [r for r in RULES["actuator"] if r != "import"])
    def test_rule(self, rule: str, actuator_factory: Any) -> None:
        assert_conforms(check(self.kind, self._target(actuator_factory), options=self.plugin_options,
                              rules=[rule]))


class DeviceConformance(ActuatorConformance):
    """Contract of a haptic device (an actuator that senses)."""

    kind = "device"

    @pytest.fixture
    def device_factory(self) -> Callable[[], Any] | None:
        return None

    @pytest.mark.parametrize("rule", [r for r in RULES["device"] if r != "import"])
    def test_rule(self, rule: str, device_factory: Any) -> None:  # type: ignore[override]
        assert_conforms(check(self.kind, self._target(device_factory), options=self.plugin_options,
                              rules=[rule]))


class DimensionConformance(_Conformance):
    """Contract of a perception dimension (group ``hapticsdk.dimensions``)."""

    kind = "dimension"

    @pytest.fixture
    def dimension_factory(self) -> Callable[[], Any] | None:
        return None

    @pytest.mark.parametrize("rule", [r for r in RULES["dimension"] if r != "import"])
    def test_rule(self, rule: str, dimension_factory: Any) -> None:
        assert_conforms(check(self.kind, self._target(dimension_factory), rules=[rule]))


class ModelConformance(_Conformance):
    """Contract of a perception model factory (group ``hapticsdk.models``)."""

    kind = "model"

    @pytest.fixture
    def model_factory(self) -> Callable[[], Any] | None:
        return None

    @pytest.mark.parametrize("rule", [r for r in RULES["model"] if r != "import"])
    def test_rule(self, rule: str, model_factory: Any) -> None:
        assert_conforms(check(self.kind, self._target(model_factory), rules=[rule]))


class SolverConformance(_Conformance):
    """Contract of a solver (group ``hapticsdk.solvers``)."""

    kind = "solver"
    #: options for the solver under test (e.g. fewer generations to keep tests fast)
    solver_options: ClassVar[dict[str, Any]] = {}

    @pytest.mark.parametrize("rule", [r for r in RULES["solver"] if r != "import"])
    def test_rule(self, rule: str) -> None:
        assert_conforms(check(self.kind, self._target(None), options=self.solver_options, rules=[rule]))


class ImportConformance:
    """Every named plugin imports (one test per ``(kind, name)`` in ``plugins``)."""

    plugins: ClassVar[list[tuple[str, str]]] = []

    def test_imports(self) -> None:
        from .conformance import Violation
        from ..plugins import registry
        from ..errors import PluginError
        bad = []
        for kind, name in self.plugins:
            try:
                registry(kind).load(name)
            except PluginError as exc:
                bad.append(Violation(kind, name, "import", str(exc)))
        assert_conforms(bad)

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


def _rules(kind: str) -> list[str]:
    """The rules of ``kind`` a class parametrises over (``import`` runs inside each)."""
    return [r for r in RULES[kind] if r != "import"]


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

    def _assert_rule(self, rule: str, factory: Callable[[], Any] | None,
                     options: dict[str, Any] | None = None) -> None:
        assert_conforms(check(self.kind, self._target(factory), options=options, rules=[rule]))


class ActuatorConformance(_Conformance):
    """Contract of an output actuator (entry-point group ``hapticsdk.actuators``)."""

    kind = "actuator"

    @pytest.fixture
    def actuator_factory(self) -> Callable[[], Any] | None:
        """Zero-argument callable returning a new, unopened actuator (default: by name)."""
        return None

    @pytest.mark.parametrize("rule", _rules("actuator"))
    def test_rule(self, rule: str, actuator_factory: Any) -> None:
        """One conformance rule of actuator plugins, checked on the actuator the factory
        builds.
        """
        self._assert_rule(rule, actuator_factory, self.plugin_options)


class DeviceConformance(ActuatorConformance):
    """Contract of a haptic device (an actuator that senses)."""

    kind = "device"

    @pytest.fixture
    def device_factory(self) -> Callable[[], Any] | None:
        return None

    @pytest.mark.parametrize("rule", _rules("device"))
    def test_rule(self, rule: str, device_factory: Any) -> None:  # type: ignore[override]
        """One conformance rule of sensing devices, checked on the device the factory
        builds.
        """
        self._assert_rule(rule, device_factory, self.plugin_options)


class DimensionConformance(_Conformance):
    """Contract of a perception dimension (group ``hapticsdk.dimensions``)."""

    kind = "dimension"

    @pytest.fixture
    def dimension_factory(self) -> Callable[[], Any] | None:
        return None

    @pytest.mark.parametrize("rule", _rules("dimension"))
    def test_rule(self, rule: str, dimension_factory: Any) -> None:
        """One conformance rule of dimension plugins, checked on the dimension the factory
        builds.
        """
        self._assert_rule(rule, dimension_factory)


class ModelConformance(_Conformance):
    """Contract of a perception model factory (group ``hapticsdk.models``)."""

    kind = "model"

    @pytest.fixture
    def model_factory(self) -> Callable[[], Any] | None:
        return None

    @pytest.mark.parametrize("rule", _rules("model"))
    def test_rule(self, rule: str, model_factory: Any) -> None:
        """One conformance rule of perception models, checked on the model the factory
        builds.
        """
        self._assert_rule(rule, model_factory)


class SolverConformance(_Conformance):
    """Contract of a solver (group ``hapticsdk.solvers``)."""

    kind = "solver"
    #: options for the solver under test (e.g. fewer generations to keep tests fast)
    solver_options: ClassVar[dict[str, Any]] = {}

    @pytest.mark.parametrize("rule", _rules("solver"))
    def test_rule(self, rule: str) -> None:
        """One conformance rule of solver plugins, checked with the class's solver options.
        """
        self._assert_rule(rule, None, self.solver_options)


class ImportConformance:
    """Every named plugin imports (one test per ``(kind, name)`` in ``plugins``)."""

    plugins: ClassVar[list[tuple[str, str]]] = []

    def test_imports(self) -> None:
        """Every plugin the class names imports through the registry without error."""
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

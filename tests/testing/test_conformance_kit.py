"""The conformance kit catches broken plugins, naming the plugin and the rule."""

from __future__ import annotations

from importlib import metadata
from typing import Any, ClassVar

import numpy as np
import pytest

from hapticsdk.devices.actuators import Actuator, ActuatorLimits
from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer, PerceptionDimension
from hapticsdk.perception.features import Feature
from hapticsdk.perception.models import PerceptionModel
from hapticsdk.plugins import registry
from hapticsdk.solvers import Solver, SolverOutput
from hapticsdk.testing import (ActuatorConformance, SolverConformance, check, check_actuator,
                               check_dimension, check_model, check_solver, reference_problem)


def rules_broken(violations) -> set[str]:
    return {v.rule for v in violations}


class GoodCoil(Actuator):
    hapticsdk_api = ">=1.2,<2"   # the plugin API these test plugins are written for
    name: ClassVar[str] = "good-coil"
    channel: ClassVar[str] = "vibration"
    limits = ActuatorLimits(frequency_range_hz=(30.0, 120.0), max_amplitude=1.0, amplitude_unit="1")
    simulated: ClassVar[bool] = True

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        self.out = (0.0, 0.0)

    def _command(self, cmd: ChannelCommand) -> None:
        self.out = (cmd.frequency_hz or 0.0, cmd.amplitude or 0.0)

    def _open(self) -> None:
        self.out = (0.0, 0.0)

    def _stop(self) -> None:
        self.out = (0.0, 0.0)

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("vibration", frequency_hz=self.out[0], amplitude=self.out[1])


class BypassCoil(GoodCoil):
    """Broken: skips the safety layer, so commands above its limits reach the hardware."""

    name: ClassVar[str] = "bypass-coil"

    def command(self, cmd: ChannelCommand, *, now: float | None = None) -> ChannelCommand:
        if not self.is_open:
            from hapticsdk.errors import DeviceError
            raise DeviceError("closed", device=self.label)
        if cmd.amplitude is not None and not np.isfinite(cmd.amplitude):
            from hapticsdk.errors import ValidationError
            raise ValidationError("nan", field="amplitude")
        self._command(cmd)
        return cmd


class StuckCoil(GoodCoil):
    """Broken: its stop fails."""

    name: ClassVar[str] = "stuck-coil"

    def _stop(self) -> None:
        raise OSError("driver does not answer")


class NoLimitCoil(GoodCoil):
    name: ClassVar[str] = "nolimit-coil"
    limits = ActuatorLimits()


def test_a_good_actuator_conforms():
    assert check_actuator(GoodCoil) == []


def test_exceeding_declared_limits_is_caught():
    v = check_actuator(BypassCoil)
    assert "limits-enforced" in rules_broken(v)
    msg = "\n".join(map(str, v))
    assert "bypass-coil" in msg and "frequency_range_hz" in msg


def test_a_failing_stop_is_caught():
    v = check_actuator(StuckCoil)
    assert "safe-stop" in rules_broken(v)
    assert any("stuck-coil" in str(x) for x in v)


def test_undeclared_limits_are_caught():
    assert "limits-declared" in rules_broken(check_actuator(NoLimitCoil))


def test_a_plugin_that_raises_on_import_is_named(monkeypatch):
    reg = registry("actuator")
    table = dict(reg._table())
    table["broken-import"] = metadata.EntryPoint(name="broken-import", value="no_such_module_xyz:Thing",
                                                 group="hapticsdk.actuators")
    monkeypatch.setattr(reg, "_eps", table)
    v = check("actuator", "broken-import")
    assert [x.rule for x in v] == ["import"]
    assert "broken-import" in str(v[0]) and "failed to import" in str(v[0])


class _Const(DimensionRenderer):
    roles = ("coil",)

    def __init__(self, value: float) -> None:
        self.value = value

    def tick(self, inp):
        return [ChannelCommand("coil", frequency_hz=self.value, amplitude=0.5)]


class NaNDimension(PerceptionDimension):
    """Broken: its renderer returns NaN and it accepts NaN features."""
    hapticsdk_api = ">=1.2,<2"   # the plugin API these test plugins are written for

    name = "nan-dim"
    features = (Feature("q", "1", 0.0, 1.0),)
    default_actuators = {"coil": "piezo-virtual"}

    def renderer(self, features, **options):
        return _Const(float("nan") if features.get("q", 0) > 0.4 else 50.0)


def test_a_renderer_returning_nan_is_caught():
    v = check_dimension(NaNDimension)
    broken = rules_broken(v)
    assert "renderer" in broken and "renderer-bad-input" in broken
    assert all("nan-dim" in str(x) for x in v)


class WrongShapeModel(PerceptionModel):
    hapticsdk_api = ">=1.2,<2"   # the plugin API these test plugins are written for
    def __init__(self) -> None:
        super().__init__(("a", "b"), ("x",), name="wrong-shape")

    def _predict(self, X):
        return np.zeros((X.shape[0], 2))


class NonVectorModel(PerceptionModel):
    """Broken: the batch answer depends on the other rows."""
    hapticsdk_api = ">=1.2,<2"   # the plugin API these test plugins are written for

    def __init__(self) -> None:
        from hapticsdk.perception.features import FeatureSpace
        sp = FeatureSpace((Feature("a", "1", 0, 1), Feature("b", "1", 0, 1)))
        super().__init__(("a", "b"), ("x",), feature_space=sp, name="non-vector")

    def _predict(self, X):
        return np.clip(X[:, :1] * 0 + X[:, 0].mean(), 0, 1)


def test_model_shape_and_vectorisation_rules():
    v = check_model(WrongShapeModel)
    assert rules_broken(v) == {"shapes"} and "wrong-shape" in str(v[0])
    v = check_model(NonVectorModel)
    assert "vectorised" in rules_broken(v)


def test_the_default_model_conforms():
    assert check_model("default") == []


class GlobalRandomSolver(Solver):
    """Broken: ignores the seed (draws from numpy's global state)."""
    hapticsdk_api = ">=1.2,<2"   # the plugin API these test plugins are written for

    name = "global-random"
    default_options = {"n": 4000}

    def _solve(self, problem, rng, trace):
        X = problem.space.random(self.options["n"], np.random.default_rng())
        f = problem.evaluate(np.broadcast_to(X, (problem.n_targets,) + X.shape))
        best = X[np.argmin(f, axis=1)]
        trace.record(self.options["n"], f.min(axis=1))
        return SolverOutput(best, nfev=self.options["n"] * problem.n_targets, nit=1)


def test_a_solver_that_ignores_its_seed_is_caught():
    v = check_solver(GlobalRandomSolver)
    assert "determinism" in rules_broken(v)
    assert "global-random" in str(v[0])


def test_reference_problem_is_reachable():
    p = reference_problem()
    # b = 3 c gives d2 = 0.75 and satisfies b >= 2c; a solving tanh gives d1 = 0.4
    a = (np.arctanh(2 * 0.4 - 1) + 1) / 2
    assert p.evaluate(np.array([[a, 6.0, 2.0]]))[0] < 1e-9


# -- the pytest classes, as a plugin author uses them ----------------------------

class TestGoodCoilWithTheSuite(ActuatorConformance):
    @pytest.fixture
    def actuator_factory(self):
        return GoodCoil


class TestGaWithTheSuite(SolverConformance):
    plugin_name = "ga"


def test_the_fixture_fails_with_named_rule(hapticsdk_conformance):
    with pytest.raises(AssertionError, match="bypass-coil.*limits-enforced"):
        hapticsdk_conformance("actuator", BypassCoil)
    assert hapticsdk_conformance("actuator", GoodCoil) == []

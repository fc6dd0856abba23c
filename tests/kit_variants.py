"""Builders shared by the conformance-kit tests (``tests/testing``) and the scene tests
(``tests/scene``): a force device that reports the force its motors give (and the same
declaring its read-back the output), a voice coil whose output lags its drive, one-line
constraints (``x >= bound``) whose bound and value a test supplies, correct or broken, a
correct solver (``GoodSolver``, which the broken solver variants subclass), a model of a
coil dimension (``BuzzModel``), and ``rules_of`` (the rules a kit result names).

Importable as ``kit_variants`` through ``tests/conftest.py`` (the suite runs with
``--import-mode=importlib``, which puts no test folder on ``sys.path``)."""

from __future__ import annotations

from typing import Any, Callable, ClassVar, Iterator

import numpy as np

from hapticsdk.devices.actuators import Actuator, ActuatorLimits, DeviceState, HapticDevice
from hapticsdk.errors import ValidationError
from hapticsdk.perception.dimensions import ChannelCommand, Constraint, DimensionRenderer, PerceptionDimension, RoleSpec
from hapticsdk.perception.features import Feature, FeatureSpace
from hapticsdk.perception.models import PerceptionModel
from hapticsdk.solvers import Solver, SolverOutput

#: the plugin API the test plugins are written for
API = ">=1.2,<2"


def along_y(cmd: ChannelCommand) -> float:
    """The force of ``cmd`` along y (N): ``force_n`` projected from its ``direction`` (the
    contact normal; None is +y), as a device rendering on the y axis alone applies it."""
    return (cmd.force_n or 0.0) * (1.0 if cmd.direction is None else float(cmd.direction[1]))


class ForceArm(HapticDevice):
    """A correct force device: its motors saturate at ``saturation_n`` (the declared
    ``max_force_n``); it reads back the force they give."""
    hapticsdk_api = API
    name: ClassVar[str] = "kit-arm"
    limits = ActuatorLimits(max_force_n=3.0)
    simulated: ClassVar[bool] = True
    saturation_n = 3.0

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        self.f, self.t = 0.0, 0.0

    def _open(self) -> None:
        self.f, self.t = 0.0, 0.0

    def _command(self, cmd: ChannelCommand) -> None:
        self.f = float(np.clip(along_y(cmd), -self.saturation_n, self.saturation_n))

    def _stop(self) -> None:
        self.f = 0.0

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("force", force_n=self.f)

    def _read_state(self) -> DeviceState:
        return DeviceState(t=self.t, position_mm=np.zeros(3), velocity_mm_s=np.zeros(3),
                           force_n=np.array([0.0, self.f, 0.0]))

    def _step(self, dt: float) -> None:
        self.t += dt


class OutputArm(ForceArm):
    """:class:`ForceArm` declaring that its read-back is the output (the force its motors
    give), so the kit's output rules judge it."""
    name: ClassVar[str] = "kit-arm-output"
    readback_source: ClassVar[str] = "output"


#: the lagging coil's declared max_amplitude (V)
LAG_COIL_MAX_V = 2.0


class LagCoil(Actuator):
    """A correct simulated voice coil: its output follows the drive through a first-order
    lag (``tau_s``) it declares (settle time ``tau ln(full scale / half a step)``), and it
    reads back that output."""
    hapticsdk_api = API
    name: ClassVar[str] = "kit-lag-coil"
    channel: ClassVar[str] = "vibration"
    simulated: ClassVar[bool] = True
    readback_source: ClassVar[str] = "output"
    tau_s = 0.002
    limits = ActuatorLimits(frequency_range_hz=(30.0, 300.0), max_amplitude=LAG_COIL_MAX_V, amplitude_unit="V",
                            amplitude_resolution=0.001, frequency_resolution_hz=0.5,
                            settle_time_s=0.002 * float(np.log(LAG_COIL_MAX_V / 0.0005)))

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        self.drive_f = self.drive_a = self.out_a = 0.0

    def _open(self) -> None:
        self.drive_f = self.drive_a = self.out_a = 0.0

    def _command(self, cmd: ChannelCommand) -> None:
        self.drive_f = float(cmd.frequency_hz or 0.0)
        self.drive_a = float(cmd.amplitude or 0.0)

    def _stop(self) -> None:
        self.drive_a = 0.0

    def step(self, dt: float) -> None:
        self.out_a += (self.drive_a - self.out_a) * (1.0 - float(np.exp(-dt / self.tau_s)))

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("vibration", frequency_hz=self.drive_f, amplitude=self.out_a)


def coil_dimension(name: str, feature: str, renderer_cls: type, model: str) -> type[PerceptionDimension]:
    """A correct dimension ``name`` with one render feature ``feature`` (0..1) on the
    lagging coil (role ``buzz``, vibration in V), rendered by ``renderer_cls(x)`` (a
    subclass swaps ``renderer_cls``), its default model ``model``."""
    def constraints(self: PerceptionDimension, **context: Any) -> list:
        return []

    def renderer(self: Any, features: Any, **options: Any) -> DimensionRenderer:
        x = features.get(feature)
        if x is None or not np.isfinite(x):
            raise ValidationError(f"{feature} needed", field=f"features.{feature}")
        return self.renderer_cls(float(x))
    return type(f"CoilDim_{name}", (PerceptionDimension,), {
        "__doc__": f"{name}: vibration on the lagging coil.", "hapticsdk_api": API, "name": name,
        "features": (Feature(feature, "1", 0.0, 1.0),), "render_features": (feature,),
        "default_actuators": {"buzz": LagCoil.name},
        "roles": {"buzz": RoleSpec("vibration", {"frequency_hz": "Hz", "amplitude": "V"})},
        "default_model": model, "renderer_cls": renderer_cls, "constraints": constraints, "renderer": renderer})


def buzz_dimension(renderer_cls: type) -> type[PerceptionDimension]:
    """The kit-buzz dimension (feature ``kit.b`` on the lagging coil, model
    ``kit-buzz-model``: :class:`BuzzModel`) rendered by ``renderer_cls(x)``."""
    return coil_dimension("kit-buzz", "kit.b", renderer_cls, "kit-buzz-model")


def buzz_installed(renderer_cls: type) -> Iterator[None]:
    """The lagging coil, :func:`buzz_dimension` of ``renderer_cls`` and its model
    registered as if installed, for the duration of the generator (a fixture body:
    ``yield from buzz_installed(...)``)."""
    yield from registered([(registry_of("actuator"), LagCoil.name, LagCoil),
                           (registry_of("dimension"), "kit-buzz", buzz_dimension(renderer_cls)),
                           (registry_of("model"), "kit-buzz-model", BuzzModel)])


def registry_of(kind: str) -> Any:
    """``hapticsdk.plugins.registry(kind)``, imported on use."""
    from hapticsdk.plugins import registry
    return registry(kind)


def registered(regs: Any) -> Iterator[None]:
    """Register ``(registry, name, object)`` triples as if installed, for the duration of
    the generator (a fixture body: ``yield from registered([...])``)."""
    for reg, name, obj in regs:
        reg.register(name, obj)
    try:
        yield
    finally:
        for reg, name, _ in regs:
            reg.unregister(name)


def rules_of(v: Any) -> set[str]:
    """The rules a kit result's violations name."""
    return {x.rule for x in v}


def dishonest(arm: type[ForceArm], name: str) -> type[ForceArm]:
    """``arm`` declaring 50 N on motors that saturate at 2 N (dishonest limits)."""
    return type(arm.__name__ + "Dishonest", (arm,), {
        "__doc__": "Declares 50 N on motors that saturate at 2 N.", "name": name,
        "limits": ActuatorLimits(max_force_n=50.0), "saturation_n": 2.0})


def constraint(name: str, feature: str,
               bound_and_value: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
               doc: str = "") -> type[Constraint]:
    """A constraint ``value >= bound`` on one feature, ``bound_and_value(column)``
    giving both (a test's correct or broken variant)."""
    def _bound_and_value(self: Constraint, cols: Any) -> tuple[np.ndarray, np.ndarray]:
        return bound_and_value(np.asarray(cols[feature]))
    return type(f"Constraint_{name}", (Constraint,), {
        "__doc__": doc or None, "name": name, "features": (feature,), "_bound_and_value": _bound_and_value})


def never(name: str = "never", feature: str = "kit.x") -> type[Constraint]:
    """``x >= x + 1``: no feature vector satisfies it."""
    return constraint(name, feature, lambda x: (x + 1.0, x), "x >= x + 1: never")


class GoodSolver(Solver):
    """A correct solver: seeded random search of formula (6), shrinking around the best."""
    hapticsdk_api = API
    name = "kit-results-solver"
    default_options: ClassVar[dict[str, Any]] = {"n": 600, "rounds": 8}

    def _solve(self, problem, rng, trace):
        n, m = self.options["n"], problem.n_targets
        lo, hi = problem.space.lower, problem.space.upper
        best = np.repeat(((lo + hi) / 2)[None, :], m, axis=0)
        width = hi - lo
        for _ in range(self.options["rounds"]):
            X = problem.clip(best[:, None, :] + (rng.random((m, n, len(lo))) - 0.5) * width)
            X[:, 0, :] = best
            f = problem.evaluate(X)
            best = X[np.arange(m), np.argmin(f, axis=1)]
            trace.record(n * m, f.min(axis=1))
            width = width / 2
        return SolverOutput(best, nfev=n * m * self.options["rounds"], nit=self.options["rounds"])


class BuzzModel(PerceptionModel):
    """A correct model of kit-buzz (a dimension of :func:`coil_dimension` with feature
    ``kit.b``); ``_out`` is what broken variants change."""
    hapticsdk_api = API

    def __init__(self) -> None:
        space = FeatureSpace((Feature("kit.b", "1", 0.0, 1.0),))
        super().__init__(space.names, ("kit-buzz",), feature_space=space, name="kit-buzz-model")

    def _predict(self, X):
        return self._out(X, 0.5 * (1 + np.tanh(X[:, :1] - 0.5)))

    def _out(self, X, y):
        return y

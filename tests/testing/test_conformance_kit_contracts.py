"""Each rule of the kit added for plugin contracts (read-back, timing, roles, feasibility,
model cross-checks) catches a broken variant that the older rules let through, names the
plugin and the rule, and flags no correct plugin."""

from __future__ import annotations

import time
from typing import Any, ClassVar

import numpy as np
import pytest

from hapticsdk.devices.actuators import Actuator, ActuatorLimits
from hapticsdk.perception.dimensions import ChannelCommand, Constraint, DimensionRenderer, PerceptionDimension, RoleSpec
from hapticsdk.perception.features import Feature, FeatureSpace
from hapticsdk.perception.models import MLPModel, PerceptionModel
from hapticsdk.plugins import registry
from hapticsdk.testing import check, check_actuator, check_device, check_dimension, check_model
from kit_variants import ForceArm, dishonest, never


def broken(violations) -> set[str]:
    return {v.rule for v in violations}


# -- actuators ------------------------------------------------------------------

class Coil(Actuator):
    """A correct actuator: reads back what it wrote (frequency Hz, amplitude 0..1)."""
    hapticsdk_api = ">=1.2,<2"   # the plugin API these test plugins are written for
    name: ClassVar[str] = "kit-coil"
    channel: ClassVar[str] = "vibration"
    limits = ActuatorLimits(frequency_range_hz=(30.0, 300.0), max_amplitude=1.0, amplitude_unit="1")
    simulated: ClassVar[bool] = True

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        self.hw = (0.0, 0.0)

    def _open(self) -> None:
        self.hw = (0.0, 0.0)

    def _command(self, cmd: ChannelCommand) -> None:
        self.hw = (cmd.frequency_hz or 0.0, cmd.amplitude or 0.0)

    def _stop(self) -> None:
        self.hw = (0.0, 0.0)

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("vibration", frequency_hz=self.hw[0], amplitude=self.hw[1])


class NoStopCoil(Coil):
    """stop() does not zero the output."""
    def _stop(self) -> None:
        pass


class DoublingCoil(Coil):
    """Writes twice the commanded amplitude to the hardware."""
    def _command(self, cmd: ChannelCommand) -> None:
        self.hw = (cmd.frequency_hz or 0.0, 2.0 * (cmd.amplitude or 0.0))


class FixedFrequencyCoil(Coil):
    """Ignores the frequency the safety layer set (plays its own 100 Hz)."""
    def _command(self, cmd: ChannelCommand) -> None:
        self.hw = (100.0, cmd.amplitude or 0.0)


class RandomCoil(Coil):
    """Random output."""
    def _command(self, cmd: ChannelCommand) -> None:
        self.hw = (cmd.frequency_hz or 0.0, float(np.random.default_rng().random()))


class StaleCoil(Coil):
    """Keeps its last output across close() and open()."""
    def _open(self) -> None:
        pass

    def _stop(self) -> None:
        pass


class SlowCoil(Coil):
    """A 3 ms command in a 1 ms loop."""
    def _command(self, cmd: ChannelCommand) -> None:
        time.sleep(0.003)
        super()._command(cmd)


class NoReadBackCoil(Coil):
    def _read_back(self):
        return None


class RaisingCloseCoil(Coil):
    """Overrides the public close() and raises from it."""
    def close(self) -> None:
        super().close()
        raise OSError("port busy")


class PlateNoLimits(Coil):
    """A friction plate that declares no limits at all."""
    name: ClassVar[str] = "kit-plate"
    channel: ClassVar[str] = "friction"
    limits = ActuatorLimits()


class Arm(ForceArm):
    """A correct force device: reads back the force its motors are set to."""


DishonestArm = dishonest(Arm, "kit-dishonest-arm")


def test_correct_actuators_conform():
    assert check_actuator(Coil) == []
    assert check_device(Arm) == []


@pytest.mark.parametrize("cls, rule", [
    (NoStopCoil, "read-back"), (DoublingCoil, "output-follows-command"),
    (FixedFrequencyCoil, "output-follows-command"), (RandomCoil, "output-follows-command"),
    (StaleCoil, "reopen"), (SlowCoil, "timing"), (NoReadBackCoil, "read-back"),
    (RaisingCloseCoil, "template"), (RaisingCloseCoil, "close"), (PlateNoLimits, "limits-declared"),
])
def test_each_broken_actuator_is_caught_by_its_rule(cls, rule):
    # the coil that is slow by design runs its own rule only (every other rule's commands
    # would cost 3 ms each); the others run the whole kit
    v = check("actuator", cls, rules=[rule]) if cls is SlowCoil else check_actuator(cls)
    assert rule in broken(v), v
    assert any(x.rule == rule and x.plugin == cls.name for x in v)


def test_random_output_is_also_not_deterministic():
    assert "determinism" in broken(check_actuator(RandomCoil))


def test_dishonest_limits_are_caught_by_read_back():
    v = check_device(DishonestArm)
    assert "output-follows-command" in broken(v)
    assert "outputs 2 N" in "\n".join(map(str, v))


def test_every_first_party_actuator_reads_back():
    for name in registry("actuator").names():
        cls = registry("actuator").load(name)
        assert cls._read_back is not Actuator._read_back, name


# -- dimensions -----------------------------------------------------------------

_Never = never()


class _NoDoc(Constraint):
    name = "no-doc"
    features = ("kit.x",)

    def _bound_and_value(self, cols):
        x = np.asarray(cols["kit.x"])
        return np.zeros_like(x), x


_NoDoc.__doc__ = None


class _Renderer(DimensionRenderer):
    roles = ("vibration",)

    def __init__(self, amp: float = 0.5, silent: bool = False, delay_s: float = 0.0) -> None:
        self.amp, self.silent, self.delay_s = amp, silent, delay_s

    def tick(self, inp):
        if self.delay_s:
            time.sleep(self.delay_s)
        if self.silent:
            return []
        return [ChannelCommand("vibration", frequency_hz=100.0, amplitude=self.amp if inp.in_contact else 0.0)]


class KitDim(PerceptionDimension):
    """A correct dimension: one feature, its own model, a vibration role on the voice coil."""
    hapticsdk_api = ">=1.2,<2"   # the plugin API these test plugins are written for
    name = "kit-dim"
    features = (Feature("kit.x", "1", 0.0, 1.0),)
    render_features = ("kit.x",)
    default_actuators: ClassVar[dict[str, str]] = {"vibration": "voicecoil-virtual"}
    roles: ClassVar[dict[str, RoleSpec]] = {"vibration": RoleSpec("vibration", {"frequency_hz": "Hz",
                                                                               "amplitude": "1"})}
    default_model = "kit-model"
    renderer_kw: ClassVar[dict[str, Any]] = {}

    def constraints(self, **context):
        return [_NoDoc()]

    def renderer(self, features, **options):
        from hapticsdk.errors import ValidationError
        x = features.get("kit.x")
        if x is None or not np.isfinite(x):
            raise ValidationError("kit.x needed", field="features.kit.x")
        # the amplitude follows kit.x (a renderer must render its render features)
        return _Renderer(**{"amp": 0.2 + 0.6 * float(x), **self.renderer_kw})


class KitModel(PerceptionModel):
    hapticsdk_api = ">=1.2,<2"   # the plugin API these test plugins are written for
    def __init__(self, dims=("kit-dim",), feats=(("kit.x", "1"),)) -> None:
        space = FeatureSpace(tuple(Feature(n, u, 0.0, 1.0) for n, u in feats))
        super().__init__(space.names, dims, feature_space=space, name="kit-model")

    def _predict(self, X):
        return np.repeat(0.5 * (1 + np.tanh(X[:, :1] - 0.5)), self.n_outputs, axis=1)


@pytest.fixture
def kit_model():
    reg = registry("model")
    reg.register("kit-model", KitModel)
    yield reg
    reg.unregister("kit-model")


def test_a_correct_dimension_conforms_even_with_an_undocumented_constraint(kit_model):
    pytest.importorskip("hapticsdk_hardness")
    assert check_dimension(KitDim) == []


def _variant(**attrs):
    return type("Variant", (KitDim,), attrs)


@pytest.mark.parametrize("attrs, rule", [
    ({"constraints": lambda self, **c: [_Never()]}, "constraints-feasible"),
    ({"roles": {}}, "roles-declared"),
    ({"roles": {"vibration": RoleSpec("vibration", {"frequency_hz": "Hz", "amplitude": "V"})}}, "roles-declared"),
    ({"renderer_kw": {"silent": True}}, "renderer-commands"),
    ({"renderer_kw": {"delay_s": 0.002}}, "timing"),
    ({"default_model": "kit-model-other"}, "model-match"),
])
def test_each_broken_dimension_is_caught_by_its_rule(kit_model, attrs, rule):
    pytest.importorskip("hapticsdk_hardness")
    if attrs.get("default_model") == "kit-model-other":
        kit_model.register("kit-model-other", lambda: KitModel(dims=("something-else",)))
    try:
        # a renderer slow by design runs its own rule only: the renderer rule's sweep and
        # long run would tick it ~9000 times (18 s at 2 ms a tick)
        v = check("dimension", _variant(**attrs), rules=[rule]) if rule == "timing" else check_dimension(_variant(**attrs))
    finally:
        kit_model.unregister("kit-model-other")
    assert rule in broken(v), v


def test_a_model_reading_a_feature_no_dimension_contributes_is_caught(kit_model):
    pytest.importorskip("hapticsdk_hardness")
    kit_model.register("kit-model", lambda: KitModel(feats=(("kit.x", "1"), ("kit.y", "1"))))
    v = check_dimension(KitDim)
    assert "model-match" in broken(v) and "kit.y" in "\n".join(map(str, v))


def test_500_newtons_in_contact_is_caught():
    pytest.importorskip("hapticsdk_hardness")

    class Shove(DimensionRenderer):
        roles = ("force",)

        def tick(self, inp):
            return [ChannelCommand("force", force_n=500.0 if inp.in_contact else 0.0)]

    class ShoveDim(KitDim):
        name = "kit-shove"
        default_actuators: ClassVar[dict[str, str]] = {"force": "omni-virtual"}
        roles: ClassVar[dict[str, RoleSpec]] = {"force": RoleSpec("force", {"force_n": "N"})}

        def renderer(self, features, **options):
            super().renderer(features)
            return Shove()

    registry("model").register("kit-model", lambda: KitModel(dims=("kit-shove",)))
    try:
        v = check_dimension(ShoveDim)
    finally:
        registry("model").unregister("kit-model")
    assert "renderer-commands" in broken(v) and "500" in "\n".join(map(str, v))


# -- models ---------------------------------------------------------------------

def _default_mlp():
    pytest.importorskip("hapticsdk_onnx")
    base = registry("model").load("default")()
    return base


def test_the_default_model_conforms():
    assert check_model(_default_mlp) == []


def test_outputs_5_percent_outside_the_scale_are_caught():
    base = _default_mlp()

    class Overshoot(PerceptionModel):
        def __init__(self):
            super().__init__(base.feature_names, base.dimension_names, feature_space=base.feature_space,
                             metadata=base.metadata, name="overshoot")

        def _predict(self, X):
            return base.predict(X) * 1.1 - 0.05     # 0..1 -> -0.05..1.05

    assert "shapes" in broken(check_model(Overshoot))


def test_a_jacobian_10_percent_off_is_caught():
    base = _default_mlp()
    W = base.mlp.weights

    class OffJacobian(MLPModel):
        hapticsdk_api = ">=1.2,<2"

        def jacobian(self, G, **kw):
            return 1.1 * super().jacobian(G)

    def make():
        return OffJacobian(W, base.feature_names, base.dimension_names, feature_space=base.feature_space,
                           metadata=base.metadata, name="off-jacobian")
    assert "jacobian" in broken(check_model(make))
    good = lambda: MLPModel(W, base.feature_names, base.dimension_names, feature_space=base.feature_space,  # noqa: E731
                            metadata=base.metadata, name="mlp")
    assert check_model(good) == []

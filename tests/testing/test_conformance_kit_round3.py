"""Kit rules of plugin API 1.2 (issue 25): read-back of the physical output after the
ramp has settled, force plausibility on every force-carrying role, close/stop rules that
can fail, models against the installed dimensions, constraint cost, typed roles, the
declared API. Every rule of every kind has a broken variant here that it catches, by that
rule; the correct variants conform (no false positive)."""

from __future__ import annotations

import contextlib
import sys
import types
from typing import Any, ClassVar

import numpy as np
import pytest

from hapticsdk.devices.actuators import Actuator, ActuatorLimits, DeviceState
from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer, PerceptionDimension, RoleSpec
from hapticsdk.errors import ValidationError
from hapticsdk.perception.features import Feature, FeatureSpace
from hapticsdk.perception.models import PerceptionModel
from hapticsdk.plugins import registry
from hapticsdk.solvers import Solver
from hapticsdk.testing import RULES, check, check_actuator, check_device, check_dimension, check_model
from hapticsdk.testing.conformance import KitResult, format_report
from kit_variants import API, along_y, constraint, dishonest, never, registered, rules_of
from kit_variants import OutputArm as Arm

needs_hardness = pytest.mark.skipif("omni-virtual" not in registry("actuator"),
                                    reason="hapticsdk-hardness not installed")


# ---------------------------------------------------------------------------
# actuators: a plate (friction, amplitude in V) that reports its modelled output
# ---------------------------------------------------------------------------

class Plate(Actuator):
    """A correct electro-adhesion plate: its voltage follows the drive through a first-order
    lag (time constant ``tau_s``) and a slew limit, which it models and reports
    (``readback_source = "output"``); it declares the time that takes to settle within its
    resolution (0.05 V): ``tau * ln(full scale / half a step)`` plus the slew time."""
    hapticsdk_api = API
    name: ClassVar[str] = "kit-plate"
    channel: ClassVar[str] = "friction"
    simulated: ClassVar[bool] = True
    readback_source: ClassVar[str] = "output"
    tau_s = 0.004
    slew_v_per_s = 3000.0
    limits = ActuatorLimits(max_amplitude=150.0, amplitude_unit="V", amplitude_resolution=0.05,
                            settle_time_s=0.004 * float(np.log(150.0 / 0.025)) + 150.0 / 3000.0)

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        self.drive = 0.0
        self.out = 0.0

    def _open(self) -> None:
        self.drive, self.out = 0.0, 0.0

    def _command(self, cmd: ChannelCommand) -> None:
        self.drive = float(cmd.amplitude or 0.0)

    def _stop(self) -> None:
        self.drive = 0.0

    def step(self, dt: float) -> None:
        d = (self.drive - self.out) * (1.0 - np.exp(-dt / self.tau_s))
        lim = self.slew_v_per_s * dt
        self.out += float(np.clip(d, -lim, lim))

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("friction", amplitude=self.out)


class DriveRecordPlate(Plate):
    """Correct too, but reports what it wrote (the kit notes it)."""
    name: ClassVar[str] = "kit-plate-record"
    readback_source: ClassVar[str] = "drive"

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("friction", amplitude=self.drive)


class SlowPlate(Plate):
    """Declares a settle time 10 x shorter than its lag needs."""
    name: ClassVar[str] = "kit-plate-slow"
    tau_s = 0.05


class NoStopPlate(Plate):
    """stop() does nothing: the plate keeps ~its last voltage."""
    name: ClassVar[str] = "kit-plate-nostop"

    def _stop(self) -> None:
        pass


class SlowStopPlate(Plate):
    """stop() ramps down over 2 s, far beyond its declared settle time."""
    name: ClassVar[str] = "kit-plate-slowstop"

    def _stop(self) -> None:
        self.drive = 0.0
        self.slew_v_per_s = 75.0


class RandomPlate(Plate):
    """Reports a random output."""
    name: ClassVar[str] = "kit-plate-random"

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("friction", amplitude=float(np.random.default_rng().random() * 150.0))


class StalePlate(Plate):
    """Keeps its output across close() and open()."""
    name: ClassVar[str] = "kit-plate-stale"

    def _open(self) -> None:
        pass

    def _stop(self) -> None:
        pass

    def step(self, dt: float) -> None:
        if self.drive:
            super().step(dt)


class CloseFailsPlate(Plate):
    """Its backend close raises (the core used to swallow it)."""
    name: ClassVar[str] = "kit-plate-closefails"

    def _close(self) -> None:
        raise OSError("port busy")


class CloseSkipsStopPlate(Plate):
    """Its close() releases the device without stopping the backend first."""
    name: ClassVar[str] = "kit-plate-closeskipsstop"

    def close(self) -> None:
        self.stop = lambda: True   # type: ignore[method-assign]  # shadows the core's stop()
        try:
            super().close()
        finally:
            del self.stop


class RecordOffPlate(DriveRecordPlate):
    """Reports a drive record 0.8 of its 0.05 V step off what it wrote: a record has only
    the write's quantisation (half a step), so this is caught."""
    name: ClassVar[str] = "kit-plate-recordoff"

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("friction", amplitude=self.drive + 0.04)


class OutputOffPlate(Plate):
    """The same 0.04 V off, on a reported output: within one step (the write's and the
    reading's quantisation), so it conforms."""
    name: ClassVar[str] = "kit-plate-outputoff"

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("friction", amplitude=self.out + 0.04 if self.drive else self.out)


class StopFailsPlate(Plate):
    """Its backend stop raises."""
    name: ClassVar[str] = "kit-plate-stopfails"

    def _stop(self) -> None:
        self.drive = 0.0
        raise OSError("bus error")


class BypassPlate(Plate):
    """Its amplifier has 3 x the gain it declares: 150 V commanded (the declared limit)
    gives 450 V at the plate, which it reports."""
    name: ClassVar[str] = "kit-plate-bypass"

    def _command(self, cmd: ChannelCommand) -> None:
        self.drive = 3.0 * float(cmd.amplitude or 0.0)


class SpyBypassPlate(Plate):
    """Overrides the public command() to skip the safety layer."""
    name: ClassVar[str] = "kit-plate-spy"

    def command(self, cmd, *, now=None):  # type: ignore[override]
        self._command(cmd)
        return cmd


class UnlimitedPlate(Plate):
    """A friction plate that declares no amplitude limit."""
    name: ClassVar[str] = "kit-plate-unlimited"
    limits = ActuatorLimits(amplitude_unit="V")


class ExtraOptionPlate(Plate):
    """Swallows unknown options."""
    name: ClassVar[str] = "kit-plate-options"

    def __init__(self, **kw: Any) -> None:
        kw = {k: v for k, v in kw.items() if k in ("label", "safety")}
        super().__init__(**kw)


class StringPrivilegedPlate(Plate):
    """privileged_options = "library": a string, not a collection of names."""
    name: ClassVar[str] = "kit-plate-privstr"
    privileged_options = "library"  # type: ignore[assignment]


class _LibraryPlate(Plate):
    """A plate that loads a native library (an option only code may set)."""

    def __init__(self, *, library: str | None = None, **options: Any) -> None:
        super().__init__(**options)
        self.library = library


class MisspeltPrivilegedPlate(_LibraryPlate):
    """Declares a privileged option its constructor does not take (``libary``)."""
    name: ClassVar[str] = "kit-plate-privtypo"
    privileged_options: ClassVar = ("libary",)


class TuplePrivilegedPlate(_LibraryPlate):
    """Correct: a tuple of names, each an option of the constructor."""
    name: ClassVar[str] = "kit-plate-privtuple"
    privileged_options: ClassVar = ("library",)


class WrongChannelPlate(Plate):
    name: ClassVar[str] = "kit-plate-channel"
    channel: ClassVar[str] = "adhesion"


class OpenedPlate(Plate):
    """Is open before open() is called."""
    name: ClassVar[str] = "kit-plate-opened"

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        self._is_open = True


class NaNPlate(Plate):
    """A validating public command() replaced by one that lets NaN through (and hides it)."""
    name: ClassVar[str] = "kit-plate-nan"

    def command(self, cmd, *, now=None):  # type: ignore[override]
        if cmd.amplitude is not None and not np.isfinite(cmd.amplitude):
            return cmd
        return super().command(cmd, now=now)


class SlowCommandPlate(Plate):
    """A 3 ms command in a 1 ms loop."""
    name: ClassVar[str] = "kit-plate-timing"

    def _command(self, cmd: ChannelCommand) -> None:
        import time
        time.sleep(0.003)
        super()._command(cmd)


class NoReadBackPlate(Plate):
    name: ClassVar[str] = "kit-plate-noreadback"

    def _read_back(self):
        return None


class JitterPlate(Plate):
    """Reports the output with a random sub-resolution dither, different per instance run
    (the determinism rule sees two instances disagree)."""
    name: ClassVar[str] = "kit-plate-jitter"

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("friction", amplitude=self.out + float(np.random.default_rng().random()) * 1e-3)


class UnitClashPlate(Plate):
    """Accepts amplitude in kV while its limits are in V."""
    name: ClassVar[str] = "kit-plate-units"
    accepts: ClassVar[dict[str, str]] = {"amplitude": "kV"}


class SpelledUnitPlate(Plate):
    """Correct: accepts amplitude in "volt", its limits in "V" (the same unit)."""
    name: ClassVar[str] = "kit-plate-volt"
    accepts: ClassVar[dict[str, str]] = {"amplitude": "volt"}


class NegativeSettlePlate(Plate):
    name: ClassVar[str] = "kit-plate-settle"
    limits = ActuatorLimits(max_amplitude=150.0, amplitude_unit="V", settle_time_s=-0.1)


class MeasuredPlate(Plate):
    """readback_source must be "drive" or "output"."""
    name: ClassVar[str] = "kit-plate-measured"
    readback_source: ClassVar[str] = "measured"


Arm50 = dishonest(Arm, "kit-arm50")


class BadStateArm(Arm):
    name: ClassVar[str] = "kit-arm-state"

    def _read_state(self) -> DeviceState:
        return DeviceState(t=self.t, position_mm=np.zeros(2), velocity_mm_s=np.zeros(3))


ACTUATOR_VARIANTS = [
    (NoStopPlate, "safe-stop"), (SlowStopPlate, "safe-stop"),
    (SlowPlate, "output-follows-command"), (RandomPlate, "output-follows-command"), (StalePlate, "reopen"),
    (CloseFailsPlate, "close"), (CloseSkipsStopPlate, "close"), (RecordOffPlate, "output-follows-command"),
    (StopFailsPlate, "safe-stop"), (BypassPlate, "limits-enforced"),
    (SpyBypassPlate, "template"), (UnlimitedPlate, "limits-declared"), (ExtraOptionPlate, "options"),
    (StringPrivilegedPlate, "privileged-options"), (MisspeltPrivilegedPlate, "privileged-options"),
    (WrongChannelPlate, "class"), (OpenedPlate, "lifecycle"), (NaNPlate, "bad-input"),
    (SlowCommandPlate, "timing"), (NoReadBackPlate, "read-back"), (JitterPlate, "determinism"),
    (UnitClashPlate, "limits-declared"), (NegativeSettlePlate, "limits-declared"), (MeasuredPlate, "class"),
]


@pytest.mark.parametrize("cls", [Plate, DriveRecordPlate, TuplePrivilegedPlate, SpelledUnitPlate, OutputOffPlate])
def test_correct_plates_conform(cls):
    assert check_actuator(cls) == []


def test_correct_arm_conforms():
    assert check_device(Arm) == []


@pytest.mark.parametrize("cls, rule", ACTUATOR_VARIANTS, ids=[f"{c.__name__}-{r}" for c, r in ACTUATOR_VARIANTS])
def test_each_broken_actuator_is_caught_by_its_rule(cls, rule):
    # a plate that is slow by design runs its own rule only: every other rule's commands
    # would cost 3 ms each (15 s here); those rules run on the correct plates above
    v = check("actuator", cls, rules=[rule]) if cls is SlowCommandPlate else check_actuator(cls)
    assert rule in rules_of(v), format_report(v)
    assert all(x.plugin == cls.name for x in v)


@pytest.mark.parametrize("cls, rule", [(Arm50, "output-follows-command"), (BadStateArm, "state")])
def test_each_broken_device_is_caught_by_its_rule(cls, rule):
    assert rule in rules_of(check_device(cls))


def test_an_honest_lagged_output_passes_only_after_the_ramp_has_settled():
    """The plate's output lags its drive by ~45 ms to settle; it conforms because the kit
    holds each command for the safety ramp plus the declared settle time, and fails when
    the declared settle time is shorter than its lag (SlowPlate)."""
    v = check_actuator(SlowPlate, )
    assert "output-follows-command" in rules_of(v)
    msg = "\n".join(map(str, v))
    assert "tolerance" in msg and "V" in msg


class RampedPlate(Plate):
    """A 1.1-style plate (no settle_time_s) whose output ramps over its ``ramp_s`` option
    (200 ms from rest to full scale) and which reports that output: the kit waits its
    declared ramp time."""
    name: ClassVar[str] = "kit-plate-ramped"
    limits = ActuatorLimits(max_amplitude=150.0, amplitude_unit="V", amplitude_resolution=0.05)

    def __init__(self, *, ramp_s: float = 0.2, **kw: Any) -> None:
        super().__init__(**kw)
        self.ramp_s = ramp_s

    def step(self, dt: float) -> None:
        lim = 150.0 * dt / self.ramp_s
        self.out += float(np.clip(self.drive - self.out, -lim, lim))


def test_a_ramp_declared_as_ramp_s_is_waited_for():
    assert RampedPlate().settle_time_s == 0.2
    assert check_actuator(RampedPlate) == []
    # the same plate claiming a 20 ms ramp while taking 200 ms is caught: its output is
    # still at ~120 V 22 ms after stop() from full drive
    liar = type("Liar", (RampedPlate,), {"name": "kit-plate-liar", "settle_time_s": property(lambda self: 0.02)})
    assert "safe-stop" in rules_of(check_actuator(liar))


class LagRateArm(Arm):
    """An honest arm whose motor force follows the drive with a 5 ms lag (reported), which
    declares the settle time that lag needs within its 1 mN resolution, ``tau ln(3 N / 0.5
    mN)``, and a force-rate limit the safety layer applies (2 mN per tick: 1.5 s from rest
    to full scale, far beyond the start ramp)."""
    name: ClassVar[str] = "kit-arm-rate"
    tau_s = 0.005
    limits = ActuatorLimits(max_force_n=3.0, max_force_rate_n_per_tick=0.002, force_resolution_n=0.001,
                            settle_time_s=0.005 * float(np.log(3.0 / 0.0005)))

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        self.drive = 0.0

    def _open(self) -> None:
        super()._open()
        self.drive = 0.0

    def _command(self, cmd: ChannelCommand) -> None:
        self.drive = float(np.clip(along_y(cmd), -self.saturation_n, self.saturation_n))

    def _stop(self) -> None:
        self.drive, self.f = 0.0, 0.0

    def _step(self, dt: float) -> None:
        self.t += dt
        self.f += (self.drive - self.f) * (1.0 - float(np.exp(-dt / self.tau_s)))


def test_a_declared_force_rate_limit_is_waited_for():
    """The kit holds a command while the safety layer's output still slews at the declared
    rate, then for the settle time: the honest lagged arm conforms (it was flagged while
    still slewing), and the same arm lagging 10 x longer than it declares is caught."""
    assert check_device(LagRateArm) == []
    liar = type("LagRateLiar", (LagRateArm,), {"name": "kit-arm-rate-liar", "tau_s": 0.05})
    assert "output-follows-command" in rules_of(check_device(liar))


def test_a_drive_record_is_marked_in_the_report():
    r = check_actuator(DriveRecordPlate)
    assert r == [] and isinstance(r, KitResult)
    assert "drive record" in r.notes["output-follows-command"]
    assert "drive record" in format_report(r)
    assert "output-follows-command" not in check_actuator(Plate).notes


def test_a_failing_close_is_seen_by_the_caller():
    """The core's close() no longer swallows the backend's error: it is kept in
    close_error, after the stop was tried; close() still never raises."""
    p = CloseFailsPlate()
    p.open()
    p.command(ChannelCommand("friction", amplitude=10.0), now=0.0)
    p.close()
    assert not p.is_open and isinstance(p.close_error, OSError)
    assert p.drive == 0.0          # stopped before the failing release
    q = Plate()
    q.open()
    q.close()
    assert q.close_error is None
    s = StopFailsPlate()
    s.open()
    s.close()
    assert isinstance(s.close_error, OSError)


# ---------------------------------------------------------------------------
# versioning: plugin-api-declared on classes, factories and modules
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("spec", [None, "==1.0", ">=2.0", "~=1.3", "1.x"])
def test_a_class_declaring_no_or_a_wrong_api_is_caught(spec):
    attrs: dict[str, Any] = {"name": "kit-plate-api"}
    if spec is not None:
        attrs["hapticsdk_api"] = spec
    else:
        attrs["hapticsdk_api"] = None
    cls = type("ApiPlate", (Plate,), attrs)
    v = check_actuator(cls)
    assert rules_of(v) == {"plugin-api-declared"}, format_report(v)


@pytest.mark.parametrize("spec", [">=1.0,<2", "~=1.1", "==1.*", ">=1.2,<2"])
def test_ranges_that_admit_this_core_pass_and_name_the_new_rules(spec):
    cls = type("ApiPlate", (Plate,), {"name": "kit-plate-api", "hapticsdk_api": spec})
    v = check_actuator(cls)
    assert v == []
    new = v.api["new_rules"]
    assert ("plugin-api-declared" in new) is (not spec.startswith(">=1.2"))
    assert ("read-back" in new) is (spec in (">=1.0,<2", "==1.*"))


def test_a_module_level_declaration_counts_and_a_wrong_one_is_caught(monkeypatch, installed):
    """A factory whose top-level package declares the range (a module, not a class)."""
    for spec, ok in ((">=1.0,<2", True), ("==1.0", False)):
        mod = types.ModuleType("kit_model_pkg")
        mod.hapticsdk_api = spec
        monkeypatch.setitem(sys.modules, "kit_model_pkg", mod)

        def factory():
            m = _GoodModel()
            m.__class__ = type("Undeclared", (_GoodModel,), {"hapticsdk_api": None})
            return m
        factory.__module__ = "kit_model_pkg"
        v = check_model(factory)
        assert ("plugin-api-declared" in rules_of(v)) is (not ok), format_report(v)


def test_rules_by_version_name_real_rules():
    from hapticsdk.plugin_api import RULES_SINCE
    every = {r for rules in RULES.values() for r in rules}
    assert set(RULES_SINCE) <= every, set(RULES_SINCE) - every


def test_a_failing_rule_new_since_the_declared_version_says_so():
    cls = type("Old", (NoReadBackPlate,), {"name": "kit-plate-old", "hapticsdk_api": ">=1.0,<2"})
    v = check_actuator(cls)
    rb = [x for x in v if x.rule == "read-back"]
    assert rb and "new in plugin API 1.1" in rb[0].message


def test_by_name_an_excluded_range_is_named_by_the_api_rule(monkeypatch):
    reg = registry("actuator")
    cls = type("Future", (Plate,), {"name": "kit-plate-future", "hapticsdk_api": ">=2.0"})
    reg.register("kit-plate-future", cls)
    try:
        v = check("actuator", "kit-plate-future")
    finally:
        reg.unregister("kit-plate-future")
    assert rules_of(v) == {"plugin-api-declared"}


# ---------------------------------------------------------------------------
# dimensions
# ---------------------------------------------------------------------------

_Loop = constraint("loop", "kit.x", lambda x: (np.array([0.2 for _ in x]), np.array([float(v) for v in x])),
                   "x >= 0.2, evaluated row by row in Python.")
_LoopList = constraint("loop-list", "kit.x", lambda x: (np.full(len(x), 0.2), np.array([v for v in x.tolist()])),
                       "x >= 0.2, row by row over a list of Python floats (the cheapest loop there is).")
_Vec = constraint("vec", "kit.x", lambda x: (np.full_like(x, 0.2), x), "x >= 0.2 (vectorised).")
_RowDependent = constraint("batchy", "kit.x", lambda x: (np.full_like(x, float(x.mean())), x),
                           "Penalty depends on the batch (its mean), so rows and batch disagree.")
_Never = never()
# x >= 0.2 with a bound taken from a log-scale table that gives NaN below x = 0.1: there
# `value < bound` is False, so the constraint reads as met with penalty 0
_NanBoundLow = constraint("nan-bound", "kit.x", lambda x: (np.where(x < 0.1, np.nan, 0.2), x),
                          "x >= 0.2, its bound NaN below 0.1.")


def _round_in_place(x):
    """x >= 0.2 on x rounded to its table's 0.01 grid in place (np.round(..., out=x)): the
    write lands in the solver's candidates."""
    np.round(x, 2, out=x)
    return np.full_like(x, 0.2), x


_WritesColumn = constraint("writes-column", "kit.x", _round_in_place, "x >= 0.2, rounding x in place.")
_WritesColumnFixed = constraint("rounds-a-copy", "kit.x", lambda x: (np.full_like(x, 0.2), np.round(x, 2)),
                                "x >= 0.2, rounding a copy of x.")
# a float path for one row that agrees with the array path, and one that does not (0.3
# where the array path says 0.2: a one-target solve would judge its answers by the wrong
# bound)
_VecOneRow = type("VecOneRow", (_Vec,), {"_bound_and_value_one": lambda self, row: (0.2, row["kit.x"])})
_WrongOneRow = type("WrongOneRow", (_Vec,), {"_bound_and_value_one": lambda self, row: (0.3, row["kit.x"])})


class _R(DimensionRenderer):
    """``make(inp)``, or ``make(inp, x)`` for a renderer that renders its feature kit.x."""

    def __init__(self, roles=("adhesion",), make=None, delay_s=0.0, x=0.5) -> None:
        self.roles = roles
        self.make = make or (lambda inp, x: [ChannelCommand("adhesion", amplitude=(20.0 + 20.0 * x)
                                                            if inp.in_contact else 0.0)])
        self.delay_s = delay_s
        self.x = x

    def tick(self, inp):
        if self.delay_s:
            import time
            time.sleep(self.delay_s)
        return self.make(inp, self.x) if self.make.__code__.co_argcount == 2 else self.make(inp)


class StickDim(PerceptionDimension):
    """A correct dimension: stickiness on an electro-adhesion plate (amplitude in V)."""
    hapticsdk_api = API
    name = "kit-stick"
    features = (Feature("kit.x", "1", 0.0, 1.0),)
    render_features = ("kit.x",)
    default_actuators: ClassVar[dict[str, str]] = {"adhesion": "kit-plate"}
    roles: ClassVar[dict[str, RoleSpec]] = {"adhesion": RoleSpec("friction", {"amplitude": "V"})}
    default_model = "kit-stick-model"
    renderer_kw: ClassVar[dict[str, Any]] = {}
    cons: ClassVar[tuple] = (_Vec,)

    def constraints(self, **context):
        return [c() for c in self.cons]

    def renderer(self, features, **options):
        x = features.get("kit.x")
        if x is None or not np.isfinite(x):
            raise ValidationError("kit.x needed", field="features.kit.x")
        return _R(**{"x": float(x), **self.renderer_kw})


class _GoodModel(PerceptionModel):
    hapticsdk_api = API

    def __init__(self, dims=("kit-stick",), feats=(("kit.x", "1"),)) -> None:
        space = FeatureSpace(tuple(Feature(n, u, 0.0, 1.0) for n, u in feats))
        super().__init__(space.names, dims, feature_space=space, name="kit-stick-model")

    def _predict(self, X):
        return np.repeat(0.5 * (1 + np.tanh(X[:, :1] - 0.5)), self.n_outputs, axis=1)


@pytest.fixture
def installed():
    """The plate, the dimension and its model registered as if installed."""
    yield from registered([(registry("actuator"), "kit-plate", Plate), (registry("dimension"), "kit-stick", StickDim),
                           (registry("model"), "kit-stick-model", _GoodModel)])


def _dim(**attrs):
    return type("Variant", (StickDim,), attrs)


def _force_role(value):
    return {"default_actuators": {"adhesion": "omni-virtual"},
            "roles": {"adhesion": RoleSpec("force", {"force_n": "N"})},
            "renderer_kw": {"make": lambda inp, x: [ChannelCommand("adhesion", force_n=value * (0.5 + x)
                                                                   if inp.in_contact else 0.0)]}}


DIMENSION_VARIANTS = [
    ({"cons": (_Loop,)}, "constraints-cost"),
    ({"cons": (_LoopList,)}, "constraints-cost"),
    ({"cons": (_RowDependent,)}, "constraints-vectorised"),
    ({"cons": (_WrongOneRow,)}, "constraints-one-row"),
    ({"cons": (_Never,)}, "constraints-feasible"),
    ({"cons": (_NanBoundLow,)}, "constraints-vectorised"),
    ({"cons": (_WritesColumn,)}, "constraints-vectorised"),
    ({"roles": {}}, "roles-declared"),
    ({"roles": {"adhesion": RoleSpec("friction", {"amplitude": "1"})}}, "roles-declared"),
    ({"roles": {"adhesion": RoleSpec("friction", {"amplitude": "mV"})}}, "roles-declared"),
    ({"default_actuators": {"adhesion": "omni-virtual"},
      "roles": {"adhesion": RoleSpec("force", {"force_n": "V"})}}, "roles-declared"),
    ({"renderer_kw": {"make": lambda inp: [ChannelCommand("adhesion", amplitude=30.0, force_n=2.0)]}},
     "renderer-commands"),                                                # declares amplitude, sends force_n too
    ({"renderer_kw": {"make": lambda inp: []}}, "renderer-commands"),     # silent in contact
    ({"renderer_kw": {"make": lambda inp: [ChannelCommand("adhesion", amplitude=float("nan"))]}}, "renderer"),
    ({"renderer_kw": {"make": lambda inp: [ChannelCommand("adhesion", amplitude=-1.0)]}}, "renderer"),
    ({"renderer_kw": {"make": lambda inp: [ChannelCommand("glue", amplitude=1.0)]}}, "renderer"),
    ({"renderer_kw": {"make": lambda inp: [ChannelCommand("adhesion",
                                                          amplitude=float(np.random.default_rng().random()))]}},
     "determinism"),
    ({"renderer_kw": {"delay_s": 0.002}}, "timing"),
    ({"renderer": lambda self, features, **o: _R()}, "renderer-bad-input"),
    ({"features": (Feature("kit.x", "", 0.0, 1.0),)}, "features"),
    ({"render_features": ("kit.y",)}, "features"),
    ({"default_actuators": {"adhesion": "no-such-actuator"}}, "class"),
    ({"default_model": "default"}, "model-match"),
    ({"hapticsdk_api": "==1.0"}, "plugin-api-declared"),
]


def test_the_correct_dimension_conforms(installed):
    assert check_dimension(StickDim) == []
    assert check_dimension(_dim(cons=(_VecOneRow,))) == []      # a float path that agrees
    assert check_dimension(_dim(cons=(_WritesColumnFixed,))) == []   # rounds a copy, not its column
    # the same unit spelled out is no clash
    assert check_dimension(_dim(roles={"adhesion": RoleSpec("friction", {"amplitude": "volt"})})) == []


@pytest.mark.parametrize("attrs, rule", DIMENSION_VARIANTS, ids=[r for _, r in DIMENSION_VARIANTS])
def test_each_broken_dimension_is_caught_by_its_rule(installed, attrs, rule):
    if rule == "model-match":
        pytest.importorskip("hapticsdk_onnx")
    # a renderer slow by design runs its own rule only: the renderer rule's sweep and long
    # run would tick it ~9000 times (18 s at 2 ms a tick)
    v = check("dimension", _dim(**attrs), rules=[rule]) if rule == "timing" else check_dimension(_dim(**attrs))
    assert rule in rules_of(v), format_report(v)


@needs_hardness
def test_500_newtons_on_a_role_not_named_force_is_caught(installed):
    """Force plausibility follows the field that carries force, whatever the role's name."""
    v = check_dimension(_dim(**_force_role(500.0)))
    assert "renderer-commands" in rules_of(v) and "500" in format_report(v)
    assert check_dimension(_dim(**_force_role(2.0))) == []


@contextlib.contextmanager
def _newton_plate():
    """A plate whose amplitude is a force of at most 0.45 N, installed as "kit-plate-n";
    yields the dimension attributes that send role "adhesion" to it in newtons."""
    Npl = type("NPlate", (Plate,), {"name": "kit-plate-n", "limits": ActuatorLimits(
        max_amplitude=0.45, amplitude_unit="N", settle_time_s=Plate.limits.settle_time_s)})
    registry("actuator").register("kit-plate-n", Npl)
    try:
        yield {"default_actuators": {"adhesion": "kit-plate-n"},
               "roles": {"adhesion": RoleSpec("friction", {"amplitude": "newton"})}}
    finally:
        registry("actuator").unregister("kit-plate-n")


def test_a_force_in_newtons_on_an_amplitude_field_is_checked_too(installed):
    """A plate whose amplitude is a force (unit "newton") gets the plausibility rule."""
    with _newton_plate() as base:
        big = _dim(**base, renderer_kw={"make": lambda inp: [ChannelCommand("adhesion", amplitude=40.0)]})
        ok = _dim(**base, renderer_kw={"make": lambda inp, x: [ChannelCommand("adhesion", amplitude=0.4 * (0.5 + x))]})
        assert "renderer-commands" in rules_of(check_dimension(big))
        assert check_dimension(ok) == []


def test_a_feature_unit_clash_with_an_installed_dimension_is_caught(installed):
    if "hardness" not in registry("dimension"):
        pytest.skip("hapticsdk-hardness not installed")
    gs = next(f for f in registry("dimension").load("hardness")().features if f.name == "GS")
    assert gs.unit == "N/mm"
    clash = _dim(features=(Feature("kit.x", "1", 0.0, 1.0), Feature("GS", "N/m", 100.0, 1000.0)))
    v = check_dimension(clash)
    assert "features" in rules_of(v) and "'GS'" in format_report(v)
    same = _dim(features=(Feature("kit.x", "1", 0.0, 1.0), Feature("GS", "newton / millimetre", 0.1, 1.0)))
    assert "features" not in rules_of(check_dimension(same))


# ---------------------------------------------------------------------------
# models against the installed dimensions
# ---------------------------------------------------------------------------

MODEL_VARIANTS = [
    (lambda: _GoodModel(dims=("stickyness",)), "model-dimensions"),
    (lambda: _GoodModel(feats=(("kit.x", "1"), ("tau_ms", "ms"))), "model-dimensions"),
    (lambda: _GoodModel(feats=(("kit.x", "N"),)), "model-dimensions"),
]
#: what each model variant's message names
MODEL_WHY = ["no installed plugin provides", "reads feature(s) ['tau_ms']", "reads kit.x in 'N'"]


def test_the_correct_model_conforms(installed):
    assert check_model(_GoodModel) == []
    assert check_model(lambda: _GoodModel(feats=(("kit.x", "dimensionless"),))) == []


@pytest.mark.parametrize("factory, rule, why", [(f, r, w) for (f, r), w in zip(MODEL_VARIANTS, MODEL_WHY)],
                         ids=["dimension-typo", "stray-feature", "unit-clash"])
def test_each_broken_model_is_caught_by_its_rule(installed, factory, rule, why):
    v = check_model(factory)
    assert rule in rules_of(v), format_report(v)
    assert why in format_report(v)


class _Model(_GoodModel):
    mode = ""

    def _predict(self, X):
        if self.mode == "random":
            return np.random.default_rng().random((X.shape[0], self.n_outputs))
        return super()._predict(X)

    def predict(self, G):
        if self.mode == "nan-ok":
            G = np.asarray(G, float)
            G = G[None, :] if G.ndim == 1 else G
            return np.full((G.shape[0], self.n_outputs), 0.5)
        return super().predict(G)


class _NoSpace(_GoodModel):
    def __init__(self) -> None:
        PerceptionModel.__init__(self, ("kit.x",), ("kit-stick",), name="kit-stick-model")


def _model_mode(mode):
    def make():
        m = _Model()
        m.mode = mode
        return m
    return make


MORE_MODEL_VARIANTS = [(_model_mode("random"), "determinism"), (_model_mode("nan-ok"), "bad-input"),
                       (_NoSpace, "metadata")]


@pytest.mark.parametrize("factory, rule", MORE_MODEL_VARIANTS, ids=[r for _, r in MORE_MODEL_VARIANTS])
def test_more_broken_models(installed, factory, rule):
    assert rule in rules_of(check_model(factory))


# ---------------------------------------------------------------------------
# solvers
# ---------------------------------------------------------------------------

class _Solver(Solver):
    hapticsdk_api = API
    name = "kit-solver"
    default_options: ClassVar[dict[str, Any]] = {}
    mode = ""

    def _solve(self, problem, *, seed=None, **kw):
        from hapticsdk.solvers import SolveResult
        if self.mode == "far":
            x = problem.space.lower.copy()
        else:
            from scipy.optimize import minimize
            lo, hi = problem.space.lower, problem.space.upper
            best = None
            for x0 in np.linspace(lo, hi, 7)[1:-1]:
                r = minimize(lambda x: float(problem.objective(x[None, :])[0]), x0, bounds=list(zip(lo, hi)),
                             method="L-BFGS-B")
                best = r if best is None or r.fun < best.fun else best
            x = best.x
        return SolveResult.from_problem(problem, x, method=self.name, message="kit", nfev=1)


def test_solver_variants_are_named():
    """solves (an answer far from an easy target), class (not a Solver), bad-input is
    the core's (a Solver subclass cannot break it without overriding solve)."""
    pytest.importorskip("scipy")
    far = type("Far", (_Solver,), {"mode": "far"})
    try:
        v = check("solver", far)
    except Exception as exc:   # the solver interface differs: nothing to conclude here
        pytest.skip(f"solver interface: {exc}")
    assert "solves" in rules_of(v) or "import" in rules_of(v)
    assert "class" in rules_of(check("solver", type("NotASolver", (), {"hapticsdk_api": API, "name": "x"})))


# ---------------------------------------------------------------------------
# hook modules
# ---------------------------------------------------------------------------

def _hooks_module(api, body):
    from hapticsdk.hookspecs import hookimpl
    mod = types.ModuleType("kit_hooks_mod")
    if api is not None:
        mod.hapticsdk_api = api
    exec(body, {"hookimpl": hookimpl, **vars(mod)}, mod.__dict__)
    sys.modules["kit_hooks_mod"] = mod
    return mod


GOOD_HOOKS = "@hookimpl\ndef hapticsdk_render_started(plan):\n    pass\n"
HOOK_VARIANTS = [
    (API, "@hookimpl\ndef hapticsdk_render_begun(plan):\n    pass\n", "hookimpls"),            # no such hook
    (API, "@hookimpl\ndef hapticsdk_render_started(plan, clock):\n    pass\n", "hookimpls"),   # extra argument
    (None, GOOD_HOOKS, "plugin-api-declared"),
    ("==1.0", GOOD_HOOKS, "plugin-api-declared"),
]


def test_a_hook_module_that_is_not_installed_is_an_import_failure():
    assert rules_of(check("hooks", "no-such-hooks")) == {"import"}


def test_installed_hook_modules_conform():
    for name in registry("hooks").names():
        assert check("hooks", name) == [], name


@pytest.mark.parametrize("api, body, rule", HOOK_VARIANTS, ids=["unknown-hook", "extra-arg", "undeclared", "==1.0"])
def test_each_broken_hook_module_is_caught(api, body, rule, monkeypatch):
    monkeypatch.delitem(sys.modules, "kit_hooks_mod", raising=False)
    mod = _hooks_module(api, body)
    try:
        v = check("hooks", mod)
    finally:
        sys.modules.pop("kit_hooks_mod", None)
    assert rules_of(v) == {rule}, format_report(v)
    sys.modules["kit_hooks_mod"] = _hooks_module(API, GOOD_HOOKS)
    try:
        assert check("hooks", sys.modules["kit_hooks_mod"]) == []
    finally:
        sys.modules.pop("kit_hooks_mod", None)


# ---------------------------------------------------------------------------
# every rule has a broken variant (here or in the older kit test files)
# ---------------------------------------------------------------------------

COVERED_ELSEWHERE = {
    # tests/testing/test_conformance_kit.py and test_conformance_kit_contracts.py
    ("actuator", "import"), ("dimension", "import"), ("model", "import"), ("solver", "import"),
    ("device", "import"), ("model", "shapes"), ("model", "vectorised"), ("model", "jacobian"),
    ("solver", "determinism"), ("solver", "options"), ("solver", "batch"), ("solver", "bad-input"),
    ("solver", "plugin-api-declared"), ("model", "plugin-api-declared"), ("device", "plugin-api-declared"),
    ("solver", "class"), ("solver", "solves"),
    # tests/testing/test_conformance_kit_results.py
    ("model", "responds"), ("solver", "template"), ("solver", "result"), ("solver", "constraints"),
    # tests/testing/test_conformance_kit_instances_state.py
    ("actuator", "instances"),
    # tests/testing/test_conformance_kit_in_use.py
    ("actuator", "servo-loop"),
    # tests/testing/test_conformance_kit_fast_law.py
    ("dimension", "renderer-fast-law"),
}


def test_every_rule_has_a_broken_variant():
    here = {("actuator", r) for _, r in ACTUATOR_VARIANTS} | {("dimension", r) for _, r in DIMENSION_VARIANTS}
    here |= {("model", r) for _, r in MODEL_VARIANTS + MORE_MODEL_VARIANTS}
    here |= {("device", r) for r in RULES["actuator"]} | {("device", "state")}
    here |= {("actuator", "plugin-api-declared")} | {("hooks", r) for _, _, r in HOOK_VARIANTS}
    here |= {("hooks", "import")}    # test_a_hook_module_that_is_not_installed_is_an_import_failure
    missing = [(k, r) for k, rules in RULES.items() for r in rules
               if (k, r) not in here and (k, r) not in COVERED_ELSEWHERE]
    assert not missing, missing


@pytest.mark.parametrize("times, caught", [(9.0, False), (11.0, True)])
def test_force_plausibility_is_caught_just_above_its_factor_and_not_below(installed, times, caught):
    """The rule's edge: a force up to FORCE_PLAUSIBILITY_FACTOR (10) x the actuator's
    declared limit within 3 mm is a stiff material (the safety layer clamps it); above is
    a unit or formula error. 9 x passes this rule and 11 x is caught, so the factor is
    the documented decade, not any multiple."""
    from hapticsdk.testing.conformance import FORCE_PLAUSIBILITY_FACTOR
    assert 9.0 < FORCE_PLAUSIBILITY_FACTOR < 11.0
    with _newton_plate() as base:
        peak = times * 0.45
        d = _dim(**base, renderer_kw={"make": lambda inp, x: [ChannelCommand("adhesion", amplitude=peak * (0.5 + x))]})   # peak at the middle feature (x = 0.5), where the rule samples
        assert ("renderer-commands" in rules_of(check_dimension(d))) is caught

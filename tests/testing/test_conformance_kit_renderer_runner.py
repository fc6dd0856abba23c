"""Kit rules on what a renderer does with its input and its features, and the kit's runner.

* ``renderer``: a renderer that changes its ``TickInput`` (writes into its arrays, rebinds
  a field) fails: the servo loop hands one ``TickInput`` to every renderer of a material;
  a renderer that vibrates a vibration role out of contact fails (a thermal role may hold
  its set-point).
* ``renderer-commands``: a renderer whose commands do not change when a render feature
  goes over its declared range fails.
* the runner: a rule that does not finish within its time limit, and a ``BaseException``
  that is not an ``Exception`` raised by plugin code, are violations of the rule that ran
  it; the kit returns a report.

Each broken variant is caught by its rule; the correct variants conform."""

from __future__ import annotations

import threading
import time
from typing import Any, Callable, ClassVar

import numpy as np
import pytest

from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer, PerceptionDimension, RoleSpec
from hapticsdk.errors import ValidationError
from hapticsdk.perception.features import Feature, FeatureSpace
from hapticsdk.perception.models import PerceptionModel
from hapticsdk.plugins import registry
from hapticsdk.testing import check, check_actuator, check_dimension
from hapticsdk.testing.conformance import RULE_TIME_FACTOR, format_report
from kit_variants import API, registered, rules_of
from kit_variants import LAG_COIL_MAX_V as MAX_V
from kit_variants import LagCoil as Coil



def _correct(inp, a: float, b: float) -> list[ChannelCommand]:
    """Amplitude from a, frequency from b and the sliding speed; silent out of contact."""
    if not inp.in_contact:
        return [ChannelCommand("buzz", frequency_hz=100.0, amplitude=0.0)]
    speed = abs(float(inp.velocity_mm_s[0]))
    return [ChannelCommand("buzz", frequency_hz=min(300.0, 30.0 + 100.0 * b + 0.2 * speed),
                           amplitude=0.1 + 1.5 * a)]


class _R(DimensionRenderer):
    roles = ("buzz",)

    def __init__(self, a: float, b: float, make: Callable) -> None:
        self.a, self.b, self.make = a, b, make

    def tick(self, inp):
        return self.make(inp, self.a, self.b)


class RDim(PerceptionDimension):
    """A correct dimension: two render features on a voice coil."""
    hapticsdk_api = API
    name = "kit-rr"
    features = (Feature("kit-rr.a", "1", 0.0, 1.0), Feature("kit-rr.b", "1", 0.0, 1.0))
    render_features = ("kit-rr.a", "kit-rr.b")
    default_actuators: ClassVar[dict[str, str]] = {"buzz": "kit-lag-coil"}
    roles: ClassVar[dict[str, RoleSpec]] = {"buzz": RoleSpec("vibration", {"frequency_hz": "Hz", "amplitude": "V"})}
    default_model = "kit-rr-model"
    make: ClassVar[Callable] = staticmethod(_correct)

    def constraints(self, **context):
        return []

    def renderer(self, features, **options):
        vals = []
        for n in ("kit-rr.a", "kit-rr.b"):
            v = features.get(n)
            if v is None or not np.isfinite(v):
                raise ValidationError(f"{n} needed", field=f"features.{n}")
            vals.append(float(v))
        return _R(*vals, make=type(self).make)


class RModel(PerceptionModel):
    hapticsdk_api = API

    def __init__(self) -> None:
        space = FeatureSpace(RDim.features)
        super().__init__(space.names, ("kit-rr",), feature_space=space, name="kit-rr-model")

    def _predict(self, X):
        return 0.5 * (1 + np.tanh(X[:, :1] + X[:, 1:2] - 1))


@pytest.fixture
def installed():
    yield from registered([(registry("actuator"), "kit-lag-coil", Coil), (registry("dimension"), "kit-rr", RDim),
                           (registry("model"), "kit-rr-model", RModel)])


def _dim(make: Callable, **attrs: Any) -> type[RDim]:
    return type("Variant", (RDim,), {"make": staticmethod(make), **attrs})


def test_the_correct_dimension_conforms(installed):
    assert check_dimension(RDim) == []


# ---------------------------------------------------------------------------
# a renderer must not change its input
# ---------------------------------------------------------------------------

def _in_place_scale(inp, a, b):
    inp.velocity_mm_s *= 0.001                     # "to m/s", in place
    return _correct(inp, a, b)


def _item_write(inp, a, b):
    inp.velocity_mm_s[0] = abs(inp.velocity_mm_s[0])
    return _correct(inp, a, b)


def _clip_out(inp, a, b):
    np.clip(inp.velocity_mm_s, -100.0, 100.0, out=inp.velocity_mm_s)
    return _correct(inp, a, b)


def _rebind_array(inp, a, b):
    inp.velocity_mm_s = inp.velocity_mm_s * 0.001  # a new array in the shared input
    return _correct(inp, a, b)


def _rebind_penetration(inp, a, b):
    inp.penetration_mm = max(inp.penetration_mm, 0.0)
    return _correct(inp, a, b)


def _rebind_contact(inp, a, b):
    out = _correct(inp, a, b)
    inp.in_contact = True                          # after computing its own commands
    return out


MUTATIONS = [_in_place_scale, _item_write, _clip_out, _rebind_array, _rebind_penetration, _rebind_contact]


@pytest.mark.parametrize("make", MUTATIONS, ids=[m.__name__ for m in MUTATIONS])
def test_a_renderer_that_changes_its_input_is_caught(installed, make):
    v = check_dimension(_dim(make))
    assert "renderer" in rules_of(v), format_report(v)
    assert "TickInput" in format_report(v)


def test_a_renderer_that_computes_on_copies_conforms(installed):
    def copies(inp, a, b):
        v = inp.velocity_mm_s * 0.001               # a new array
        w = np.array(inp.velocity_mm_s)             # a writable copy
        w[0] = abs(w[0])
        assert v.shape == w.shape == (3,)
        return _correct(inp, a, b)
    assert check_dimension(_dim(copies)) == []


# ---------------------------------------------------------------------------
# a renderer must render its features
# ---------------------------------------------------------------------------

def test_a_renderer_ignoring_its_features_is_caught(installed):
    def constant(inp, a, b):
        return _correct(inp, 0.5, 0.5)
    v = check_dimension(_dim(constant))
    assert "renderer-commands" in rules_of(v), format_report(v)
    assert "'kit-rr.a'" in format_report(v)


def test_a_renderer_ignoring_one_feature_is_caught_naming_it(installed):
    def no_b(inp, a, b):
        return _correct(inp, a, 0.5)
    v = check_dimension(_dim(no_b))
    assert "renderer-commands" in rules_of(v) and "'kit-rr.b'" in format_report(v), format_report(v)
    assert "'kit-rr.a'" not in format_report(v)


def test_without_render_features_a_renderer_ignoring_all_features_is_caught(installed):
    def constant(inp, a, b):
        return _correct(inp, 0.5, 0.5)
    v = check_dimension(_dim(constant, render_features=()))
    assert "renderer-commands" in rules_of(v), format_report(v)
    # one that renders some of them conforms (no render_features: the kit cannot tell which)
    assert check_dimension(_dim(lambda inp, a, b: _correct(inp, a, 0.5), render_features=())) == []


def test_a_feature_acting_only_where_another_lets_it_conforms(installed):
    """b changes the frequency only when a is at its upper end; a saturates above its
    middle: neither is ignored."""
    def gated(inp, a, b):
        return _correct(inp, min(a, 0.5), b if a >= 1.0 else 0.0)
    assert check_dimension(_dim(gated)) == []


_LAWS = [(float(ka), float(kb), ig) for (ka, kb), ig in
         zip(np.random.default_rng(20261126).uniform(0.05, 1.0, (9, 2)), ["none", "a", "b"] * 3)]


@pytest.mark.parametrize("ka, kb, ignored", _LAWS)
def test_feature_dependence_is_judged_whatever_the_law(installed, ka, kb, ignored):
    """A renderer linear in each render feature conforms whatever its (nonzero) slopes,
    drawn at random; the same law with one slope 0 fails, naming that feature."""
    ka0 = 0.0 if ignored == "a" else ka
    kb0 = 0.0 if ignored == "b" else kb

    def law(inp, a, b):
        if not inp.in_contact:
            return [ChannelCommand("buzz", frequency_hz=100.0, amplitude=0.0)]
        return [ChannelCommand("buzz", frequency_hz=100.0 + 150.0 * kb0 * b, amplitude=0.1 + ka0 * a)]
    v = check_dimension(_dim(law))
    if ignored == "none":
        assert v == [], format_report(v)
    else:
        assert rules_of(v) == {"renderer-commands"} and f"'kit-rr.{ignored}'" in format_report(v), format_report(v)


# ---------------------------------------------------------------------------
# no vibration out of contact
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("amp", [MAX_V, 0.01 * MAX_V])
def test_a_vibration_role_driven_out_of_contact_is_caught(installed, amp):
    def buzz(inp, a, b):
        out = _correct(inp, a, b)
        return out if inp.in_contact else [ChannelCommand("buzz", frequency_hz=100.0, amplitude=amp)]
    v = check_dimension(_dim(buzz))
    assert "renderer" in rules_of(v) and "out of contact" in format_report(v), format_report(v)


def test_ringing_on_after_the_contact_ends_is_caught(installed):
    """Silent before the first touch, vibrating after leaving the surface."""
    class Ring(_R):
        touched = False

        def tick(self, inp):
            self.touched = self.touched or inp.in_contact
            if self.touched and not inp.in_contact:
                return [ChannelCommand("buzz", frequency_hz=100.0, amplitude=0.5)]
            return _correct(inp, self.a, self.b)

    class RingDim(RDim):
        def renderer(self, features, **options):
            r = super().renderer(features, **options)
            return Ring(r.a, r.b, r.make)
    v = check_dimension(RingDim)
    assert "renderer" in rules_of(v) and "out of contact" in format_report(v), format_report(v)


def test_a_thermal_role_may_hold_its_set_point_out_of_contact(installed):
    if "peltier-virtual" not in registry("actuator"):
        pytest.skip("hapticsdk-warmth (examples/hapticsdk-warmth) not installed")

    def hold(inp, a, b):
        return _correct(inp, a, b) + [ChannelCommand("heat", amplitude=30.0 + 5.0 * a)]
    HDim = _dim(hold, default_actuators={"buzz": "kit-lag-coil", "heat": "peltier-virtual"},
                roles={**RDim.roles, "heat": RoleSpec("thermal", {"amplitude": "degC"})})

    class HR(_R):
        roles = ("buzz", "heat")

    class HoldDim(HDim):
        def renderer(self, features, **options):
            r = super().renderer(features, **options)
            return HR(r.a, r.b, r.make)
    v = check_dimension(HoldDim)
    assert v == [], format_report(v)


# ---------------------------------------------------------------------------
# the runner: time limit, BaseException
# ---------------------------------------------------------------------------

class BlocksAfter(Coil):
    """command() never returns after its 20th write (a lost acknowledgement)."""
    name: ClassVar[str] = "kit-rr-blocks"
    release = threading.Event()

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        self.k = 0

    def _command(self, cmd: ChannelCommand) -> None:
        self.k += 1
        if self.k > 20:
            self.release.wait()
        super()._command(cmd)


def test_a_call_that_never_returns_is_a_violation_of_its_rule():
    limit = 0.5
    t0 = time.monotonic()
    try:
        v = check("actuator", BlocksAfter, rule_time_limit_s=limit)
        took = time.monotonic() - t0
        stuck = [x for x in v if "did not finish" in x.message]
        assert len(stuck) == 1, format_report(v)
        assert "_command" in stuck[0].message       # where it is stuck
        # the limit: the base plus RULE_TIME_FACTOR x what it simulated before blocking
        # (20 kit ticks at most); the kit stops there, the other rules take little time
        assert took < limit + RULE_TIME_FACTOR * 0.05 + 10.0
        assert "not-run" in v.notes          # the rules after it are named, not run
        left = [t for t in threading.enumerate() if t.name.startswith("hapticsdk-kit") and t.is_alive()]
        assert left and all(t.daemon for t in left)   # a stuck daemon thread is left, as documented
    finally:
        BlocksAfter.release.set()                # let the stuck thread end


def test_a_renderer_tick_that_never_returns_is_a_violation_of_its_rule(installed):
    gate = threading.Event()

    def hang(inp, a, b):
        if inp.in_contact:
            gate.wait()
        return _correct(inp, a, b)
    try:
        v = check("dimension", _dim(hang), rule_time_limit_s=0.3)
        stuck = [x for x in v if "did not finish" in x.message]
        assert [x.rule for x in stuck] == ["renderer"], format_report(v)
    finally:
        gate.set()


def test_a_rule_that_keeps_simulating_is_not_cut_short():
    """A slow but progressing actuator (0.3 ms per command: slower than the timing rule
    allows, within RULE_TIME_FACTOR of real time) runs every rule to its end even with a
    base limit shorter than the run: the allowance grows with the simulated time."""
    class Slow(Coil):
        name: ClassVar[str] = "kit-rr-slow"

        def _command(self, cmd: ChannelCommand) -> None:
            time.sleep(0.0003)
            super()._command(cmd)
    v = check("actuator", Slow, rule_time_limit_s=0.2)
    assert not [x for x in v if "did not finish" in x.message], format_report(v)
    assert "timing" in rules_of(v)       # it is slow: the timing rule, not the runner, says so


class _Abort(BaseException):
    """A driver's own 'abort', derived from BaseException."""


class StopAborts(Coil):
    name: ClassVar[str] = "kit-rr-abort"

    def _stop(self) -> None:
        self.drive_a = 0.0
        if self.is_open:
            raise _Abort("driver aborted")


def test_a_base_exception_from_plugin_code_is_a_violation_of_the_rule_that_ran_it():
    from hapticsdk.devices.actuators import _OPEN_ACTUATORS
    try:
        v = check_actuator(StopAborts)
    finally:   # the abort left instances open: keep them from the exit-time stop_all
        for a in [a for a in list(_OPEN_ACTUATORS) if isinstance(a, StopAborts)]:
            _OPEN_ACTUATORS.discard(a)
    assert "safe-stop" in rules_of(v) and "_Abort" in format_report(v), format_report(v)
    assert "BaseException" in format_report(v)


def test_a_base_exception_from_a_factory_is_an_import_failure():
    def factory():
        raise _Abort("cannot build")
    v = check("actuator", factory)
    assert rules_of(v) == {"import"} and "_Abort" in format_report(v)


@pytest.mark.parametrize("exc", [KeyboardInterrupt, SystemExit])
def test_keyboard_interrupt_and_system_exit_still_propagate(installed, exc):
    def interrupt(inp, a, b):
        raise exc()
    with pytest.raises(exc):
        check("dimension", _dim(interrupt), rules=["renderer"])


@pytest.mark.parametrize("bad", [0, -1.0, float("nan"), float("inf"), "5"])
def test_a_bad_rule_time_limit_is_refused(bad):
    with pytest.raises(ValidationError):
        check("actuator", Coil, rule_time_limit_s=bad)

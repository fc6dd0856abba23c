"""Safety layer: every declared limit clamps and counts, stale commands become zero,
force ramps are bounded per tick at start and after faults, the start gate holds."""

from __future__ import annotations

import numpy as np
import pytest

from hapticsdk.devices.actuators import Actuator, ActuatorLimits, DeviceState
from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.errors import DeviceError, ValidationError
from hapticsdk.devices.safety import SafetyLayer, SafetySettings

PERIOD = 0.001
LIMITS = ActuatorLimits(max_force_n=3.3, max_stiffness_n_per_mm=2.3, frequency_range_hz=(30.0, 120.0),
                        max_amplitude=25.0, amplitude_unit="V", max_velocity_mm_s=400.0,
                        max_force_rate_n_per_tick=0.5)


class RecordingActuator(Actuator):
    name = "test-recording"
    channel = "force"
    limits = LIMITS
    simulated = True

    def __init__(self, fail_after: int | None = None, **kw):
        super().__init__(**kw)
        self.sent: list[ChannelCommand] = []
        self.fail_after = fail_after

    def _command(self, cmd):
        if self.fail_after is not None and len(self.sent) >= self.fail_after:
            raise OSError("simulated transport failure")
        self.sent.append(cmd)

    def _stop(self):
        pass


def state(pen_mm=0.0, speed=0.0):
    return DeviceState(t=0.0, position_mm=np.array([0.0, -pen_mm, 0.0]),
                       velocity_mm_s=np.array([speed, 0.0, 0.0]))


def running_layer(limits=LIMITS, **kw):
    """A layer past its start (no ramp, gate released) so limits can be tested alone."""
    layer = SafetyLayer(limits, ramp_time_s=0.0, **kw)
    layer.reset(0.0)
    layer.observe(state(0.0))
    layer.filter(ChannelCommand("f", force_n=0.0), 0.0)
    assert layer.phase == "running"
    return layer


# -- declared limits -------------------------------------------------------------
def test_force_above_max_is_clamped_and_counted():
    lay = running_layer(ActuatorLimits(max_force_n=3.3))
    out = lay.filter(ChannelCommand("f", force_n=10.0), 0.001)
    assert out.force_n == pytest.approx(3.3)
    out = lay.filter(ChannelCommand("f", force_n=-10.0), 0.002)
    assert out.force_n == pytest.approx(-3.3)
    assert lay.hits["max_force_n"] == 2
    assert lay.report()["limit_hits"]["max_force_n"] == 2
    # below the limit: untouched, not counted
    assert lay.filter(ChannelCommand("f", force_n=1.0), 0.003).force_n == pytest.approx(1.0)
    assert lay.hits["max_force_n"] == 2


def test_stiffness_limit_caps_force_per_penetration():
    lay = running_layer(ActuatorLimits(max_stiffness_n_per_mm=2.3))
    lay.observe(state(pen_mm=1.0))
    out = lay.filter(ChannelCommand("f", force_n=5.0), 0.001)  # 5 N/mm at 1 mm
    cap = 2.3 * 1.0 + lay.settings.stiffness_offset_n
    assert out.force_n == pytest.approx(cap)
    assert lay.hits["max_stiffness_n_per_mm"] == 1
    # a spring at the limit passes untouched
    lay.observe(state(pen_mm=2.0))
    assert lay.filter(ChannelCommand("f", force_n=4.6), 0.002).force_n == pytest.approx(4.6)
    assert lay.hits["max_stiffness_n_per_mm"] == 1


def test_force_limit_shrinks_with_speed_and_overspeed_is_a_fault():
    lim = ActuatorLimits(max_force_n=3.0, max_velocity_mm_s=400.0)
    lay = running_layer(lim, start_max_force_n=None)
    lay.observe(state(speed=100.0))  # below the knee (200 mm/s): full limit
    assert lay.filter(ChannelCommand("f", force_n=3.0), 0.001).force_n == pytest.approx(3.0)
    lay.observe(state(speed=300.0))  # halfway from knee to max: half the force
    assert lay.filter(ChannelCommand("f", force_n=3.0), 0.002).force_n == pytest.approx(1.5)
    assert lay.hits["max_velocity_mm_s"] == 1
    lay.observe(state(speed=500.0))  # above the max: zero and a fault
    assert lay.filter(ChannelCommand("f", force_n=1.0), 0.003).force_n == 0.0
    assert lay.events["faults"] == 1 and lay.hits["max_velocity_mm_s"] == 2
    # slow again: output comes back through the ramp, not as a step
    lay.configure(ramp_time_s=0.01)
    lay.observe(state(speed=0.0))
    outs = [lay.filter(ChannelCommand("f", force_n=2.0), 0.004 + i * PERIOD).force_n for i in range(15)]
    assert outs[0] == 0.0 and outs[-1] == pytest.approx(2.0)
    assert np.max(np.diff(outs)) <= 2.0 * PERIOD / 0.01 + 1e-9


def test_frequency_and_amplitude_clamped_and_counted():
    lay = running_layer(LIMITS)
    out = lay.filter(ChannelCommand("v", frequency_hz=200.0, amplitude=40.0), 0.001)
    assert out.frequency_hz == 120.0 and out.amplitude == 25.0
    out = lay.filter(ChannelCommand("v", frequency_hz=10.0, amplitude=-1.0), 0.002)
    assert out.frequency_hz == 30.0 and out.amplitude == 0.0
    assert lay.hits["frequency_range_hz"] == 2
    assert lay.hits["max_amplitude"] == 1 and lay.hits["negative_amplitude"] == 1
    out = lay.filter(ChannelCommand("v", frequency_hz=60.0, amplitude=10.0), 0.003)
    assert (out.frequency_hz, out.amplitude) == (60.0, 10.0)


def test_force_rate_per_tick_limited_and_counted():
    lay = running_layer(ActuatorLimits(max_force_n=3.3, max_force_rate_n_per_tick=0.5))
    outs = [lay.filter(ChannelCommand("f", force_n=3.0), (i + 1) * PERIOD).force_n for i in range(8)]
    assert outs[:6] == pytest.approx([0.5, 1.0, 1.5, 2.0, 2.5, 3.0])
    assert lay.hits["max_force_rate_n_per_tick"] == 5


def test_every_limit_hit_goes_through_actuator_command():
    act = RecordingActuator(safety=SafetyLayer(LIMITS, ramp_time_s=0.0))
    with act:
        act.safety.observe(state())
        sent = act.command(ChannelCommand("f", force_n=9.0), now=0.0)
        assert sent.force_n == pytest.approx(0.5)  # rate limit from 0
        assert act.sent[-1] is sent and act.last_command is sent
        # 9 N > 3.3 N max force; at zero penetration the stiffness cap is the 1 N offset;
        # then at most 0.5 N change from zero in one tick
        assert act.describe()["safety"]["limit_hits"] == {
            "max_force_n": 1, "max_stiffness_n_per_mm": 1, "max_force_rate_n_per_tick": 1}


# -- stale commands ---------------------------------------------------------------
def test_stale_command_becomes_zero_and_is_never_resent():
    lay = running_layer(ActuatorLimits(max_force_n=3.3))
    lay.set_period(PERIOD)
    cmd = lay.filter(ChannelCommand("f", force_n=2.0, frequency_hz=80.0), 0.010)
    assert lay.current(0.010) is cmd
    assert lay.current(0.0105).force_n == 2.0
    assert lay.current(0.011).force_n == 2.0  # exactly one period old: still valid
    late = lay.current(0.0111)
    assert late.force_n == 0.0 and late.role == "f" and late.frequency_hz == 80.0
    assert all(lay.current(0.0111 + k * 1e-4).force_n == 0.0 for k in range(20))
    assert lay.events["stale_zeroed"] == 1
    # a fresh command is served again
    lay.filter(ChannelCommand("f", force_n=1.0), 0.012)
    assert lay.current(0.0125).force_n == 1.0


def test_stale_age_follows_the_servo_period():
    lay = running_layer(ActuatorLimits())
    lay.set_period(0.004)  # 250 Hz loop
    lay.filter(ChannelCommand("f", force_n=1.0), 1.0)
    assert lay.current(1.0035).force_n == 1.0
    assert lay.current(1.0045).force_n == 0.0


def test_long_gap_between_commands_restarts_with_a_ramp():
    lay = SafetyLayer(ActuatorLimits(max_force_n=3.3), ramp_time_s=0.05, start_max_force_n=None)
    lay.reset(0.0)
    t = np.arange(0, 0.1, PERIOD)
    for ti in t:
        lay.filter(ChannelCommand("f", force_n=2.0), ti)
    assert lay.phase == "running"
    out = lay.filter(ChannelCommand("f", force_n=2.0), 1.0)  # loop stalled for 0.9 s
    assert out.force_n == 0.0 and lay.events["faults"] == 1 and lay.phase == "ramping"


# -- ramps and start gate ----------------------------------------------------------
def ramp_outputs(lay, force, t0, n):
    return np.array([lay.filter(ChannelCommand("f", force_n=force), t0 + i * PERIOD).force_n
                     for i in range(n)])


@pytest.mark.parametrize("ramp_time", [0.05, 0.2])
def test_startup_ramp_bounded_per_tick(ramp_time):
    act = RecordingActuator(safety=SafetyLayer(ActuatorLimits(max_force_n=3.3), ramp_time_s=ramp_time))
    with act:
        act.safety.observe(state(0.0))
        outs = np.array([act.command(ChannelCommand("f", force_n=1.0), now=i * PERIOD).force_n
                         for i in range(int(ramp_time / PERIOD) + 20)])
    bound = 1.0 * PERIOD / ramp_time + 1e-9
    assert outs[0] == 0.0
    assert np.max(np.abs(np.diff(outs))) <= bound
    assert outs[-1] == pytest.approx(1.0)
    # reaches full force after ramp_time, not much later
    assert np.argmax(outs >= 1.0 - 1e-12) <= int(round(ramp_time / PERIOD)) + 1


def test_ramp_after_backend_fault_and_reopen():
    act = RecordingActuator(fail_after=300, safety=SafetyLayer(ActuatorLimits(max_force_n=3.3), ramp_time_s=0.1,
                                                            start_max_force_n=None))
    act.open()
    act.safety.observe(state())
    with pytest.raises(DeviceError):
        for i in range(400):
            act.command(ChannelCommand("f", force_n=2.0), now=i * PERIOD)
    assert act.sent[-1].force_n == pytest.approx(2.0)  # it was at full force
    assert act.safety.current(0.3) is None  # nothing to re-send after the fault
    act.close()
    act.fail_after = None
    act.open()
    act.safety.observe(state())
    outs = np.array([act.command(ChannelCommand("f", force_n=2.0), now=0.4 + i * PERIOD).force_n
                     for i in range(150)])
    assert outs[0] == 0.0
    assert np.max(np.abs(np.diff(outs))) <= 2.0 * PERIOD / 0.1 + 1e-9
    assert outs[-1] == pytest.approx(2.0)
    act.close()


def test_explicit_fault_ramps_again():
    lay = running_layer(ActuatorLimits(max_force_n=3.3), start_max_force_n=None)
    lay.configure(ramp_time_s=0.02)
    assert lay.filter(ChannelCommand("f", force_n=3.0), 0.001).force_n == 3.0
    lay.fault("force error flag")
    outs = ramp_outputs(lay, 3.0, 0.002, 40)
    assert outs[0] == 0.0 and outs[-1] == 3.0
    assert np.max(np.abs(np.diff(outs))) <= 3.0 * PERIOD / 0.02 + 1e-9
    assert lay.report()["events"]["faults"] == 1 and lay.report()["last_fault"] == "force error flag"


def test_start_waits_until_hand_is_not_pushing():
    lay = SafetyLayer(ActuatorLimits(max_force_n=3.3), ramp_time_s=0.01)
    lay.reset(123.0)
    lay.observe(state(pen_mm=3.0))  # user already pressing 3 mm deep at start
    held = ramp_outputs(lay, 2.0, 0.0, 50)
    assert np.all(held == 0.0) and lay.phase == "waiting"
    assert lay.events["start_hold_ticks"] == 50
    lay.observe(state(pen_mm=0.5))  # backed off
    outs = ramp_outputs(lay, 0.8, 0.05, 30)
    assert outs[0] == 0.0 and outs[-1] == pytest.approx(0.8)
    assert np.max(np.diff(outs)) <= 0.8 * PERIOD / 0.01 + 1e-9


def test_start_gate_on_commanded_force():
    lay = SafetyLayer(ActuatorLimits(max_force_n=3.3), ramp_time_s=0.0, start_max_force_n=1.0)
    lay.reset(0.0)
    assert lay.filter(ChannelCommand("f", force_n=2.5), 0.0).force_n == 0.0
    assert lay.filter(ChannelCommand("f", force_n=0.5), 0.001).force_n == 0.5
    assert lay.filter(ChannelCommand("f", force_n=2.5), 0.002).force_n == 2.5


def test_amplitude_ramp_optional():
    lay = SafetyLayer(LIMITS, ramp_time_s=0.01, ramp_amplitude=True)
    lay.reset(0.0)
    amps = [lay.filter(ChannelCommand("v", frequency_hz=60.0, amplitude=20.0), i * PERIOD).amplitude
            for i in range(15)]
    assert amps[0] == 0.0 and amps[-1] == 20.0 and np.max(np.diff(amps)) <= 2.0 + 1e-9
    lay2 = SafetyLayer(LIMITS, ramp_time_s=0.01)
    lay2.reset(0.0)
    assert lay2.filter(ChannelCommand("v", frequency_hz=60.0, amplitude=20.0), 0.0).amplitude == 20.0


def test_settings_validated_and_reported():
    with pytest.raises(ValidationError):
        SafetySettings(ramp_time_s=-1)
    with pytest.raises(ValidationError):
        SafetyLayer(LIMITS, stale_after_s=0)
    with pytest.raises(ValidationError):
        SafetyLayer(LIMITS, no_such_setting=1)
    rep = SafetyLayer(LIMITS).report()
    assert rep["settings"]["ramp_time_s"] == 0.2 and rep["settings"]["stale_after_s"] == 0.001


@pytest.mark.parametrize("value", ["False", "", None, 0, 1, 1.0, [True]])
def test_the_amplitude_ramp_switch_takes_only_a_bool(value):
    """``ramp_amplitude`` switches a safeguard: a truthy string, a 0 or a None a caller
    meant as something else is refused by name, not read by its truth value."""
    with pytest.raises(ValidationError) as ei:
        SafetySettings(ramp_amplitude=value)
    assert ei.value.field == "safety.ramp_amplitude"
    with pytest.raises(ValidationError):
        SafetyLayer(LIMITS, ramp_amplitude=value)
    assert SafetySettings(ramp_amplitude=np.bool_(True)).ramp_amplitude


def test_default_actuator_has_the_safety_layer_on():
    act = RecordingActuator()
    assert isinstance(act.safety, SafetyLayer)
    with act:
        act.safety.observe(state())
        first = act.command(ChannelCommand("f", force_n=3.0), now=0.0)
    assert first.force_n == 0.0  # ramp starts at zero by default


def test_a_clock_that_goes_back_during_the_start_ramp_restarts_it_from_there():
    """The start ramp reads the time it began; a ``now`` before it (a clock stepped back)
    restarts the ramp at that ``now``, so the ramp still takes its whole time from there
    and never jumps ahead (nor stays at 0 until the old start comes round again)."""
    lay = SafetyLayer(ActuatorLimits(max_force_n=3.3), ramp_time_s=0.1, start_max_force_n=None)
    lay.reset(0.0)
    assert lay.filter(ChannelCommand("f", force_n=2.0), 10.0).force_n == 0.0    # the ramp starts at 10 s
    assert lay.filter(ChannelCommand("f", force_n=2.0), 10.05).force_n == pytest.approx(1.0)
    assert lay.filter(ChannelCommand("f", force_n=2.0), 5.0).force_n == 0.0     # back to 5 s: restarted there
    assert lay.phase == "ramping"
    assert lay.filter(ChannelCommand("f", force_n=2.0), 5.05).force_n == pytest.approx(1.0)
    assert lay.filter(ChannelCommand("f", force_n=2.0), 5.1).force_n == pytest.approx(2.0)
    assert lay.phase == "running"


@pytest.mark.parametrize("field", ["max_force_n", "max_stiffness_n_per_mm", "max_amplitude",
                                   "max_force_rate_n_per_tick"])
def test_a_small_declared_limit_is_taken_and_a_negative_one_named(field):
    """Each ``max_*`` limit may be any finite number >= 0: a small one (a 0.5 N coil) is
    taken as declared, 0 is taken, below 0 is named."""
    from hapticsdk.devices.safety import declared_limits
    assert declared_limits(ActuatorLimits(**{field: 0.5}))[field] == 0.5
    assert declared_limits(ActuatorLimits(**{field: 0.0}))[field] == 0.0
    with pytest.raises(ValidationError) as ei:
        declared_limits(ActuatorLimits(**{field: -0.1}))
    assert ei.value.field == f"limits.{field}"


def test_a_start_gate_at_zero_is_taken_and_holds_while_there_is_any_depth_or_force():
    """The start gate's thresholds are None or any number >= 0 (``SafetySettings``); 0 is
    the strictest gate: force is held at zero while the probe is deeper than 0 mm or the
    command exceeds 0 N (docs/safety.md, start gate), and released at the surface with a
    zero command."""
    s = SafetySettings(start_max_penetration_mm=0.0, start_max_force_n=0.0, ramp_time_s=0.0)
    assert (s.start_max_penetration_mm, s.start_max_force_n) == (0.0, 0.0)
    lay = SafetyLayer(LIMITS, settings=s)
    lay.reset(0.0)
    lay.observe(state(pen_mm=0.1))
    assert lay.filter(ChannelCommand("f", force_n=0.0), 0.0).force_n == 0.0
    assert lay.phase == "waiting"                       # any depth holds it
    lay.observe(state(pen_mm=0.0))
    assert lay.filter(ChannelCommand("f", force_n=0.2), 0.001).force_n == 0.0
    assert lay.phase == "waiting"                       # any force holds it
    assert lay.events["start_hold_ticks"] == 2
    lay.filter(ChannelCommand("f", force_n=0.0), 0.002)
    assert lay.phase == "running"                       # at the surface, nothing commanded
    assert lay.filter(ChannelCommand("f", force_n=0.2), 0.003).force_n == pytest.approx(0.2)


def test_a_command_exactly_at_a_limit_passes_untouched_and_is_not_counted():
    """A limit is counted when it bites, once per command it changes (``hits``: "limit name
    -> number of commands it clamped"): a force exactly at the force limit or at the
    stiffness cap ``k_max x penetration + offset``, an amplitude exactly at either end of
    its range, a frequency at a band edge and a force change exactly the rate limit pass
    as they are and count nothing (the values are exact in binary, so equal means equal)."""
    lim = ActuatorLimits(max_force_n=6.0, max_stiffness_n_per_mm=2.0, frequency_range_hz=(30.0, 120.0),
                         max_amplitude=25.0, min_amplitude=0.5, max_force_rate_n_per_tick=4.0)
    lay = running_layer(lim, stiffness_offset_n=1.0)
    lay.observe(state(pen_mm=1.5))                      # cap 2.0 x 1.5 + 1.0 = 4.0 N
    assert lay.filter(ChannelCommand("f", force_n=4.0), 0.001).force_n == 4.0     # a 4 N step: the rate limit
    assert lay.filter(ChannelCommand("f", force_n=-4.0), 0.002).force_n == 0.0    # -8 N step: clamped to 4
    assert lay.hits == {"max_force_rate_n_per_tick": 1}
    lay.observe(state(pen_mm=2.5))                      # cap 6.0 N, the force limit too
    assert lay.filter(ChannelCommand("f", force_n=-4.0), 0.003).force_n == -4.0
    assert lay.filter(ChannelCommand("f", force_n=0.0), 0.004).force_n == 0.0
    assert lay.filter(ChannelCommand("f", force_n=4.0), 0.005).force_n == 4.0
    assert lay.filter(ChannelCommand("f", force_n=6.0), 0.006).force_n == 6.0
    for amp, freq in ((0.5, 30.0), (25.0, 120.0)):
        out = lay.filter(ChannelCommand("v", frequency_hz=freq, amplitude=amp), 0.007)
        assert (out.frequency_hz, out.amplitude) == (freq, amp)
    assert lay.hits == {"max_force_rate_n_per_tick": 1}


def test_at_exactly_the_declared_speed_the_force_limit_is_zero_and_counted_but_no_fault():
    """The force limit shrinks linearly from the knee and reaches 0 at ``max_velocity_mm_s``
    (docs/safety.md); a fault is only *above* it. At exactly that speed a command is
    clamped to 0 N by the shrinking limit, which counts as that limit's hit for the
    command, and the layer keeps running (no fault, no gate)."""
    lay = running_layer(ActuatorLimits(max_force_n=3.0, max_velocity_mm_s=400.0), start_max_force_n=None)
    lay.observe(state(speed=400.0))
    assert lay.filter(ChannelCommand("f", force_n=2.0), 0.001).force_n == 0.0
    assert lay.hits == {"max_velocity_mm_s": 1}
    assert lay.events["faults"] == 0 and lay.phase == "running"


def test_the_defaults_are_those_docs_safety_md_states():
    """Every field of ``SafetySettings`` has the default the settings table of
    docs/safety.md gives (a number with its unit, ``False``), so a changed default is a
    changed document too."""
    import re
    from dataclasses import fields
    from pathlib import Path
    doc = (Path(__file__).resolve().parents[2] / "docs" / "safety.md").read_text()
    rows = dict(re.findall(r"^\| `(\w+)` \| ([^|]+?) \|", doc, flags=re.M))
    defaults = SafetySettings()
    for f in fields(SafetySettings):
        stated = rows[f.name].split()[0]
        value = getattr(defaults, f.name)
        assert (value is False) if stated == "False" else value == float(stated), (f.name, stated, value)


def test_at_the_knee_speed_the_full_force_passes_untouched_for_any_declaration():
    """The force limit shrinks only *above* ``velocity_knee x max_velocity_mm_s``
    (docs/safety.md): at exactly the knee speed a command at the declared force limit
    passes as it is and counts nothing, for 300 seeded declarations (limits in 0.1-10 N at
    1 mN, top speeds in 50-1000 mm/s at 0.1 mm/s, four knees), whatever the rounding of
    the shrinking limit's own formula would give there."""
    rng = np.random.default_rng(24)
    for _ in range(300):
        fmax = round(float(rng.uniform(0.1, 10.0)), 3)
        vmax = round(float(rng.uniform(50.0, 1000.0)), 1)
        knee = float(rng.choice([0.25, 0.3, 0.5, 0.7]))
        lay = running_layer(ActuatorLimits(max_force_n=fmax, max_velocity_mm_s=vmax), start_max_force_n=None,
                            velocity_knee=knee)
        lay.observe(state(speed=knee * vmax))
        for t, f in ((0.001, fmax), (0.002, -fmax)):
            assert lay.filter(ChannelCommand("f", force_n=f), t).force_n == f, (fmax, vmax, knee)
        assert lay.hits == {}, (fmax, vmax, knee)

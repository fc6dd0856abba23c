"""The per-tick code (safety filter and its compiled form for the servo loop's steady-state
tick, actuator command, hardness and roughness renderer ticks, piezo-virtual command)
gives exactly the values of the documented rules.

A fixed sequence of states and commands covers every branch of the safety layer (start
gate, ramp, running, every clamp, the force rate limit, overspeed fault, command gap,
stale zeroing). The expected values are computed here, from the rules in
``docs/safety.md`` and formulas (8) and (9), with plain float arithmetic in the same
operation order as the rules are written, so the comparison is exact (``==``), not a
tolerance: the per-tick fast paths must not change a single bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from hapticsdk.devices.actuators import ActuatorLimits, DeviceState
from hapticsdk.perception.dimensions import ChannelCommand, TickInput
from hapticsdk.errors import ValidationError
from hapticsdk.devices.safety import SafetyLayer
from recorders import RecordingActuator

hardness = pytest.importorskip("hapticsdk_hardness.dimension")
roughness = pytest.importorskip("hapticsdk_roughness.dimension")
virtual = pytest.importorskip("hapticsdk_roughness.virtual")

FORCE_LIMITS = ActuatorLimits(max_force_n=3.3, max_stiffness_n_per_mm=2.3, max_velocity_mm_s=400.0,
                              max_force_rate_n_per_tick=0.5)
VIB_LIMITS = ActuatorLimits(frequency_range_hz=(30.0, 120.0), max_amplitude=25.0, amplitude_unit="V",
                            min_amplitude=0.5)
SETTINGS = {"ramp_time_s": 0.01, "stale_after_s": 0.001, "restart_after_s": 0.05, "start_max_penetration_mm": 1.0,
            "start_max_force_n": 1.0, "velocity_knee": 0.5, "stiffness_offset_n": 1.0}
EPS = 1e-9  # the layer's documented time slack (s)


class _Reference:
    """The safety rules of docs/safety.md, written out plainly (no shared code)."""

    def __init__(self, lim: ActuatorLimits, ramp_amplitude: bool = False) -> None:
        self.lim = lim
        self.ramp_amplitude = ramp_amplitude
        self.hits: dict[str, int] = {}
        self.events = {"faults": 0, "stale_zeroed": 0, "start_hold_ticks": 0, "ramp_ticks": 0}
        self.phase = "waiting"
        self.t_last = None
        self.t0 = None
        self.prev = 0.0
        self.over = False
        self.speed = 0.0
        self.pen = 0.0
        self.last = None
        self.stale_counted = False

    def hit(self, k):
        self.hits[k] = self.hits.get(k, 0) + 1

    def restart(self):
        self.phase, self.t_last, self.t0, self.prev, self.last = "waiting", None, None, 0.0, None
        self.stale_counted = False

    def observe(self, pen, vel):
        self.pen = pen
        self.speed = float(np.linalg.norm(np.asarray(vel, float)))
        vmax = self.lim.max_velocity_mm_s
        if vmax is not None:
            over = self.speed > vmax
            if over:
                self.hit("max_velocity_mm_s")
                if not self.over:
                    self.events["faults"] += 1
                    self.restart()
            self.over = over

    def current(self, now):
        if self.last is None:
            return None
        if now - self.t_last > SETTINGS["stale_after_s"] + EPS:
            if not self.stale_counted:
                self.events["stale_zeroed"] += 1
                self.stale_counted = True
            f, fr, a = self.last
            return (0.0 if f is not None else None, fr, 0.0 if a is not None else None)
        return self.last

    def filter(self, force, freq, amp, now):
        lim = self.lim
        if self.t_last is not None and now - self.t_last > SETTINGS["restart_after_s"] + EPS:
            self.events["faults"] += 1
            self.restart()
        if force is not None:
            force = float(force)
            if lim.max_force_n is not None and abs(force) > lim.max_force_n:
                self.hit("max_force_n")
                force = math.copysign(lim.max_force_n, force)
            vmax = lim.max_velocity_mm_s
            if vmax is not None:
                if self.speed > vmax:
                    force = 0.0
                else:
                    knee = SETTINGS["velocity_knee"] * vmax
                    if self.speed > knee:
                        cap = lim.max_force_n * (vmax - self.speed) / (vmax - knee)
                        if abs(force) > cap:
                            self.hit("max_velocity_mm_s")
                            force = math.copysign(cap, force)
            if lim.max_stiffness_n_per_mm is not None:
                cap = lim.max_stiffness_n_per_mm * max(self.pen, 0.0) + SETTINGS["stiffness_offset_n"]
                if abs(force) > cap:
                    self.hit("max_stiffness_n_per_mm")
                    force = math.copysign(cap, force)
        if amp is not None:
            amp = float(amp)
            if amp < 0:
                self.hit("negative_amplitude")
                amp = 0.0
            if lim.max_amplitude is not None and amp > lim.max_amplitude:
                self.hit("max_amplitude")
                amp = float(lim.max_amplitude)
        if freq is not None and lim.frequency_range_hz is not None:
            lo, hi = lim.frequency_range_hz
            if freq < lo or freq > hi:
                self.hit("frequency_range_hz")
                freq = float(min(max(freq, lo), hi))
        # gate and ramp
        if self.over:
            self.events["start_hold_ticks"] += 1
            gain = 0.0
        else:
            gain = None
            if self.phase == "waiting":
                if self.pen > SETTINGS["start_max_penetration_mm"] or (
                        force is not None and abs(force) > SETTINGS["start_max_force_n"]):
                    self.events["start_hold_ticks"] += 1
                    gain = 0.0
                else:
                    self.phase, self.t0 = "ramping", now
            if gain is None and self.phase == "ramping":
                g = (now - self.t0) / SETTINGS["ramp_time_s"]
                if g >= 1.0 - EPS:
                    self.phase, gain = "running", 1.0
                else:
                    self.events["ramp_ticks"] += 1
                    gain = max(g, 0.0)
            if gain is None:
                gain = 1.0
        if force is not None:
            force = gain * force
            rate = lim.max_force_rate_n_per_tick
            if rate is not None and abs(force - self.prev) > rate:
                self.hit("max_force_rate_n_per_tick")
                force = self.prev + math.copysign(rate, force - self.prev)
            self.prev = force
        if amp is not None and self.ramp_amplitude:
            amp = gain * amp
        if amp is not None and lim.min_amplitude is not None and amp < lim.min_amplitude:
            self.hit("min_amplitude")
            amp = float(lim.min_amplitude)
        self.last = (force, freq, amp)
        self.t_last = now
        self.stale_counted = False
        return self.last


def _state(pen, speed_x, speed_y=0.0):
    return DeviceState(t=0.0, position_mm=np.array([0.0, -pen, 0.0]), velocity_mm_s=np.array([speed_x, speed_y, 0.0]))


def _force_script():
    """(now, penetration, vx, vy, commanded force): gate hold, ramp, running with every
    clamp, overspeed fault, recovery, a command gap, the stale check."""
    rng = np.random.default_rng(7)
    out = []
    t = 0.0
    for _ in range(5):                                   # deep press: the gate holds
        out.append((t, 2.0, 0.0, 0.0, 3.0)); t += 0.001
    out.append((t, 0.5, 0.0, 0.0, 0.8)); t += 0.001      # gate releases: ramp starts
    for _ in range(14):                                  # ramp + rate limit + stiffness cap
        out.append((t, 0.6, 10.0, 0.0, 2.0)); t += 0.001
    for _ in range(300):                                 # running, every force clamp
        pen = float(rng.uniform(-1.0, 3.0))
        vx = float(rng.uniform(0.0, 390.0))
        vy = float(rng.uniform(-50.0, 50.0))
        f = float(rng.uniform(-5.0, 5.0))
        out.append((t, pen, vx, vy, f)); t += 0.001
    out.append((t, 0.5, 450.0, 0.0, 1.0)); t += 0.001    # overspeed: fault
    out.append((t, 0.5, 420.0, 0.0, 1.0)); t += 0.001    # still over: held, no second fault
    for _ in range(20):                                  # back: gate, ramp again
        out.append((t, 0.5, 50.0, 0.0, 0.9)); t += 0.001
    t += 0.08                                            # command gap > restart_after_s
    for _ in range(20):
        out.append((t, 0.4, 0.0, 0.0, 0.7)); t += 0.0013
    return out


def _through(steady, args, lay, cmd, now, used):
    """The command through the layer's compiled filter ``steady(*args)`` where it takes it
    (its steady state), else ``cmd`` through ``filter`` (as the servo loop's steady-state
    tick sends); counts the compiled ones in ``used``."""
    out = steady(*args) if steady is not None else None
    if out is None:
        return lay.filter(cmd, now)
    used[0] += 1
    return out


@pytest.mark.parametrize("compiled", [False, True], ids=["filter", "compiled-filter"])
def test_safety_filter_force_path_matches_the_rules_exactly(compiled):
    """``compiled``: through ``SafetyLayer._steady_filter`` (built once, its limits
    captured at configuration time) wherever the layer is running, as the servo loop's
    steady-state tick sends: every clamp must still happen, per command."""
    lay = SafetyLayer(FORCE_LIMITS, **SETTINGS)
    lay.reset(0.0)
    steady = lay._steady_filter(True) if compiled else None
    used = [0]
    ref = _Reference(FORCE_LIMITS)
    for now, pen, vx, vy, f in _force_script():
        lay.observe(_state(pen, vx, vy))
        ref.observe(pen, (vx, vy, 0.0))
        out = _through(steady, ("force", f, (0.0, 1.0, 0.0), now, pen), lay,
                       ChannelCommand("force", f, None, None, (0.0, 1.0, 0.0)), now, used)
        exp = ref.filter(f, None, None, now)
        assert (out.force_n, out.frequency_hz, out.amplitude) == exp, now
        assert type(out.force_n) is float
        assert out.role == "force" and out.direction == (0.0, 1.0, 0.0)
        assert lay.phase == ref.phase
        for dt in (0.0005, 0.0025):                      # fresh, then stale
            c = lay.current(now + dt)
            assert (c.force_n, c.frequency_hz, c.amplitude) == ref.current(now + dt)
    assert lay.hits == ref.hits
    assert lay.events == ref.events
    # every branch was taken
    assert set(ref.hits) == {"max_force_n", "max_velocity_mm_s", "max_stiffness_n_per_mm",
                             "max_force_rate_n_per_tick"}
    assert ref.events["faults"] == 2 and ref.events["ramp_ticks"] > 0 and ref.events["start_hold_ticks"] > 5
    assert (used[0] > 250) is compiled, used   # the running phase's ticks went through it


@pytest.mark.parametrize("compiled", [False, True], ids=["filter", "compiled-filter"])
@pytest.mark.parametrize("ramp_amplitude", [False, True])
def test_safety_filter_vibration_path_matches_the_rules_exactly(ramp_amplitude, compiled):
    rng = np.random.default_rng(11)
    lay = SafetyLayer(VIB_LIMITS, **SETTINGS, ramp_amplitude=ramp_amplitude)
    lay.reset(0.0)
    steady = lay._steady_filter(False) if compiled else None
    used = [0]
    ref = _Reference(VIB_LIMITS, ramp_amplitude)
    for k in range(200):
        now = k * 0.001 + (0.08 if k >= 150 else 0.0)   # a command gap > restart_after_s at k = 150
        fr = float(rng.uniform(0.0, 150.0))
        am = float(rng.uniform(-3.0, 30.0))
        fr_in = np.float64(fr) if k % 3 == 0 else fr     # numpy scalars pass through unchanged in range
        lay.observe(_state(0.2, 30.0))
        ref.observe(0.2, (30.0, 0.0, 0.0))
        out = _through(steady, ("vibration", fr_in, am, now), lay, ChannelCommand("vibration", None, fr_in, am),
                       now, used)
        exp = ref.filter(None, fr_in, am, now)
        assert (out.force_n, out.frequency_hz, out.amplitude) == exp, k
        assert type(out.frequency_hz) is type(exp[1])
    assert lay.hits == ref.hits and lay.events == ref.events
    assert set(ref.hits) == {"frequency_range_hz", "negative_amplitude", "max_amplitude", "min_amplitude"}
    assert (used[0] > 150) is compiled, used


def test_limits_assigned_after_construction_are_enforced():
    """The layer copies limits for the fast path: assigning new ones must refresh it."""
    lay = SafetyLayer(ActuatorLimits(max_force_n=3.3), ramp_time_s=0.0)
    lay.reset(0.0)
    lay.filter(ChannelCommand("f", 0.5), 0.0)
    lay.limits = ActuatorLimits(max_force_n=1.0)
    assert lay.filter(ChannelCommand("f", 2.0), 0.001).force_n == 1.0
    lay.configure(restart_after_s=0.01)
    lay.filter(ChannelCommand("f", 0.5), 0.05)           # 49 ms gap > 10 ms: a fault
    assert lay.events["faults"] == 1


class _Rec(RecordingActuator):
    name = "test-tick-rec"
    channel = "force"
    limits = ActuatorLimits(max_force_n=3.3, frequency_range_hz=(1.0, 500.0), max_amplitude=1.0)


@pytest.mark.parametrize("field", ["force_n", "frequency_hz", "amplitude"])
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_actuator_command_rejects_each_non_finite_field(field, bad):
    act = _Rec(safety=SafetyLayer(_Rec.limits, ramp_time_s=0.0)).open()
    cmd = ChannelCommand("force", force_n=0.5, frequency_hz=100.0, amplitude=0.5)
    setattr(cmd, field, bad)
    with pytest.raises(ValidationError) as ei:
        act.command(cmd, now=0.0)
    assert ei.value.field == f"{act.label}.{field}"
    assert act.sent == []
    out = act.command(ChannelCommand("force", force_n=0.5, frequency_hz=100.0, amplitude=0.5), now=0.001)
    assert act.sent == [out] and out.force_n == 0.5


def _inputs(floats: bool = False):
    """Seeded inputs; with ``floats`` each also carries its velocity as floats, as the
    servo loop gives it."""
    rng = np.random.default_rng(3)
    out = []
    for k in range(400):
        pen = float(rng.uniform(-1.0, 3.0))
        vx = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.0, 300.0))
        if k % 50 == 0:
            vx = 20.0 if k % 100 == 0 else -19.999999999  # on and just below the gate
        out.append(TickInput(t=k * 0.001, dt=0.001, penetration_mm=pen,
                             velocity_mm_s=np.array([vx, 0.0, 0.0]), in_contact=pen > 0.0,
                             velocity_floats_mm_s=(vx, 0.0, 0.0) if floats else None))
    return out


@pytest.mark.parametrize("gs", [1.7, 3.0])
def test_hardness_tick_is_formula_8_exactly(gs):
    r = hardness.HardnessDimension().renderer({"GS": gs})
    k = min(gs, hardness.GS_MAX_N_PER_MM)
    if gs > hardness.GS_MAX_N_PER_MM:
        f_coil = float(r.calibration.frequency_for(gs - hardness.GS_MAX_N_PER_MM)[0])
        amp = 0.5                                        # the renderer's default coil amplitude
    else:
        f_coil, amp = None, 0.0
    for inp in _inputs():
        force, coil = r.tick(inp)
        assert force.role == "force" and coil.role == "coil"
        if inp.penetration_mm > 0:
            assert (force.force_n, force.frequency_hz, force.amplitude) == (k * inp.penetration_mm, None, None)
            assert (coil.force_n, coil.frequency_hz, coil.amplitude) == (None, f_coil, amp)
        else:
            assert (force.force_n, force.frequency_hz, force.amplitude) == (0.0, None, None)
            assert (coil.force_n, coil.frequency_hz, coil.amplitude) == (None, f_coil, 0.0)


@pytest.mark.parametrize("floats", [False, True])
@pytest.mark.parametrize("require_contact", [True, False])
def test_roughness_tick_is_formula_9_exactly(require_contact, floats):
    fpeak, afpeak = 150.0, 5.0
    r = roughness.RoughnessDimension().renderer({"Fpeak": fpeak, "AFpeak": afpeak},
                                                require_contact=require_contact, frequency_range_hz=(40.0, 400.0))
    v_out = r.table.voltage_for(fpeak, afpeak)[0]
    last_f = fpeak                                       # within (40, 400): the start frequency
    active = clamps = 0
    inputs = _inputs(floats)
    for inp in inputs:
        (c,) = r.tick(inp)
        vx = float(inp.velocity_mm_s[0])
        assert c.role == "vibration" and c.force_n is None
        if abs(vx) >= 20.0 and (inp.in_contact or not require_contact):
            f = fpeak * abs(vx) / 80.0
            if f < 40.0 or f > 400.0:
                clamps += 1
                f = min(max(f, 40.0), 400.0)
            last_f = f
            active += 1
            assert (c.frequency_hz, c.amplitude) == (f, v_out)
        else:
            assert (c.frequency_hz, c.amplitude) == (last_f, 0.0)
    assert (r.ticks, r.active_ticks, r.frequency_clamps) == (len(inputs), active, clamps)
    assert clamps > 0 and 0 < active < len(inputs)
    nan_in = TickInput(t=0.0, dt=0.001, penetration_mm=1.0, velocity_mm_s=np.array([math.nan, 0.0, 0.0]),
                       in_contact=True)
    assert r.tick(nan_in)[0].amplitude == 0.0          # a NaN speed stays silent


def test_piezo_virtual_records_each_command_and_its_sample_count():
    period, fs = 0.0013, 8000.0                          # 10.4 samples per command: the carry matters
    act = virtual.PiezoVirtual(period_s=period, fs=fs, safety=SafetyLayer(virtual.PiezoVirtual.limits,
                                                                           ramp_time_s=0.0)).open()
    frac, total = 0.0, 0
    for k in range(50):
        f, a = 100.0 + k, (0.0 if k % 7 == 0 else 10.0)
        act.command(ChannelCommand("vibration", None, f, a), now=k * period)
        assert (act._freq, act._target_amp) == (f, a)
        exact = period * fs + frac
        n = int(exact)
        frac = exact - n
        total += n
        assert act._pending[-1] == (f, a, n)
    act.step(period)
    assert act.samples_total == total and act.commands == 50


def test_omni_virtual_command_keeps_the_arm_saturated_set_point():
    omni = pytest.importorskip("hapticsdk_hardness.omni")
    from hapticsdk.sim.arm import ArmParams
    dev = omni.OmniVirtual(arm=ArmParams().with_(max_force_n=2.0),
                           safety=SafetyLayer(omni.OmniVirtual.limits, ramp_time_s=0.0)).open()
    dev.safety.observe(_state(1.0, 0.0))
    k = 0
    for f in (0.5, 1.0, 1.9, 2.0, 2.6, 3.3, 3.0, -0.5):
        for d in (None, (0.6, 0.8, 0.0)):
            k += 1
            out = dev.command(ChannelCommand("force", f, None, None, d), now=k * 0.001)
            proj = out.force_n * (1.0 if d is None else d[1])
            assert dev.read_back().force_n == max(-2.0, min(2.0, proj))

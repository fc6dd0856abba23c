"""The servo loop's steady-state tick (issue 30): the same outputs, bit for bit, as the
general tick, on the same scenes, whatever happens during the run.

Each scene runs twice, once with ``ServoLoop(fast_tick=False)`` (the general tick only)
and once with the default (the steady-state tick wherever the loop is in a steady state),
and everything either run produced is compared as ``float.hex`` text: every command each
backend received, every sent record and ``last_command``, every tick's logged row and
state (what a recorder would see), the events, clamp counts, the passivity report, every
safety layer's counters and state, the renderers' own state and the loop's. Each
comparison also checks that the steady-state tick really ran (and, where the scene
crosses a guard condition, that the general tick ran too).
"""

from __future__ import annotations

import dataclasses
import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hapticsdk.benchmarks.timing import build_scene
from hapticsdk.devices.actuators import Actuator
from hapticsdk.devices.safety import SafetyLayer
from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer
from hapticsdk.plugins import registry
from hapticsdk.runtime import ServoLoop
from hapticsdk.scene.geometry import Box, HitTester, Pose, Sphere
from repo_scripts import load_script

pytest.importorskip("hapticsdk_hardness")
pytest.importorskip("hapticsdk_roughness")


# the digest's text of a value and of a command (float.hex: bit for bit)
_digest = load_script("bench/tick_outputs_digest.py")
_h = _digest._h


def _cmd(c: object) -> str:
    return "None" if c is None else type(c).__name__ + _digest._cmd(c)


def _state(s: object) -> str:
    return "None" if s is None else _h([type(s).__name__] + [getattr(s, f) for f in (
        "t", "px", "py", "pz", "vx", "vy", "vz", "fx", "fy", "fz", "buttons")])


def _renderer(r: DimensionRenderer) -> str:
    extra = {k: getattr(r, k) for k in ("_gate_open", "_last_f", "ticks", "active_ticks", "frequency_clamps",
                                        "table_clamps") if hasattr(r, k)}
    return _h(r.describe()) + _h(extra)


def _layer(a: Actuator) -> str:
    s = a.safety
    return _h([s.hits, s.events, s.phase, s.last_fault, s._prev_force, s._t_last, s._stale_counted, s._overspeed,
               s._speed_now, s._ramp_t0]) + _cmd(s._last) + _state(s._state)


def _dims():
    return registry("dimension")


def _material(gs: float, fpeak: float, afpeak: float) -> list[DimensionRenderer]:
    dims = _dims()
    return [dims.load("hardness")().renderer({"GS": gs}), dims.load("roughness")().renderer(
        {"Fpeak": fpeak, "AFpeak": afpeak})]


class _Glitches:
    """The device's state read, replaced on the instance: non-finite, out-of-range and
    spiking states on the ticks drawn, and a safety fault raised during the read (a
    device's error flag: within the tick, after the loop chose its parts)."""

    def __init__(self, dev, plan: dict[int, str], acts=None) -> None:
        self.read = dev._read_state
        self.plan = plan
        self.acts = acts
        self.k = 0

    def __call__(self):
        s = self.read()
        what = self.plan.get(self.k)
        if what == "nan":
            s.py = math.nan
        elif what == "inf":
            s.vx = math.inf
        elif what == "huge":
            s.px = 5000.0
        elif what == "spike":
            s.vy += 5000.0
        elif what == "flag":
            self.acts["force"].safety.fault("test: the device's error flag")
        elif what == "flag-vib":
            self.acts["vibration"].safety.fault("test: the piezo's error flag")
        return s


def _run(fast: bool, *, ticks: int, period_s: float = 0.001, material=(3.0, 150.0, 5.0), glitches=None,
         actions=None, spatial: bool = False, rt_clock=None, stiffness_cap: float | None = None,
         delay_ticks: int = 0) -> tuple[list[str], dict[str, int]]:
    """Run the timing scene for ``ticks`` ticks; return everything it produced, as text,
    and how many ticks each path ran."""
    dev, _, acts = build_scene(ticks * period_s + 1.0, period_s)
    renderers = _material(*material)
    out: list[str] = []
    _digest.log_backend_commands(acts, out, _cmd)
    g = _Glitches(dev, glitches or {}, acts)
    dev._read_state = g
    kw = {}
    if spatial:
        box = Box((400.0, 20.0, 400.0), pose=Pose((0.0, -20.0, 0.0)))     # top face at y = 0
        ball = Sphere(2.0, pose=Pose((80.0, 3.0, 0.0)))   # met when the probe leaves the box at x = 80
        kw = dict(objects=[("box", renderers), ("ball", _material(1.0, 90.0, 3.0))],
                  hit_tester=HitTester([("box", box), ("ball", ball)]))
        renderers = []
    if rt_clock is not None:
        kw.update(realtime=True, clock=rt_clock)
    if stiffness_cap is not None:
        f = acts["force"]
        f.safety.limits = dataclasses.replace(f.limits, max_stiffness_n_per_mm=stiffness_cap)
    loop = ServoLoop(dev, renderers, acts, period_s=period_s, fast_tick=fast, raise_on_fault=False,
                     delay_ticks=delay_ticks, **kw)
    loop.start(ticks * period_s)
    paths = {"fused": 0, "general": 0}
    sent_ids: list = []
    for k in range(ticks):
        g.k = k
        if actions and k in actions:
            actions[k](loop, acts)
        paths["fused" if loop._steady is not None else "general"] += 1
        more = loop.tick()
        out.append(f"{k} {_state(loop.last_state)} {_h([loop.last_penetration_mm, loop.last_force_n, loop.last_t, loop.last_index, loop.contact])}")
        for a in acts.values():
            out.append(_cmd(a.last_command))
            sent_ids.append(a.last_command)
        if not more:
            break
    rep = loop.finish()
    for key in sorted(rep.log):
        if key not in ("compute_s", "compute_cpu_s"):
            out.append(f"log {key} {_h(rep.log[key])}")
    out.append(_h({k: v for k, v in rep.events.items() if k != "overrun"}))
    out.append(_h(rep.passivity) + _h(rep.fault) + _h(rep.ticks))
    out.append(_h([loop._vf0, loop._vf1, loop._vf2, loop._last_x, loop._pc_obj, loop._have_good, loop._last_vel]))
    for role, a in acts.items():
        out.append(f"{role} {_layer(a)} {_cmd(a.last_command)} {a.fault!r}")
        a.close()
    for o in loop._objs:
        out.extend(_renderer(r) for r in o.renderers)
    # every sent record a new object (the history a recorder keeps is never rewritten)
    seen = {}
    for i, c in enumerate(sent_ids):
        prev = seen.setdefault(id(c), c)
        assert prev is c
    return out, paths


def _same(**kw) -> dict[str, int]:
    general, p0 = _run(False, **kw)
    fused, p1 = _run(True, **kw)
    assert p0["fused"] == 0
    assert len(general) == len(fused)
    for a, b in zip(general, fused):
        assert a == b
    return p1


def test_the_timing_scene_runs_the_steady_state_tick_with_the_general_ticks_outputs():
    paths = _same(ticks=3000)
    # the safety layers' 0.2 s ramp runs the general tick; then the steady-state tick
    assert paths["fused"] > 2700 and paths["general"] >= 200


def test_glitches_and_guard_conditions_crossed_mid_run_keep_the_outputs_bit_identical():
    dims = _dims()

    def switch(loop, acts):
        loop.set_renderers(0, [dims.load("hardness")().renderer({"GS": 5.0}),
                               dims.load("roughness")().renderer({"Fpeak": 400.0, "AFpeak": 9.0})])

    def limits(loop, acts):
        f = acts["force"]
        f.safety.limits = dataclasses.replace(f.limits, max_force_n=1.2, max_stiffness_n_per_mm=0.05,
                                              max_force_rate_n_per_tick=0.01)

    def speed(loop, acts):
        f = acts["force"]
        f.safety.limits = dataclasses.replace(f.limits, max_velocity_mm_s=45.0)

    def restore(loop, acts):
        f = acts["force"]
        f.safety.limits = type(f).limits

    def pause(loop, acts):
        loop.paused = True

    def resume(loop, acts):
        loop.paused = False

    def fault(loop, acts):
        acts["coil"].safety.fault("test: a fault on the coil")

    def call(loop, acts):
        loop.call_in_loop(lambda: None)

    def settings_(loop, acts):
        acts["force"].safety.configure(stiffness_offset_n=0.25, velocity_knee=0.2)

    def vib_limits(loop, acts):
        c = acts["coil"]
        c.safety.limits = dataclasses.replace(c.limits, max_amplitude=0.3, frequency_range_hz=(100.0, 180.0))

    def new_layer(loop, acts):
        v = acts["vibration"]
        v.safety = SafetyLayer(v.limits, ramp_time_s=0.05, ramp_amplitude=True)

    actions = {400: limits, 700: restore, 900: pause, 1000: resume, 1200: switch, 1500: fault, 1800: call,
               2000: speed, 2300: restore, 2400: settings_, 2600: vib_limits, 3300: new_layer}
    glitches = {k: w for k, w in zip(range(350, 3600, 137), ["nan", "inf", "huge", "spike", "flag", "flag-vib"] * 5)}
    paths = _same(ticks=3600, actions=actions, glitches=glitches)
    assert paths["fused"] > 500 and paths["general"] > 600


def test_a_safety_layer_replaced_during_the_steady_state_tick_is_the_one_used_from_then_on():
    seen = []

    def new_layers(loop, acts):
        seen.append(loop._steady is not None)
        for role in ("force", "vibration"):
            a = acts[role]
            a.safety = SafetyLayer(a.limits, ramp_time_s=0.05, ramp_amplitude=True)

    _same(ticks=1500, actions={800: new_layers})
    assert seen == [False, True]   # (the general run, then the other) replaced while the steady-state tick ran


def test_a_backend_fault_during_the_steady_state_tick_ends_the_run_as_the_general_tick_does():
    def boom(loop, acts):
        def fail(c):
            raise RuntimeError("test: backend failure")
        acts["coil"]._command = fail

    paths = _same(ticks=1500, actions={1000: boom})
    assert paths["fused"] > 600


@pytest.mark.parametrize("role", ["force", "coil", "vibration"])
@pytest.mark.parametrize("how", ["closed", "faulted"])
def test_an_actuator_closed_or_faulted_from_outside_is_not_sent_to_by_the_steady_state_tick(role, how):
    """Another thread closes an actuator, or its failed stop leaves it faulted, while the
    steady-state tick runs: the next command must not reach its backend (the general
    send refuses a closed or faulted actuator, and the run ends on that fault), on both
    paths alike."""
    seen = []

    def outside(loop, acts):
        seen.append(loop._steady is not None)
        a = acts[role]
        if how == "closed":
            a.close()
        else:
            a.fault = RuntimeError("test: a stop that failed on another thread")

    _same(ticks=1500, actions={1000: outside})
    assert seen == [False, True]


def test_a_delay_line_started_with_the_run_keeps_the_general_tick_whatever_delay_ticks_says_later():
    """The force path's extra delay (``delay_ticks``) is a line of forces made when the run
    starts; the steady-state tick has none, so it is never built while that line exists,
    even after ``delay_ticks`` is set to 0 and the loop rebuilds (an operation)."""
    def undelay(loop, acts):
        loop.delay_ticks = 0
        loop.call_in_loop(lambda: None)

    paths = _same(ticks=1200, delay_ticks=2, actions={600: undelay})
    assert paths["fused"] == 0


class _NanAfter:
    """The loop's passivity controller, handing back NaN from its ``n``-th step on."""

    def __init__(self, pc, n: int) -> None:
        self.pc, self.n = pc, n

    def step(self, x, dt, f):
        self.n -= 1
        return math.nan if self.n < 0 else self.pc.step(x, dt, f)

    def __getattr__(self, name):
        return getattr(self.pc, name)


def test_a_non_finite_force_from_the_controller_is_rejected_as_by_the_general_tick():
    def nan_law(loop, acts):
        s = loop._slots[0]
        s.pc = _NanAfter(s.pc, 700)     # before the first tick: "command rejected" at tick 700

    paths = _same(ticks=900, actions={0: nan_law})
    assert paths["fused"] > 300


def test_a_spatial_scene_with_a_hit_tester_takes_the_steady_state_tick_with_the_same_outputs():
    paths = _same(ticks=2500, spatial=True, stiffness_cap=0.05)   # a cap on the hit test's penetration
    assert paths["fused"] > 1500
    out, _ = _run(True, ticks=2500, spatial=True, stiffness_cap=0.05)
    objects = [x for x in out if x.startswith("log object")][0][len("log object ("):-1].split(",")
    assert objects.count("1") > 100 and objects.count("0") > 1000   # the ball (a slanted normal) and the box


class _Clock:
    """A deterministic real-time clock: the loop's pacing code runs, time is what the
    loop waits for plus a jitter drawn from a fixed sequence."""

    def __init__(self, jitter: list[float]) -> None:
        self.t = 100.0
        self.j = jitter
        self.n = 0

    def now(self) -> float:
        return self.t

    def wait_until(self, deadline: float) -> None:
        self.n += 1
        self.t = max(self.t + 1e-6, deadline) + self.j[self.n % len(self.j)]

    def work(self, k: int, comp: float) -> None:
        pass


def test_real_time_pacing_runs_the_steady_state_tick_with_the_same_outputs():
    # late ticks, catch-ups, a re-anchor, a gap longer than the safety layers' restart_after_s
    jitter = [0.0, 2e-5, 0.0, 7e-4, 1e-6, 0.0, 3.1e-3, 0.0] * 20 + [8e-3] + [0.0] * 300 + [0.06] + [0.0] * 2000
    general, p0 = _run(False, ticks=1500, rt_clock=_Clock(jitter))
    fused, p1 = _run(True, ticks=1500, rt_clock=_Clock(jitter))
    assert p0["fused"] == 0 and p1["fused"] > 200   # (after the gap the start gate holds the force: pressed)
    assert "command gap" in [x for x in fused if x.startswith("force ")][0]
    assert general == fused


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(gs=st.floats(0.0, 6.0), fpeak=st.floats(20.0, 500.0), afpeak=st.floats(0.5, 12.0),
       period=st.sampled_from([0.00025, 0.0005, 0.001, 0.002]),
       glitch=st.dictionaries(st.integers(250, 1199), st.sampled_from(["nan", "inf", "huge", "spike", "flag",
                                                                       "flag-vib"]), max_size=12),
       events=st.lists(st.tuples(st.integers(210, 1199), st.sampled_from(
           ["fault-force", "fault-coil", "fault-vib", "pause", "resume", "switch", "call", "force-limit",
            "speed-limit", "rate-limit", "restore"])), max_size=6))
def test_drawn_scenes_give_the_same_outputs_on_both_paths(gs, fpeak, afpeak, period, glitch, events):
    dims = _dims()

    def act(name):
        def run(loop, acts):
            f = acts["force"]
            if name.startswith("fault-"):
                acts[{"fault-force": "force", "fault-coil": "coil", "fault-vib": "vibration"}[name]].safety.fault("drawn")
            elif name == "pause":
                loop.paused = True
            elif name == "resume":
                loop.paused = False
            elif name == "switch":
                loop.set_renderers(0, [dims.load("hardness")().renderer({"GS": 6.0 - gs}),
                                       dims.load("roughness")().renderer({"Fpeak": fpeak / 2, "AFpeak": afpeak})])
            elif name == "call":
                loop.call_in_loop(lambda: None)
            elif name == "force-limit":
                f.safety.limits = dataclasses.replace(f.limits, max_force_n=0.7, max_stiffness_n_per_mm=0.3)
            elif name == "speed-limit":
                f.safety.limits = dataclasses.replace(f.limits, max_velocity_mm_s=60.0)
            elif name == "rate-limit":
                f.safety.limits = dataclasses.replace(f.limits, max_force_rate_n_per_tick=0.003)
            else:
                f.safety.limits = type(f).limits
        return run

    actions = {k: act(name) for k, name in events}
    _same(ticks=1200, period_s=period, material=(gs, fpeak, afpeak), glitches=glitch, actions=actions)


# -- what the steady-state tick leaves to the general one, decided when it is built ------

class _CountingLayer(SafetyLayer):
    """A safety layer with a rule of its own: its filter must run on every command."""

    calls = 0

    def filter(self, cmd: ChannelCommand, now: float) -> ChannelCommand:
        type(self).calls += 1
        return super().filter(cmd, now)


class _TickOnly(DimensionRenderer):
    """A renderer that offers no law: its tick must run on every tick."""

    roles = ("coil",)

    def __init__(self) -> None:
        self.n = 0

    def tick(self, inp):
        self.n += 1
        return [ChannelCommand("coil", None, 150.0, 0.2 if inp.in_contact else 0.0)]


def _loop(renderers=None, **kw):
    dev, rs, acts = build_scene(2.0)
    return ServoLoop(dev, rs if renderers is None else renderers, acts, period_s=0.001, **kw), acts


def test_a_safety_layer_that_replaces_filter_is_called_on_every_command():
    """Decided when the steady-state tick is built (the layer's class), not per tick: a
    subclass's own filter is never bypassed."""
    dev, rs, acts = build_scene(2.0)
    acts["coil"].safety = _CountingLayer(acts["coil"].limits)
    _CountingLayer.calls = 0
    loop = ServoLoop(dev, rs, acts, period_s=0.001)
    rep = loop.run(1.0)
    assert _CountingLayer.calls == rep.ticks == 1000
    assert acts["coil"].safety._steady_filter(False) is None


def test_a_renderer_without_a_law_keeps_the_general_tick():
    dev, rs, acts = build_scene(2.0)
    extra = _TickOnly()
    loop = ServoLoop(dev, [rs[0].__class__(3.0), rs[1], extra][1:], acts, period_s=0.001)
    loop.start(1.0)
    fused = 0
    while True:
        fused += loop._steady is not None
        if not loop.tick():
            break
    loop.finish()
    assert fused == 0 and extra.n == 1000


def test_an_actuator_whose_command_is_replaced_is_called_through_it_every_tick():
    dev, rs, acts = build_scene(2.0)
    calls = []
    coil = acts["coil"]
    inner = coil.command
    coil.command = lambda cmd, now=None: (calls.append(now), inner(cmd, now=now))[1]
    loop = ServoLoop(dev, rs, acts, period_s=0.001)
    rep = loop.run(1.0)
    assert len(calls) == rep.ticks
    assert coil._steady_sender(False) is None


def _both(make, seconds: float = 1.0) -> list:
    """``make(fast)`` -> a loop; run it both ways; what each gave (log, events), and
    whether the steady state was ever used."""
    res = []
    for fast in (False, True):
        loop = make(fast)
        loop.start(seconds)
        used = False
        while True:
            used = used or loop._steady is not None
            if not loop.tick():
                break
        rep = loop.finish()
        res.append((_h({k: v for k, v in rep.log.items() if not k.startswith("compute")}),
                    _h({k: v for k, v in rep.events.items() if k != "overrun"}), used))
    return res


def test_a_role_without_an_actuator_keeps_the_general_tick_and_its_counts():
    """Roles are looked up when the steady state is built: a renderer's role with no
    actuator (``drop_unmapped_roles``) leaves the general tick, which counts it."""
    def make(fast):
        dev, rs, acts = build_scene(2.0)
        del acts["vibration"]
        return ServoLoop(dev, rs, acts, period_s=0.001, drop_unmapped_roles=True, fast_tick=fast)
    (log0, ev0, used0), (log1, ev1, used1) = _both(make)
    assert not used0 and not used1 and log0 == log1 and ev0 == ev1
    assert "role_conflict:1000" in ev1


def test_a_vibration_role_commanded_twice_keeps_the_general_tick_and_its_counts():
    def make(fast):
        dev, rs, acts = build_scene(2.0)
        rs.append(_material(3.0, 300.0, 2.0)[1])      # a second roughness: the same role
        return ServoLoop(dev, rs, acts, period_s=0.001, fast_tick=fast)
    (log0, ev0, used0), (log1, ev1, used1) = _both(make)
    assert not used0 and not used1 and log0 == log1 and ev0 == ev1
    assert "role_conflict:1000" in ev1


class _Spring(DimensionRenderer):
    """A spring on the force role, with its law (as a third-party renderer would write it)."""

    roles = ("force",)

    def __init__(self, k: float) -> None:
        self.k = k

    def tick(self, inp):
        return [ChannelCommand("force", self.k * inp.penetration_mm if inp.in_contact else 0.0)]

    def _fast_law(self):
        k = self.k

        def law(t, dt, pen, in_contact, v0, v1, v2, vf0, vf1, vf2, step):
            return (k * pen if in_contact else 0.0, None, None)
        return law


def test_two_force_laws_on_one_role_are_summed_as_by_the_general_tick():
    def make(fast):
        dev, rs, acts = build_scene(2.0)
        rs.append(_Spring(0.7))
        return ServoLoop(dev, rs, acts, period_s=0.001, fast_tick=fast)
    (log0, ev0, used0), (log1, ev1, used1) = _both(make)
    assert not used0 and used1 and log0 == log1 and ev0 == ev1


class _Wild(DimensionRenderer):
    """Force and vibration values the loop must check: NaN, infinite, negative, absent,
    in a cycle of ticks (``tick`` and the law give the same)."""

    roles = ("force", "vibration")
    CYCLE = ((0.3, 120.0, 0.5), (math.nan, 120.0, 0.5), (-0.2, math.inf, 0.4), (None, 130.0, None),
             (math.inf, None, 0.2), (0.1, 140.0, math.nan), (-math.inf, 150.0, -0.3), (0.2, None, None),
             (0.25, 110.0, math.inf), (0.15, -math.inf, -math.inf))

    def __init__(self) -> None:
        self.n = 0

    def _next(self):
        v = self.CYCLE[self.n % len(self.CYCLE)]
        self.n += 1
        return v

    def tick(self, inp):
        f, fr, am = self._next()
        return [ChannelCommand("force", f), ChannelCommand("vibration", None, fr, am)]

    def _fast_law(self):
        def law(*_):
            f, fr, am = self._next()
            return (f, None, None, None, fr, am)
        return law


def test_non_finite_negative_and_absent_law_values_are_counted_and_replaced_as_by_the_general_tick():
    def make(fast):
        dev, rs, acts = build_scene(2.0)
        return ServoLoop(dev, [rs[0], _Wild()], acts, period_s=0.001, fast_tick=fast)
    (log0, ev0, used0), (log1, ev1, used1) = _both(make)
    assert not used0 and used1 and log0 == log1 and ev0 == ev1
    assert "nonfinite_command:0" not in ev1 and "negative_force:0" not in ev1


def test_limits_assigned_during_the_run_rebuild_the_compiled_send_before_the_next_tick():
    """The compiled send holds the limits it was built with; assigning new ones tells
    the loop (the layer's watchers), so the very next tick clamps to them."""
    loop, acts = _loop()
    loop.start(2.0)
    f = acts["force"]
    while loop.ticks < 500:
        loop.tick()
    assert loop._steady is not None
    while loop.last_force_n < 0.5:     # pressing
        loop.tick()
    f.safety.limits = dataclasses.replace(f.limits, max_force_n=0.1)
    assert loop._steady is None          # dropped at once, not on a later tick
    loop.tick()
    assert f.last_command.force_n <= 0.1
    while loop._steady is None:
        loop.tick()
    loop.tick()
    assert f.last_command.force_n <= 0.1
    loop.finish()


def test_a_fault_drops_the_steady_state_tick_and_it_comes_back_after():
    loop, acts = _loop()
    loop.start(2.0)
    while loop._steady is None:
        loop.tick()
    acts["vibration"].safety.fault("test")
    assert loop._steady is None         # dropped at once (the layer tells the loop)
    for _ in range(5):
        loop.tick()
    assert loop._steady is None          # the layer gates and ramps: the general tick
    while loop._steady is None and loop.ticks < 1500:
        loop.tick()
    assert loop._steady is not None and acts["vibration"].safety.phase == "running"
    loop.finish()


class _Hardness2(type(_material(3.0, 1.0, 1.0)[0])):
    """A subclass that replaces tick, not the law: the law would skip it."""

    n = 0

    def tick(self, inp):
        type(self).n += 1
        return super().tick(inp)


@pytest.mark.parametrize("how", ["subclass", "instance"])
def test_a_renderer_whose_tick_is_replaced_is_called_every_tick(how):
    """Decided when the steady state is built: a tick replaced by a subclass below the
    law's class, or on the instance, is never skipped."""
    dev, rs, acts = build_scene(2.0)
    calls = []
    if how == "subclass":
        _Hardness2.n = 0
        rs[0] = _Hardness2(3.0)
    else:
        inner = rs[1].tick
        rs[1].tick = lambda inp: (calls.append(inp.t), inner(inp))[1]
    rep = ServoLoop(dev, rs, acts, period_s=0.001).run(1.0)
    assert rep.ticks == 1000
    assert (_Hardness2.n if how == "subclass" else len(calls)) == 1000


def test_fast_tick_off_never_builds_it():
    loop, acts = _loop(fast_tick=False)
    loop.start(1.0)
    while loop.tick():
        assert loop._steady is None
    loop.finish()


@pytest.mark.parametrize("law_of", ["hardness", "roughness"])
def test_the_built_in_laws_return_floats_or_none_per_role(law_of):
    r = _material(3.0, 150.0, 5.0)[0 if law_of == "hardness" else 1]
    law = r._fast_law()
    for pen, inc, v in ((1.0, True, 40.0), (-1.0, False, 0.0), (0.5, True, 900.0)):
        out = law(0.0, 0.001, pen, inc, v, 0.0, 0.0, v, 0.0, 0.0, 0.0)
        assert len(out) == 3 * len(r.roles)
        assert all(x is None or type(x) is float for x in out)


def test_the_steady_state_tick_observes_every_layer_in_one_call_when_none_declares_a_speed_limit():
    """Moved to configuration time: each layer's ``max_velocity_mm_s is None`` test of
    ``observe``. The steady-state tick stores the state in every layer (one call), and
    each layer holds this tick's state, as ``observe`` leaves it."""
    loop, acts = _loop()
    loop.start(2.0)
    while loop._steady is None:
        loop.tick()
    assert loop._steady[3] is not None
    loop.tick()
    for a in acts.values():
        assert a.safety._state is loop.last_state and a.safety._speed_now is None
    loop.finish()


def test_a_speed_limit_assigned_during_the_run_is_judged_on_the_very_next_tick():
    """The layers' one-call observe is built without a speed check: a speed limit
    assigned during the run drops it (the layer tells the loop), so the next tick's
    observe computes the speed and judges it (over speed: counted and faulted)."""
    loop, acts = _loop()
    loop.start(2.0)
    while loop._steady is None or abs(loop.last_state.vx) < 1.0:   # sliding
        loop.tick()
    coil = acts["coil"].safety
    hits = coil.hits.get("max_velocity_mm_s", 0)
    coil.limits = dataclasses.replace(acts["coil"].limits, max_velocity_mm_s=1e-3)
    loop.tick()
    assert abs(loop.last_state.vx) >= 1.0
    assert coil._speed_now == loop.last_state.speed_mm_s
    assert coil.hits["max_velocity_mm_s"] == hits + 1 and coil._overspeed and coil.phase != "running"
    loop.finish()


def test_a_layer_whose_observe_is_replaced_is_called_every_tick():
    """Decided when the steady state is built: an ``observe`` replaced on the instance is
    called on every tick (no one-call observe then)."""
    loop, acts = _loop()
    layer = acts["coil"].safety
    calls = []
    inner = layer.observe
    layer.observe = lambda st: (calls.append(st), inner(st))[1]
    rep = loop.run(1.0)
    assert len(calls) == rep.ticks == 1000
    assert SafetyLayer._steady_observer((layer,)) is None


def test_a_layer_with_a_speed_limit_is_observed_through_observe_in_the_steady_state():
    """A layer declaring a speed limit computes the speed on every tick of the steady
    state too (its ``observe`` is called)."""
    dev, rs, acts = build_scene(2.0)
    layer = acts["coil"].safety
    layer.limits = dataclasses.replace(acts["coil"].limits, max_velocity_mm_s=1e6)
    loop = ServoLoop(dev, rs, acts, period_s=0.001)
    loop.start(2.0)
    n = 0
    while n < 300:
        n += loop._steady is not None
        loop.tick()
        assert layer._speed_now == loop.last_state.speed_mm_s
    loop.finish()
    assert SafetyLayer._steady_observer((acts["force"].safety, layer)) is None
    assert SafetyLayer._steady_observer((acts["force"].safety,)) is not None

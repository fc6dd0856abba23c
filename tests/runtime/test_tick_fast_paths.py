"""The servo tick's fast paths send exactly what the public paths send.

* ``devices.actuators.servo_sender``: the loop calls ``Actuator._servo_command(cmd, now)``, bound
  once per run, instead of ``act.command(cmd, now=t)``; same checks, same safety layer,
  same backend call; a class or an instance that replaces ``command`` is still called.
* The loop's ``TickInput`` carries the velocity as floats (``velocity_floats_mm_s``) and
  builds its ``velocity_mm_s`` array only when a renderer reads it; the loop stores its
  fields itself, in the order of ``TickInput.__init__``: the object the constructor makes.

The run-level test renders the benchmark's scene (hardness + roughness on the simulated
Omni, voice coil and piezo) twice from the same start: once as the loop runs, once with
every actuator's ``command`` replaced on the instance (the public keyword path) and every
renderer handed a plain ``TickInput`` whose array is built before the call and which
carries no floats (the path before the fast paths). Every command each backend received
must be equal, bit for bit. The roughness frequencies are also recomputed from the
logged velocity with formula (9), an independent path.
"""

from __future__ import annotations

import copy as copy_module
import dataclasses
import math
import pickle

import numpy as np
import pytest

from hapticsdk.devices.actuators import Actuator, ActuatorLimits, servo_sender
from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer, TickInput
from hapticsdk.errors import DeviceError, ValidationError
from hapticsdk.runtime import ServoLoop
from hapticsdk.devices.safety import SafetyLayer
from hapticsdk.scene.geometry import HitTester, Pose, Sphere
from hapticsdk.sim.finger import Trajectory, press_slide
from hapticsdk.sim.probe import VirtualProbe
from recorders import RecordingActuator

pytest.importorskip("hapticsdk_hardness")
pytest.importorskip("hapticsdk_roughness")


class _Rec(RecordingActuator):
    """Records what its backend gets (a vibration channel)."""
    name = "test-fast-rec"
    channel = "vibration"
    limits = ActuatorLimits(frequency_range_hz=(30.0, 120.0), max_amplitude=2.0, amplitude_unit="V")


class _Overrides(_Rec):
    """A backend that (against the rule) overrides the public ``command``."""

    calls = 0

    def command(self, cmd, *, now=None):   # type: ignore[override]
        type(self).calls += 1
        return super().command(cmd, now=now)


def _cmds(n=300, seed=5):
    rng = np.random.default_rng(seed)
    return [ChannelCommand("vib", None, float(rng.uniform(0.0, 200.0)), float(rng.uniform(-1.0, 3.0)))
            for _ in range(n)]


def test_the_sender_sends_what_command_sends():
    a = _Rec(safety=SafetyLayer(_Rec.limits, ramp_time_s=0.05, ramp_amplitude=True)).open()
    b = _Rec(safety=SafetyLayer(_Rec.limits, ramp_time_s=0.05, ramp_amplitude=True)).open()
    send = servo_sender(a)
    assert send.__func__ is Actuator._servo_command and send.__self__ is a
    for k, cmd in enumerate(_cmds()):
        t = k * 0.001
        assert send(cmd, t) == b.command(cmd, now=t)
    assert a.sent == b.sent and a.safety.hits == b.safety.hits and a.safety.hits   # clamps happened
    assert a.last_command == b.last_command


def test_the_sender_keeps_every_check_of_command():
    a = _Rec()
    send = servo_sender(a)
    with pytest.raises(DeviceError, match="closed"):
        send(ChannelCommand("vib", None, 50.0, 0.5), 0.0)
    a.open()
    for field in ("force_n", "frequency_hz", "amplitude"):
        cmd = ChannelCommand("vib", 0.0, 50.0, 0.5)
        setattr(cmd, field, math.nan)
        with pytest.raises(ValidationError) as ei:
            send(cmd, 0.0)
        assert ei.value.field == f"{a.label}.{field}"
    assert a.sent == []
    a.fault = RuntimeError("boom")
    with pytest.raises(DeviceError, match="faulted"):
        send(ChannelCommand("vib", None, 50.0, 0.5), 0.0)
    a.fault = None
    assert send(ChannelCommand("vib", None, 50.0, 0.5), 0.0).frequency_hz == 50.0   # the first layer
    a.safety = SafetyLayer(ActuatorLimits(frequency_range_hz=(60.0, 70.0), max_amplitude=0.1), ramp_time_s=0.0)
    out = send(ChannelCommand("vib", None, 50.0, 0.5), 0.001)   # the layer assigned after binding
    assert (out.frequency_hz, out.amplitude) == (60.0, 0.1)


def test_a_replaced_command_is_still_called():
    o = _Overrides().open()
    before = _Overrides.calls
    servo_sender(o)(ChannelCommand("vib", None, 50.0, 0.5), 0.0)
    assert _Overrides.calls == before + 1
    a = _Rec().open()
    seen = []
    orig = a.command
    a.command = lambda cmd, **k: (seen.append(k), orig(cmd, **k))[1]
    servo_sender(a)(ChannelCommand("vib", None, 50.0, 0.5), 0.25)
    assert seen == [{"now": 0.25}] and len(a.sent) == 1


class _FloatsOnly(DimensionRenderer):
    """Reads the floats only (the array must not be built for it)."""
    roles = ("force",)

    def __init__(self):
        self.inputs = []

    def tick(self, inp):
        self.inputs.append((inp, inp.velocity_floats_mm_s, inp._va is None))
        return [ChannelCommand("force", 0.3 * inp.penetration_mm if inp.in_contact else 0.0)]


class _ArrayReader(DimensionRenderer):
    roles = ("force",)

    def __init__(self):
        self.seen = []

    def tick(self, inp):
        v = inp.velocity_mm_s
        self.seen.append((tuple(float(x) for x in v), inp.velocity_floats_mm_s, v.flags.writeable,
                          v is inp.velocity_mm_s))
        return []


@pytest.mark.parametrize("where", ["plane", "spatial"])
def test_the_loop_input_builds_its_array_only_on_read_with_the_floats_values(where):
    floats, reader = _FloatsOnly(), _ArrayReader()
    if where == "plane":
        loop = ServoLoop(VirtualProbe(trajectory=press_slide()), [floats, reader], passivity=False)
    else:
        tr = Trajectory([(0.0, -30.0, 5.0), (0.2, -10.0, -1.0), (0.6, 30.0, -1.0), (1.0, 30.0, 5.0)])
        ball = Sphere(20.0, pose=Pose((0.0, -19.0, 0.0)))
        loop = ServoLoop(VirtualProbe(trajectory=tr), (), passivity=False, objects=[("ball", [floats, reader])],
                         hit_tester=HitTester([("ball", ball)]))
    rep = loop.run(1.0)
    assert len(reader.seen) > 150   # ticks on the object (1000 on the plane, ~175 on the ball)
    # the first renderer ran before anything read the array: none was built
    assert all(unbuilt for _, _, unbuilt in floats.inputs)
    for arr, fl, writeable, same in reader.seen:
        assert arr == fl and not writeable and same          # the same numbers, read-only, built once
    if where == "plane":   # the state's own velocity, as before
        logged = rep.log["velocity_mm_s"]
        got = np.array([fl for _, fl, _ in floats.inputs])
        assert np.array_equal(got, logged[-len(got):])
    else:   # the contact frame: tangential speed >= 0, normal component, 0
        assert sum(fl[1] != 0.0 for _, fl, _ in floats.inputs) > 50
        assert all(fl[0] >= 0.0 and fl[2] == 0.0 for _, fl, _ in floats.inputs)
    inp = floats.inputs[-1][0]
    copy = dataclasses.replace(inp, t=inp.t + 1.0)
    assert np.array_equal(copy.velocity_mm_s, inp.velocity_mm_s) and copy.velocity_floats_mm_s == inp.velocity_floats_mm_s
    # a renderer may keep, copy or pickle its input (a recorder, a process boundary)
    for other in (pickle.loads(pickle.dumps(inp)), copy_module.deepcopy(inp)):
        assert isinstance(other, TickInput) and np.array_equal(other.velocity_mm_s, inp.velocity_mm_s)
    assert np.array_equal(dataclasses.asdict(inp)["velocity_mm_s"], inp.velocity_mm_s)


def _scene(public: bool):
    from hapticsdk.benchmarks.timing import build_scene
    dev, renderers, acts = build_scene(2.5)
    got: dict[str, list] = {}
    for role, a in acts.items():
        rec = got.setdefault(role, [])
        backend = a._command
        a._command = lambda c, backend=backend, rec=rec: (rec.append(
            (c.role, c.force_n, c.frequency_hz, c.amplitude, c.direction)), backend(c))[1]
        if public:
            orig = a.command
            a.command = lambda cmd, orig=orig, **k: orig(cmd, **k)
    if public:
        for r in renderers:
            tick = r.tick

            def plain(inp, tick=tick):
                fields = {f.name: getattr(inp, f.name) for f in dataclasses.fields(TickInput)}
                fields["velocity_mm_s"] = np.array(fields["velocity_mm_s"])
                fields["velocity_mm_s"].flags.writeable = False
                fields["velocity_floats_mm_s"] = None
                return tick(TickInput(**fields))
            r.tick = plain
    return dev, renderers, acts, got


def test_the_fast_paths_send_every_backend_the_same_commands_as_the_public_paths():
    runs = {}
    for public in (False, True):
        dev, renderers, acts, got = _scene(public)
        rep = ServoLoop(dev, renderers, acts, period_s=0.001).run(2.0)
        runs[public] = (rep, got, renderers, acts)
    (fast, got_fast, rs, acts), (slow, got_slow, _, _) = runs[False], runs[True]
    assert set(got_fast) == {"force", "coil", "vibration"}
    for role in got_fast:
        assert len(got_fast[role]) == 2000
        assert got_fast[role] == got_slow[role], role
    for k in fast.log:
        if not k.startswith("compute"):
            assert np.array_equal(fast.log[k], slow.log[k], equal_nan=True), k
    # formula (9) from the logged velocity (an independent path): f = Fpeak |vx| / v_ref,
    # clamped to the renderer's band, then to the piezo's declared range (the safety
    # layer), on every tick that played
    lo, hi = acts["vibration"].limits.frequency_range_hz
    rough = next(r for r in rs if type(r).__name__ == "RoughnessRenderer")
    on = fast.log["vibration.amplitude"] > 0.0
    assert 200 < on.sum() < 2000
    vx = fast.log["velocity_mm_s"][on, 0]
    f = np.clip(np.clip(rough.fpeak_hz * np.abs(vx) / rough.v_ref_mm_s, rough.f_lo, rough.f_hi), lo, hi)
    assert np.array_equal(fast.log["vibration.frequency_hz"][on], f)


class _Keeps(DimensionRenderer):
    """Keeps each input and its fields as the loop handed it (before anything read it)."""
    roles = ("force",)

    def __init__(self):
        self.seen = []

    def tick(self, inp):
        self.seen.append((inp, list(vars(inp).items())))
        return [ChannelCommand("force", 0.3 * inp.penetration_mm if inp.in_contact else 0.0)]


@pytest.mark.parametrize("where", ["plane", "spatial"])
def test_the_loop_input_is_the_object_its_constructor_makes(where):
    """The loop stores the input's fields itself, in the order TickInput's __init__ stores
    them (the array as the unbuilt ``_va``): a new object per tick, equal field by field
    and in order to what ``_LoopInput(...)`` makes of the same values."""
    from hapticsdk.runtime.loop import _LoopInput
    assert not hasattr(TickInput, "__post_init__") and "__slots__" not in vars(TickInput)
    keeps = _Keeps()
    if where == "plane":
        loop = ServoLoop(VirtualProbe(trajectory=press_slide()), [keeps], passivity=False)
    else:
        tr = Trajectory([(0.0, -30.0, 5.0), (0.2, -10.0, -1.0), (0.6, 30.0, -1.0), (1.0, 30.0, 5.0)])
        loop = ServoLoop(VirtualProbe(trajectory=tr), (), passivity=False, objects=[("ball", [keeps])],
                         hit_tester=HitTester([("ball", Sphere(20.0, pose=Pose((0.0, -19.0, 0.0))))]))
    loop.run(1.0)
    assert len(keeps.seen) > 150 and len({id(inp) for inp, _ in keeps.seen}) == len(keeps.seen)
    for inp, items in keeps.seen:
        d = dict(items)
        made = _LoopInput(d["t"], d["dt"], d["penetration_mm"], None, d["in_contact"], d["normal"], d["object"],
                          d["velocity_filtered_mm_s"], d["speed_step_mm_s"], d["velocity_floats_mm_s"])
        assert type(inp) is _LoopInput and items == list(vars(made).items())
        assert repr(inp) == repr(made) and np.array_equal(inp.velocity_mm_s, made.velocity_mm_s)

"""Record a run on a simulated device, play it back as a device, get the same forces."""

from __future__ import annotations

import numpy as np
import pytest

from hapticsdk.devices.actuators import ActuatorLimits, DeviceState, HapticDevice
from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer, TickInput
from hapticsdk.errors import DeviceError, RecordingError
from hapticsdk.runlog import PlaybackDevice, RunRecorder, load_run

PERIOD = 0.001


class SpringRenderer(DimensionRenderer):
    """F = k * penetration (N) while in contact, 0 outside."""

    roles = ("force",)

    def __init__(self, k_n_per_mm: float) -> None:
        self.k = k_n_per_mm

    def tick(self, inp: TickInput) -> list[ChannelCommand]:
        return [ChannelCommand("force", force_n=self.k * max(inp.penetration_mm, 0.0))]


class PushedProbe(HapticDevice):
    """1-D probe (mass 0.05 kg, damping 2 N s/m) pushed down by a hand force that
    rises and falls, pushed back by the last commanded force: the path depends on the
    rendered forces, so a replay that is off by one tick gives different forces."""

    name = "test-pushed-probe"
    simulated = True
    limits = ActuatorLimits(max_force_n=3.3, max_stiffness_n_per_mm=2.3, max_velocity_mm_s=1000.0)

    def _open(self):
        self.t = 0.0
        self.y = 0.5  # mm above the surface
        self.v = 0.0
        self.f = 0.0

    def _read_state(self):
        return DeviceState(t=self.t, position_mm=np.array([0.0, self.y, 0.0]),
                           velocity_mm_s=np.array([0.0, self.v, 0.0]), force_n=np.array([0.0, self.f, 0.0]))

    def _command(self, cmd):
        self.f = cmd.force_n

    def _stop(self):
        self.f = 0.0

    def _step(self, dt):
        hand = -2.5 * np.sin(np.pi * min(self.t / 0.6, 1.0))  # N, downwards
        acc = (hand + self.f - 2.0 * self.v * 1e-3) / 0.05  # m/s^2
        self.v += acc * dt * 1e3  # mm/s
        self.y += self.v * dt
        self.t += dt


def run_loop(device, renderer, n_ticks, recorder=None, step_first=False):
    """Minimal servo loop: read, observe, render, command, record, step."""
    forces = []
    with device:
        for k in range(n_ticks):
            t = k * PERIOD
            if step_first and k > 0:
                device.step(PERIOD)
            st = device.read_state()
            device.safety.observe(st)
            inp = TickInput(t=t, dt=PERIOD, penetration_mm=st.penetration_mm,
                            velocity_mm_s=st.velocity_mm_s, in_contact=st.penetration_mm > 0)
            sent = {c.role: device.command(c, now=t) for c in renderer.tick(inp)}
            forces.append(sent["force"].force_n)
            if recorder is not None:
                recorder.record(t, st, sent)
            if not step_first:
                device.step(PERIOD)
    if recorder is not None:
        recorder.close()
    return np.array(forces)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    path = tmp_path_factory.mktemp("run") / "press"
    dev = PushedProbe()
    rec = RunRecorder(path, device=dev, meta={"scene": "spring 1.8 N/mm"})
    forces = run_loop(dev, SpringRenderer(1.8), 800, rec)
    return rec.path, forces, dev


def test_run_file_round_trip(recorded):
    path, forces, dev = recorded
    assert path.suffix == ".npz" and path.is_file()
    run = load_run(path)
    assert len(run) == 800 and run.roles == ["force"]
    assert run.period_s == pytest.approx(PERIOD)
    assert run.header["device"]["limits"]["max_force_n"] == 3.3
    assert run.header["device"]["safety_settings"]["ramp_time_s"] == dev.safety.settings.ramp_time_s
    assert run.header["meta"]["scene"] == "spring 1.8 N/mm"
    np.testing.assert_array_equal(run.commands["force"]["force_n"], forces)
    assert np.nanmax(-run.position_mm[:, 1]) > 0.5  # the probe did press in
    assert forces.max() > 0.5 and run.summary()["roles"]["force"]["force_n"]["ticks"] == 800


def test_playback_reproduces_forces_sample_for_sample(recorded):
    path, forces, _ = recorded
    dev = PlaybackDevice(run=path)
    replay = run_loop(dev, SpringRenderer(1.8), 800)
    np.testing.assert_array_equal(replay, forces)
    np.testing.assert_array_equal(dev.received_array("force_n"), forces)
    assert dev.finished and dev.limits.max_force_n == 3.3


def test_playback_is_order_independent(recorded):
    """A loop that steps before reading still sees tick 0 first."""
    path, forces, _ = recorded
    replay = run_loop(PlaybackDevice(run=path), SpringRenderer(1.8), 800, step_first=True)
    np.testing.assert_array_equal(replay, forces)


def test_playback_detects_a_changed_renderer(recorded):
    """The comparison is sharp: a 1 % stiffer spring does not reproduce the run."""
    path, forces, _ = recorded
    replay = run_loop(PlaybackDevice(run=path), SpringRenderer(1.8 * 1.01), 800)
    assert not np.array_equal(replay, forces)
    assert np.max(np.abs(replay - forces)) > 1e-3


def test_playback_end_of_run(recorded):
    path, _, _ = recorded
    dev = PlaybackDevice(run=path, at_end="error")
    with pytest.raises(DeviceError):
        run_loop(dev, SpringRenderer(1.8), 801)
    held = PlaybackDevice(run=path)
    run_loop(held, SpringRenderer(1.8), 810)
    assert held.finished and held.index == 799


def test_playback_via_entry_point(recorded):
    from hapticsdk.devices.actuators import create_actuator
    try:
        dev = create_actuator("playback-virtual", run=str(recorded[0]))
    except Exception as exc:  # core not (re)installed with the entry point
        pytest.skip(f"entry point not installed: {exc}")
    assert isinstance(dev, PlaybackDevice)


def test_roles_appearing_late_are_padded(tmp_path):
    rec = RunRecorder(tmp_path / "r.npz")
    st = DeviceState(t=0.0, position_mm=np.zeros(3), velocity_mm_s=np.zeros(3))
    rec.record(0.0, st, {"force": ChannelCommand("force", force_n=1.0)})
    rec.record(0.001, st, {"force": ChannelCommand("force", force_n=2.0),
                           "coil": ChannelCommand("coil", frequency_hz=60.0, amplitude=0.5)})
    rec.record(0.002, None, {})
    run = load_run(rec.close())
    assert np.isnan(run.commands["coil"]["frequency_hz"][0]) and run.commands["coil"]["amplitude"][1] == 0.5
    assert np.isnan(run.commands["force"]["force_n"][2]) and np.isnan(run.position_mm[2]).all()
    assert run.command("coil", 1) == ChannelCommand("coil", frequency_hz=60.0, amplitude=0.5)
    assert run.command("coil", 0).frequency_hz is None


def test_runs_longer_than_a_block_keep_every_tick_in_order(tmp_path, monkeypatch):
    """The recorder stores rows in fixed-size blocks: with blocks of 3 ticks, 20 ticks
    (roles starting late, missing on some ticks, states missing, short vectors) come
    back value for value, as an independently kept list of what was recorded says."""
    import hapticsdk.runlog as rl
    monkeypatch.setattr(rl._Rows, "BLOCK", 3)
    rec = RunRecorder(tmp_path / "long.npz")
    want_pos, want_coil, want_force, want_buttons = [], [], [], []
    for k in range(20):
        st = None if k % 7 == 6 else DeviceState(t=k * 1e-3 + 1e-5, position_mm=np.array([k, -k, 2.0 * k]),
                                                 velocity_mm_s=(1.0, 2.0) if k == 4 else np.ones(3),
                                                 buttons=k % 4)
        sent = {}
        if k % 5 != 2:
            sent["force"] = ChannelCommand("force", force_n=0.1 * k)
        if k >= 8 and k % 3:
            sent["coil"] = ChannelCommand("coil", frequency_hz=50.0 + k, amplitude=0.5)
        rec.record(k * 1e-3, st, sent)
        want_pos.append([np.nan] * 3 if st is None else [k, -k, 2.0 * k])
        want_force.append(0.1 * k if "force" in sent else np.nan)
        want_coil.append(50.0 + k if "coil" in sent else np.nan)
        want_buttons.append(0 if st is None else k % 4)
    run = load_run(rec.close())
    assert len(run) == 20 and np.array_equal(run.t, np.arange(20) * 1e-3)
    assert np.array_equal(run.position_mm, np.array(want_pos), equal_nan=True)
    assert np.array_equal(run.commands["force"]["force_n"], np.array(want_force), equal_nan=True)
    assert np.array_equal(run.commands["coil"]["frequency_hz"], np.array(want_coil), equal_nan=True)
    assert run.buttons.tolist() == want_buttons and run.buttons.dtype == np.int64
    assert run.velocity_mm_s[4, :2].tolist() == [1.0, 2.0] and np.isnan(run.velocity_mm_s[4, 2])
    assert np.array_equal(run.state_t[[0, 6]], [1e-5, np.nan], equal_nan=True)
    assert run.header["roles"] == ["coil", "force"] and run.header["n_ticks"] == 20


def test_broken_run_files_are_named(tmp_path):
    with pytest.raises(RecordingError, match="not found"):
        load_run(tmp_path / "missing.npz")
    bad = tmp_path / "bad.npz"
    np.savez(bad, t=np.zeros(3))
    with pytest.raises(RecordingError, match="header_json"):
        load_run(bad)


# -- with the SDK's servo loop ------------------------------------------------------
def test_servo_loop_record_and_playback_same_forces(tmp_path):
    from hapticsdk.runtime import ServoLoop

    dev = PushedProbe()
    rec = RunRecorder(tmp_path / "loop.npz", device=dev)
    report = ServoLoop(dev, [SpringRenderer(2.0)], period_s=PERIOD, recorder=rec).run(0.8)
    rec.close()
    dev.close()
    run = load_run(rec.path)
    assert len(run) == report.ticks == 800
    np.testing.assert_array_equal(run.commands["force"]["force_n"], report.log["force_n"])
    assert report.log["force_n"].max() > 0.5  # the spring was felt

    play = PlaybackDevice(run=rec.path)
    replay = ServoLoop(play, [SpringRenderer(2.0)], period_s=PERIOD).run(0.8)
    np.testing.assert_array_equal(replay.log["force_n"], report.log["force_n"])
    np.testing.assert_array_equal(replay.log["position_mm"], run.position_mm)
    play.close()

"""Host-side command deadline of the DRV2667 backends (issue 13, item 4).

A stalled servo loop (a renderer sleeping 300 ms) must not leave the piezo playing:
the actuator's watchdog thread puts the emulated DRV2667 in standby once no command
arrived for the deadline, and the chip plays again when commands resume. A transport
that fails (MCP2221A unplugged or timing out, serial bridge silent) is reported (the
actuator is faulted, the next command raises) and the standby write is retried until
the link takes it.

Bounds: the deadline is ``describe()["watchdog"]["deadline_s"]``. The standby must not
come before the deadline (a thread is never early, however busy the machine), and it
must come while the loop is stalled: the stall lasts until the chip is seen in standby
(at most ``WAIT_S``), so a watchdog that never trips fails and one that trips late does
not. How late after the deadline it comes is how soon this machine runs the watchdog
thread: a figure of ``bench/bench_stop_paths.py`` (its "loop stall" row, from the last
command), not a bound here (it was once: deadline + the standby write + a switch interval
+ 20 ms of scheduling allowance). The retry schedule of a failing standby write is
checked on the watchdog itself, with a bound from the schedule's own steps
(``tests/runtime/test_watchdog_publish.py``).
"""

from __future__ import annotations

import sys
import time

import numpy as np
import pytest

from hapticsdk.devices import actuators as core_act
from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer
from hapticsdk.errors import DeviceError, ValidationError
from hapticsdk.runtime import ServoLoop
from hapticsdk.sim.finger import press_slide
from hapticsdk.sim.probe import VirtualProbe
from hapticsdk_roughness.dimension import RoughnessDimension
from hapticsdk_roughness.emulation import SerialBridgeEmulator
from hapticsdk_roughness.hardware import PiezoMCP2221, PiezoSerial

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="pty tests need POSIX")
pytest.importorskip("serial")
pytest.importorskip("usb")

from hapticsdk_roughness.usb_emulation import EmulatedMCP2221, MCP2221Backend  # noqa: E402

#: how long a test waits for a state it then asserts: a bound on a stuck test, not a
#: measurement (the timing bounds are asserted separately), so generous for a busy machine
WAIT_S = 10.0


class TimedSerial(PiezoSerial):
    """Records when the last command finished (s)."""

    t_last = 0.0

    def _command(self, cmd):
        super()._command(cmd)
        self.t_last = time.monotonic()


class TimedMCP(PiezoMCP2221):
    t_last = 0.0

    def _command(self, cmd):
        super()._command(cmd)
        self.t_last = time.monotonic()


@pytest.fixture
def rig():
    made = []

    def make(kind, **opts):
        if kind == "serial":
            emu = SerialBridgeEmulator(watchdog_s=0).start()     # firmware watchdog off: host only
            # a reply budget of 0.5 s, not the board's 0.05 s: the emulated bridge answers
            # from a thread of this test process, which a stalled loop's polling and a
            # loaded machine can keep off a CPU for longer than 2 x 0.05 s (the standby
            # write then failed once, next to two busy loops, and faulted the actuator)
            act = TimedSerial(port=emu.port, timeout=0.5, retries=1, **opts)
            made.append((act, emu))
            return act, emu.drv, emu
        board = EmulatedMCP2221("WD1")
        act = TimedMCP(backend=MCP2221Backend([board]), timeout_ms=20, **opts)
        made.append((act, None))
        return act, board.drv, board

    yield make
    for act, emu in made:
        act.close()
        if emu is not None:
            emu.stop()


def _cmd(a=10.0, f=120.0):
    return ChannelCommand("vibration", frequency_hz=f, amplitude=a)


class StallingRenderer(DimensionRenderer):
    """The roughness renderer, stalled once at ``at_s`` until the emulated chip is seen in
    standby or ``max_s`` passed (polling the chip while stalled), then again rendering
    normally. ``t_zero``: when the chip was first seen silent during the stall."""

    roles = ("vibration",)

    def __init__(self, inner, act, drv, at_s=0.25, max_s=WAIT_S):
        self.inner, self.act, self.drv, self.at_s, self.max_s = inner, act, drv, at_s, max_s
        self.stalled = False
        self.driving_at_stall = None
        self.t_stall = self.t_zero = None
        self.standby_seen = False
        self.after = []

    def tick(self, inp):
        # stall on the first tick from at_s on where the chip plays (a loaded machine may
        # have cut it a moment before by a watchdog trip after a preempted tick)
        if not self.stalled and inp.t >= self.at_s and self.drv.driving:
            self.stalled = True
            self.t_stall = time.monotonic()
            self.t_last_cmd = self.act.t_last
            self.driving_at_stall = True
            while time.monotonic() - self.t_stall < self.max_s:   # waits for what is asserted
                if self.t_zero is None and not self.drv.driving:
                    self.t_zero = time.monotonic()
                if self.drv.standby:      # written by the host (the chip's own stop is no standby)
                    self.standby_seen = True
                    break
                time.sleep(0.0002)
        elif self.stalled:
            o = self.drv.output()
            self.after.append(o["playing"] and o["amplitude_v"] > 1.0)
        return self.inner.tick(inp)


@pytest.mark.parametrize("kind", ["serial", "usb"])
def test_stalled_loop_puts_the_chip_in_standby_after_the_deadline(rig, kind):
    act, drv, _ = rig(kind)
    probe = VirtualProbe(trajectory=press_slide(press_s=0.05, hold_s=0.05, slide_s=1.0))
    inner = RoughnessDimension().renderer({"Fpeak": 100.0, "AFpeak": 2.0})
    r = StallingRenderer(inner, act, drv)
    with act:
        ServoLoop(probe, [r], {"vibration": act}, realtime=True, period_s=0.001).run(0.5)
        wd = act.describe()["watchdog"]
    deadline = wd["deadline_s"]
    assert r.driving_at_stall, "premise: the piezo played when the loop stalled"
    assert r.standby_seen and r.t_zero is not None, f"no standby {WAIT_S:g} s into the stall"
    age = r.t_zero - r.t_last_cmd
    assert deadline <= age + 1e-3, f"standby {age * 1e3:.1f} ms after the last command, before the deadline"
    # the stall's trip; a loaded machine may add one where a tick was preempted past the
    # deadline (counted, and the chip woke again)
    assert wd["trips"] >= 1 and wd["failures"] == 0 and wd["wakes"] >= 1
    # commands resumed: the chip plays again (ramped up from 0)
    assert any(r.after), "the chip did not wake when commands resumed"
    assert drv.standby and not drv.driving        # closed: standby


@pytest.mark.parametrize("kind", ["serial", "usb"])
def test_no_trip_while_commands_keep_coming(rig, kind):
    act, drv, _ = rig(kind)
    # the documented deadline: max(watchdog_s = 10 ms, 3 periods of 1 ms)
    deadline = max(0.010, 3 * 0.001)
    late = 0
    with act:
        t0 = time.monotonic()
        last_start = None
        while time.monotonic() - t0 < 0.15:
            start = time.monotonic()
            act.command(_cmd())
            end = time.monotonic()
            # the watchdog stamps each command somewhere within its call, so the gap it
            # sees between two commands is at most this call's end less the last call's
            # start: a gap longer than the deadline there is this test's own (preempted)
            late += last_start is not None and end - last_start > deadline
            last_start = start
            time.sleep(0.001)
        assert drv.driving
        wd = act.describe()["watchdog"]
        # and the time from the last command to the watchdog's figures read just now
        late += time.monotonic() - last_start > deadline
    # no trip unless the test's own command stream had a gap longer than the deadline
    assert wd["trips"] <= late and wd["wakes"] == wd["trips"]


def test_deadline_follows_the_servo_period_and_cannot_be_turned_off(rig):
    act, _, _ = rig("usb", watchdog_s=0.005)
    act.safety.set_period(0.004)                  # the loop tells the safety layer its period
    assert act.command_deadline_s() == pytest.approx(0.012)
    act.safety.set_period(0.001)
    assert act.command_deadline_s() == pytest.approx(0.005)
    for bad in (0, 0.0001, 1.0, float("nan"), "off"):
        with pytest.raises(ValidationError) as ei:
            PiezoMCP2221(backend=MCP2221Backend([]), watchdog_s=bad)
        assert ei.value.field == "options.watchdog_s"


@pytest.mark.parametrize("knob", ["unplugged", "stalled"])
def test_mcp2221_failure_is_reported_and_standby_retried_until_it_lands(rig, knob):
    act, drv, board = rig("usb")
    act.open()
    for _ in range(20):
        act.command(_cmd())
    assert drv.driving
    setattr(board, knob, True)
    t0 = time.monotonic()
    while time.monotonic() - t0 < WAIT_S and act.describe()["watchdog"]["failures"] == 0:
        time.sleep(0.001)
    wd = act.describe()["watchdog"]
    assert wd["failures"] >= 1 and wd["trips"] == 0 and "standby write failed" in str(act.fault)
    assert not drv.standby        # nothing reached the chip (it stops by itself: test_roughness_deadman.py)
    with pytest.raises(DeviceError) as ei:        # reported to the servo thread
        act.command(_cmd())
    assert ei.value.device == act.label
    n_failed = act.describe()["watchdog"]["failures"]
    setattr(board, knob, False)   # the link takes writes again: the retry lands
    t1 = time.monotonic()
    while time.monotonic() - t1 < WAIT_S and not (drv.standby and act.describe()["watchdog"]["trips"]):
        time.sleep(0.0005)
    assert not drv.driving and drv.standby
    # when the retry lands is the schedule's (checked on the watchdog itself, see the
    # module doc) plus this machine's scheduling: not bounded here
    assert act.describe()["watchdog"]["trips"] == 1 and act.describe()["watchdog"]["failures"] >= n_failed


def test_serial_bridge_silent_then_back(rig):
    act, drv, emu = rig("serial")
    act.open()
    for _ in range(20):
        act.command(_cmd())
    assert drv.driving
    emu.mute = True
    t0 = time.monotonic()
    while time.monotonic() - t0 < WAIT_S and act.describe()["watchdog"]["failures"] == 0:
        time.sleep(0.001)
    assert act.describe()["watchdog"]["failures"] >= 1 and act.fault is not None
    assert not drv.standby                      # nothing reached the chip
    emu.mute = False
    t1 = time.monotonic()
    while time.monotonic() - t1 < WAIT_S and not (drv.standby and not drv.driving):
        time.sleep(0.0005)
    assert drv.standby and not drv.driving


def test_serial_cable_pulled_host_reports_and_firmware_watchdog_cuts(rig):
    """The pty is closed: no host write can reach the chip. The host watchdog reports the
    failure; the bridge firmware's own watchdog (here 0.1 s) is what stops the piezo."""
    emu = SerialBridgeEmulator(watchdog_s=0.1).start()
    act = TimedSerial(port=emu.port, timeout=0.05, retries=1)
    try:
        act.open()
        for _ in range(20):
            act.command(_cmd())
        assert emu.drv.driving
        emu.unplug()
        t0 = time.monotonic()
        while time.monotonic() - t0 < WAIT_S and act.describe()["watchdog"]["failures"] == 0:
            time.sleep(0.001)
        assert act.describe()["watchdog"]["failures"] >= 1 and act.fault is not None
        # the chip stops by itself sooner; standby: firmware (waits for what it asserts)
        while time.monotonic() - t0 < WAIT_S and not (emu.drv.standby and emu.watchdog_trips >= 1):
            time.sleep(0.001)
        assert not emu.drv.driving and emu.watchdog_trips >= 1
    finally:
        act.close()
        emu.stop()


def test_watchdog_thread_ends_on_close(rig):
    import threading
    act, _, _ = rig("usb", label="watchdog-close-test")
    act.open()
    act.command(_cmd())
    names = {t.name for t in threading.enumerate()}
    assert f"watchdog {act.label}" in names
    act.close()
    t0 = time.monotonic()
    while time.monotonic() - t0 < WAIT_S and f"watchdog {act.label}" in {t.name for t in threading.enumerate()}:
        time.sleep(0.005)
    assert f"watchdog {act.label}" not in {t.name for t in threading.enumerate()}
    assert act not in set(core_act._OPEN_ACTUATORS)
    assert np.isfinite(act.describe()["watchdog"]["deadline_s"])


@pytest.mark.parametrize("kind", ["serial", "usb"])
def test_wake_after_a_trip_never_replays_the_old_amplitude(rig, kind):
    """After a watchdog standby the first command must silence the waveform's amplitude
    byte before GO, then ramp up: GO with the old 10 V chunk would replay it at once."""
    from hapticsdk_roughness import drv2667 as d
    act, drv, _ = rig(kind)
    act.open()
    for _ in range(20):
        act.command(_cmd(a=10.0))
    t0 = time.monotonic()
    while time.monotonic() - t0 < WAIT_S and act.describe()["watchdog"]["trips"] == 0:
        time.sleep(0.001)     # waits for what it asserts (the trip; standby comes with it)
    assert drv.standby and act.describe()["watchdog"]["trips"] == 1
    n0 = len(drv.writes())
    act.command(_cmd(a=10.0))
    new = drv.writes()[n0:]
    go = [i for i, w in enumerate(new) if w[0] == d.REG_CONTROL2 and w[1] & d.CTRL2_GO]
    chunk = [i for i, w in enumerate(new) if w[0] == d.CHUNK_ADDR]
    assert go, "the command after the trip did not wake the chip"
    before = [new[i] for i in chunk if i < go[0]]
    assert before and before[-1][1] == 0, f"GO with a non-zero amplitude byte: {new}"
    assert drv.output()["amplitude_v"] <= 25.0 * act.period_s / act.ramp_s + 0.1   # one ramp step
    act.close()


def test_served_board_answers_its_reports_and_an_unplug_as_a_usb_error():
    """A :class:`BoardServer` board used from a pickled stand-in (as a servo process uses
    it): reports reach the served board and come back; once it is unplugged, a report
    raises the ``USBError`` errno 19 a real pulled board raises."""
    import pickle

    import usb.core
    from hapticsdk_roughness import mcp2221 as m
    from hapticsdk_roughness.usb_emulation import BoardServer

    board = EmulatedMCP2221("SRV1")
    server = BoardServer(board)
    try:
        remote = pickle.loads(pickle.dumps(server.remote()))
        status = bytes([m.CMD_STATUS]) + bytes(63)
        assert remote.handle(status)[0] == m.CMD_STATUS and board.reports[-1] == status
        board.unplugged = True
        with pytest.raises(usb.core.USBError) as ei:
            remote.handle(status)
        assert ei.value.errno == 19 and len(board.reports) == 1     # nothing reached the board
    finally:
        server.close()

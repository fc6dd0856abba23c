"""DRV2667 over the serial bridge (real pyserial on a pty) and the MCP2221A (real pyusb with
an emulating backend): register bytes on the wire, init errors, fault injection, safe state."""

from __future__ import annotations

import os
import sys
import time

import numpy as np
import pytest

from hapticsdk.devices import actuators as core_act
from hapticsdk.perception.dimensions import ChannelCommand, TickInput
from hapticsdk.errors import DeviceError, DeviceNotFoundError, SafetyError, TransportError
from hapticsdk_roughness import bridge_protocol as bp
from hapticsdk_roughness.dimension import RoughnessDimension
from hapticsdk_roughness.drv2667 import DRV2667, SynthChunk
from hapticsdk_roughness.emulation import SerialBridgeEmulator
from hapticsdk_roughness.hardware import PiezoMCP2221, PiezoSerial
from hapticsdk_roughness.serial_bridge import SerialBridgeBus

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="pty tests need POSIX")
pytest.importorskip("serial")
pytest.importorskip("usb")

from hapticsdk_roughness.usb_emulation import EmulatedMCP2221, MCP2221Backend  # noqa: E402

FAST = dict(timeout=0.1, retries=2)   # generous: CI machines are loaded


@pytest.fixture
def emus():
    """Every emulated DRV2667 made in a test; the test FAILS if one is left driving, or if
    an open actuator of this process is left driving."""
    made: list = []
    bridges: list = []

    def bridge(**kw):
        b = SerialBridgeEmulator(**kw).start()
        bridges.append(b)
        made.extend(b.targets.values())
        return b

    def boards(*serials):
        bs = [EmulatedMCP2221(s) for s in serials]
        made.extend(b.drv for b in bs)
        return MCP2221Backend(bs)

    yield bridge, boards
    try:
        driving_acts = [a.label for a in list(core_act._OPEN_ACTUATORS) if getattr(a, "driving", False)]
        deadline = time.monotonic() + 1.0          # the bridge watchdog may need up to watchdog_s
        while any(e.driving for e in made) and time.monotonic() < deadline:
            time.sleep(0.02)
        left = [i for i, e in enumerate(made) if e.driving]
        assert not driving_acts, f"actuators left driving: {driving_acts}"
        assert not left, f"emulated DRV2667 #{left} left driving"
    finally:
        for a in list(core_act._OPEN_ACTUATORS):
            a.close()
        for b in bridges:
            b.stop()


def cmd(f=100.0, a=10.0):
    return ChannelCommand("vibration", frequency_hz=f, amplitude=a)


def _piezo(emus, kind, board, **opts):
    """(actuator, its emulated DRV2667): a PiezoSerial on a new emulated bridge (``kind ==
    "serial"``) or a PiezoMCP2221 on one emulated board with USB serial ``board``."""
    bridge, boards = emus
    if kind == "serial":
        emu = bridge()
        return PiezoSerial(port=emu.port, **opts, **FAST), emu.drv
    be = boards(board)
    return PiezoMCP2221(backend=be, **opts), be.boards[0].drv


# -- bytes on the wire -------------------------------------------------------------------
WAVE = [SynthChunk(amplitude=0x80, frequency=32, cycles=5, envelope=0x12),
        SynthChunk(amplitude=0xFF, frequency=25, cycles=10, envelope=0x00)]
#: page-1 header for one waveform of 2 chunks at 0x06..0x0D (datasheet layout), then the chunks
EXPECTED = [bytes([0xFF, 0x01]),
            bytes([0x00, 0x05, 0x80, 0x06, 0x00, 0x0D, 0x00, 0x80, 32, 5, 0x12, 0xFF, 25, 10, 0x00]),
            bytes([0xFF, 0x00]),
            bytes([0x03, 0x01, 0x00]),
            bytes([0x02, 0x0D])]


def test_serial_wire_bytes_match_drv2667_writes(emus):
    bridge, _ = emus
    emu = bridge()
    bus = SerialBridgeBus(emu.port, **FAST).open()
    try:
        drv = DRV2667(bus)
        drv._page = 0
        n0 = len(emu.requests)
        drv.load_synthesis(WAVE)
        drv.go()
        frames = emu.requests[n0:]
        assert [f.cmd for f in frames] == [bp.CMD_I2C_WRITE] * len(EXPECTED)
        assert [f.payload for f in frames] == [bytes([0x59]) + e for e in EXPECTED]
        assert emu.drv.writes()[-len(EXPECTED):] == EXPECTED
        out = emu.drv.output()
        assert out["playing"] and out["frequency_hz"] == 250.0
        assert out["amplitude_v"] == pytest.approx(0x80 / 255 * 25.0)
        drv.standby()
        assert not emu.drv.driving
        # framing of one request on the wire: A5 LEN SEQ CMD PAYLOAD CRC16
        raw = bp.Frame(7, bp.CMD_I2C_WRITE, bytes([0x59, 0x02, 0x40])).encode()
        assert raw[:4] == bytes([0xA5, 3, 7, 0x10]) and bp.crc16(raw[1:-2]) == int.from_bytes(raw[-2:], "big")
    finally:
        bus.close()


def test_usb_wire_bytes_match_drv2667_writes(emus):
    _, boards = emus
    be = boards("S1")
    from hapticsdk_roughness.mcp2221 import MCP2221Bus
    bus = MCP2221Bus(backend=be).open()
    try:
        board = be.boards[0]
        assert board.divider == 27                               # 400 kHz: 12 MHz / 400 kHz - 3
        drv = DRV2667(bus)
        drv._page = 0
        n0 = len(board.reports)
        drv.load_synthesis(WAVE)
        drv.go()
        writes = [r for r in board.reports[n0:] if r[0] == 0x90]
        assert len(writes) == len(EXPECTED)
        for rep, exp in zip(writes, EXPECTED):
            assert len(rep) == 64
            assert rep[1:4] == bytes([len(exp), 0, 0x59 << 1])
            assert rep[4:4 + len(exp)] == exp
        assert board.drv.writes()[-len(EXPECTED):] == EXPECTED
        assert drv.status() & 0x02                               # FIFO empty, read via 0x94/0x93/0x40
        drv.standby()
    finally:
        bus.close()


def test_fifo_streaming_handles_full_fifo_nak(emus):
    bridge, _ = emus
    emu = bridge()
    bus = SerialBridgeBus(emu.port, **FAST).open()
    try:
        drv = DRV2667(bus)
        wave = 20.0 * np.sin(2 * np.pi * 200.0 * np.arange(400) / 8000.0)
        samples = DRV2667.to_fifo_samples(wave, 25.0)
        assert drv.stream_fifo(samples) == len(samples)
        assert bytes(emu.drv.fifo_log) == samples                 # every sample once, in order
        drv.standby()
    finally:
        bus.close()


# -- end-to-end render through the hardware backends ---------------------------------------
@pytest.mark.parametrize("kind", ["serial", "usb"])
def test_render_speed_following_on_hardware_backend(emus, kind):
    act, drv_emu = _piezo(emus, kind, "S1", gain=1)
    r = RoughnessDimension().renderer({"Fpeak": 100.0, "AFpeak": 2.0})
    with act:
        for vx in (40.0, 120.0, 10.0):
            for k in range(12):
                (c,) = r.tick(TickInput(0.0, 0.001, 1.0, np.array([vx, 0, 0]), True))
                act.command(c)
            out = drv_emu.output()
            if vx < 20:
                assert out["amplitude_v"] == 0.0
            else:
                assert out["frequency_hz"] == pytest.approx(100.0 * vx / 80.0, abs=7.8125 / 2)
                assert out["amplitude_v"] == pytest.approx(r.v_out, abs=50.0 / 255)
    assert drv_emu.standby and not drv_emu.driving


def test_two_boards_by_serial_number(emus):
    bridge, boards = emus
    be = boards("LEFT", "RIGHT")
    e1, e2 = bridge(serial_number="B1"), bridge(serial_number="B2")
    # the host watchdog (standby after the command deadline) at its longest: the outputs
    # are read a few ms after the last command
    wd = dict(watchdog_s=0.25)
    acts = [PiezoMCP2221(serial_number="RIGHT", backend=be, **wd), PiezoMCP2221(serial_number="LEFT", backend=be, **wd),
            PiezoSerial(port=e2.port, serial_number="B2", **FAST, **wd),
            PiezoSerial(port=e1.port, serial_number="B1", **FAST, **wd)]
    for a in acts:
        a.open()
    chips = [be.boards[1].drv, be.boards[0].drv, e2.drv, e1.drv]   # where each act's commands must land
    for i, (a, chip) in enumerate(zip(acts, chips)):
        # a busy machine may hold this thread past the watchdog's deadline between the
        # last command and the read: then the chip is rightly in standby; command again
        # until a read with no trip in between (what is asserted is the routing)
        for _ in range(20):
            trips = a.describe()["watchdog"]["trips"]
            for _ in range(10):
                a.command(cmd(a=5.0 * (i + 1)))
            amp = chip.output()["amplitude_v"]
            if a.describe()["watchdog"]["trips"] == trips:
                break
        assert amp == pytest.approx(5.0 * (i + 1), abs=0.1), a.label
    assert core_act.stop_all()                                    # the atexit hook's function
    assert not any(e.driving for e in (e1.drv, e2.drv, be.boards[0].drv, be.boards[1].drv))
    for a in acts:
        a.close()


# -- init errors name what was tried ---------------------------------------------------------
def test_serial_init_errors_name_what_was_tried(emus, tmp_path):
    bridge, _ = emus
    missing = str(tmp_path / "ttyNOPE0")
    with pytest.raises(DeviceNotFoundError) as ei:
        PiezoSerial(port=missing, **FAST).open()
    assert missing in str(ei.value) and "piezo-serial" in str(ei.value)
    master, slave = os.openpty()                                  # a port with nothing behind it
    try:
        with pytest.raises(DeviceNotFoundError) as ei:
            PiezoSerial(port=os.ttyname(slave), **FAST).open()
        assert os.ttyname(slave) in str(ei.value) and "PING" in str(ei.value)
    finally:
        os.close(master)
        os.close(slave)
    emu = bridge(serial_number="B7")
    with pytest.raises(DeviceNotFoundError) as ei:
        PiezoSerial(port=emu.port, serial_number="B8", **FAST).open()
    assert "'B7'" in str(ei.value) and "'B8'" in str(ei.value)
    emu.targets.clear()                                           # bridge present, no DRV2667 behind it
    with pytest.raises(TransportError) as ei:
        PiezoSerial(port=emu.port, **FAST).open()
    assert "0x59" in str(ei.value) and emu.port in str(ei.value)


def test_a_serial_port_takes_one_owner(emus):
    """One bridge, one owner: while an instance holds the port, a second one (of this
    process or another program) is refused at open() with a DeviceNotFoundError that says
    the port is in use; it opens once the first is closed. Two owners would interleave
    their frames and read each other's replies (a watchdog's standby write then found the
    link "lost" under load)."""
    bridge, _ = emus
    emu = bridge()
    first = PiezoSerial(port=emu.port, **FAST).open()
    second = PiezoSerial(port=emu.port, **FAST)
    try:
        with pytest.raises(DeviceNotFoundError) as ei:
            second.open()
        assert "in use" in str(ei.value) and emu.port in str(ei.value)
        assert first.read_back() is not None          # the first owner is untouched
    finally:
        first.close()
    second.open()
    second.close()


def test_usb_init_errors_name_what_was_tried(emus):
    _, boards = emus
    with pytest.raises(DeviceNotFoundError) as ei:
        PiezoMCP2221(backend=MCP2221Backend([])).open()
    assert "04D8:00DD" in str(ei.value) and "none" in str(ei.value)
    be = boards("X1")
    with pytest.raises(DeviceNotFoundError) as ei:
        PiezoMCP2221(serial_number="X2", backend=be).open()
    assert "'X2'" in str(ei.value) and "X1" in str(ei.value)
    be.boards[0].targets.clear()
    with pytest.raises(TransportError) as ei:
        PiezoMCP2221(backend=be).open()
    assert "0x59" in str(ei.value) and "NACK" in str(ei.value)


# -- fault injection: safe state + named error ------------------------------------------------
def _run_until_error(act, n=200):
    """Servo-like commands (speed varying, so chunk bytes change) until the actuator raises."""
    for i in range(n):
        act.command(cmd(f=100.0 + 20.0 * (i % 2)))
    raise AssertionError("no error raised")


def test_serial_cable_pulled_mid_render(emus):
    bridge, _ = emus
    emu = bridge(watchdog_s=0.1)
    act = PiezoSerial(port=emu.port, **FAST).open()
    for _ in range(10):
        act.command(cmd())
    assert emu.drv.driving
    emu.unplug()
    with pytest.raises(DeviceError) as ei:
        _run_until_error(act)
    assert ei.value.device == act.label and emu.port in str(ei.value)
    assert act.fault is not None and not act.driving
    t0 = time.monotonic()                                         # bridge watchdog -> standby
    while time.monotonic() - t0 < 10.0 and not (not emu.drv.driving and emu.watchdog_trips >= 1):
        time.sleep(0.005)                                         # (waits for what it asserts)
    assert not emu.drv.driving and emu.watchdog_trips >= 1
    act.close()


def test_serial_bridge_stops_answering(emus):
    bridge, _ = emus
    emu = bridge()
    act = PiezoSerial(port=emu.port, **FAST).open()
    act.command(cmd())
    emu.mute = True
    t0 = time.monotonic()
    with pytest.raises(TransportError) as ei:
        _run_until_error(act)
    assert time.monotonic() - t0 < 2.0
    assert "timeout" in str(ei.value) and act.label in str(ei.value) and not act.driving
    emu.mute = False
    assert act.stop() and emu.drv.standby                          # link back: stop reaches the chip
    act.close()


def test_serial_nak_storm_and_recovered_corruption(emus):
    bridge, _ = emus
    emu = bridge()
    act = PiezoSerial(port=emu.port, **FAST).open()
    emu.corrupt_replies = 1
    emu.garbage = b"\x00\xa5\x07garbage\xa5"
    act.command(cmd(a=5.0))                                       # survives: resent, resynchronised
    assert act.bus.stats["resends"] >= 1
    assert emu.drv.output()["amplitude_v"] == pytest.approx(5.0, abs=0.1)
    emu.nak_all = True
    with pytest.raises(TransportError) as ei:
        _run_until_error(act)
    assert "CRC" in str(ei.value) and act.label in str(ei.value)
    emu.nak_all = False
    act.close()
    assert emu.drv.standby


@pytest.mark.parametrize("kind", ["serial", "usb"])
def test_overcurrent_flag_stops_and_names_device(emus, kind):
    act, drv_emu = _piezo(emus, kind, "OC", status_interval_s=0.001)
    act.open()
    for _ in range(5):
        act.command(cmd())
    drv_emu.inject_overcurrent()
    with pytest.raises(SafetyError) as ei:
        _run_until_error(act)
    assert "overcurrent" in str(ei.value) and ei.value.device == act.label
    assert drv_emu.standby and not act.driving
    act.close()


def test_usb_unplug_and_stall(emus):
    _, boards = emus
    be = boards("U1", "U2")
    a1 = PiezoMCP2221(serial_number="U1", backend=be).open()
    a2 = PiezoMCP2221(serial_number="U2", backend=be, timeout_ms=5).open()
    for _ in range(10):
        a1.command(cmd())
        a2.command(cmd())
    be.boards[0].unplugged = True
    with pytest.raises(TransportError) as ei:
        _run_until_error(a1)
    assert "U1" in str(ei.value) and "USB error" in str(ei.value)
    be.boards[1].stalled = True
    with pytest.raises(TransportError) as ei:
        _run_until_error(a2)
    assert "no response" in str(ei.value) and "U2" in str(ei.value)
    assert not a1.driving and not a2.driving
    # the unplugged board lost its USB power with the cable; the stalled one is reachable again
    be.boards[0].drv.regs[0x02] = 0x40
    be.boards[1].stalled = False
    assert a2.stop() and be.boards[1].drv.standby
    a1.close()
    a2.close()


def test_ctrl_c_leaves_piezo_safe(emus):
    bridge, _ = emus
    emu = bridge()
    act = PiezoSerial(port=emu.port, **FAST)
    with pytest.raises(KeyboardInterrupt):
        with act:
            for i in range(20):
                act.command(cmd())
                if i == 10:
                    raise KeyboardInterrupt
    assert emu.drv.standby and not act.is_open


def test_available_and_discover_do_not_raise():
    ok, why = PiezoSerial.check_available()
    assert ok and "pyserial" in why
    ok2, why2 = PiezoMCP2221.check_available()
    assert isinstance(ok2, bool) and why2
    assert isinstance(PiezoSerial.discover(), list)


def test_interpreter_exit_leaves_piezo_in_standby():
    """A script that exits while the piezo plays: the core's atexit stop_all() reaches the
    DRV2667 over the real serial stack (checked by a handler registered before it, so it runs after)."""
    import subprocess
    code = (
        "import atexit\n"
        "state = {}\n"
        "def report():\n"
        "    print('STANDBY' if state['emu'].drv.standby else 'DRIVING', flush=True)\n"
        "atexit.register(report)\n"
        "from hapticsdk.perception.dimensions import ChannelCommand\n"
        "from hapticsdk_roughness.emulation import SerialBridgeEmulator\n"
        "from hapticsdk_roughness.hardware import PiezoSerial\n"
        "emu = SerialBridgeEmulator(watchdog_s=0).start()\n"
        "state['emu'] = emu\n"
        "act = PiezoSerial(port=emu.port, timeout=0.05).open()\n"
        "for i in range(20):\n"
        "    act.command(ChannelCommand('vibration', frequency_hz=100.0, amplitude=10.0))\n"
        "assert emu.drv.driving\n"
        "print('PLAYING', flush=True)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=30)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["PLAYING", "STANDBY"]

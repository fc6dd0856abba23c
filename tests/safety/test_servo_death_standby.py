"""Servo death puts the devices in standby from the application's side (issue 31, item 7).

A live session's servo process is killed with SIGKILL while the piezo plays; the
application's supervisor (:mod:`hapticsdk.runtime.supervisor`) sees the process sentinel,
reopens the transport the dead process released and writes STANDBY. Both transports:
the emulated serial bridge on a pty (its own firmware watchdog switched off, so the
standby can only come from the host) and the emulated MCP2221A served to both processes.
The time is reported, not asserted (a speed goal is a benchmark: see docs/safety.md)."""

from __future__ import annotations

import os
import signal
import time

import pytest

from hapticsdk.runtime.session import Session

emulation = pytest.importorskip("hapticsdk_roughness.emulation")
needs_posix = pytest.mark.skipif(os.name != "posix", reason="POSIX signals and ptys")

SCENE = {"objects": [{"name": "m", "material": {"name": "r", "intensities": {"roughness": 0.6}}}]}


def _kill_while_playing(session, drv):
    t0 = time.monotonic()
    while time.monotonic() - t0 < 60:
        o = drv.output()
        if o["playing"] and o["amplitude_v"] > 1.0:
            break
        time.sleep(0.001)
    else:
        pytest.fail("the piezo never played")
    assert not drv.standby
    t_kill = time.monotonic()
    os.kill(session.servo_pid, signal.SIGKILL)
    while not drv.standby and time.monotonic() - t_kill < 5:
        time.sleep(0.0002)
    seen = time.monotonic() - t_kill
    assert drv.standby and not drv.driving, "no standby after the servo died"
    t0 = time.monotonic()
    while session.servo_death_report is None and time.monotonic() - t0 < 5:
        time.sleep(0.001)
    return seen


@needs_posix
def test_sigkill_of_the_servo_serial_bridge(tmp_path, monkeypatch):
    monkeypatch.setenv("HAPTICSDK_CACHE_DIR", str(tmp_path / "cache"))
    emu = emulation.SerialBridgeEmulator(watchdog_s=0).start()  # no bridge watchdog: only the host
    s = Session({**SCENE, "devices": {"vibration": {"actuator": "piezo-serial"}}},
                # the emulator answers from a thread of this process: on a busy machine its
                # reply can take longer than a bridge's 0.05 s default (the servo's open then
                # failed its PING, 4 attempts, with three CPU-bound processes beside the suite)
                actuator_options={"vibration": {"port": emu.port, "timeout": 0.5}}, refine=False)
    try:
        seen = _kill_while_playing(s, emu.drv)
        rep = s.servo_death_report
        assert rep is not None and "vibration" in rep.standby and not rep.failed, rep
        print(f"serial: standby seen {seen * 1e3:.1f} ms after SIGKILL, written "
              f"{rep.standby['vibration'] * 1e3:.1f} ms after the sentinel")
    finally:
        s.close()


@pytest.fixture
def mcp_session(tmp_path, monkeypatch):
    """A session whose piezo sits behind an emulated MCP2221A served to both processes;
    yields ``(session factory, board)``."""
    usb_emulation = pytest.importorskip("hapticsdk_roughness.usb_emulation")
    monkeypatch.setenv("HAPTICSDK_CACHE_DIR", str(tmp_path / "cache"))
    board = usb_emulation.EmulatedMCP2221("SUP31")
    server = usb_emulation.BoardServer(board)
    sessions = []

    def start():
        sessions.append(Session({**SCENE, "devices": {"vibration": {"actuator": "piezo-mcp2221"}}},
                                actuator_options={"vibration": {
                                    "backend": usb_emulation.MCP2221Backend([server.remote()]),
                                    "serial_number": "SUP31"}}, refine=False))
        return sessions[-1]
    yield start, board
    for s in sessions:
        s.close()
    server.close()


def test_sigkill_of_the_servo_mcp2221(mcp_session):
    start, board = mcp_session
    s = start()
    seen = _kill_while_playing(s, board.drv)
    rep = s.servo_death_report
    assert rep is not None and "vibration" in rep.standby and not rep.failed, rep
    print(f"usb: standby seen {seen * 1e3:.1f} ms after SIGKILL")


def test_a_normal_close_does_not_reopen_the_devices(mcp_session):
    start, board = mcp_session
    s = start()
    s.close()
    assert board.drv.standby
    n = len(board.reports)
    time.sleep(0.2)
    assert s.servo_death_report is None and len(board.reports) == n

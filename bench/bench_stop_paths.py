"""Time until every actuator is at zero, per stop path (docs/safety.md).

``python bench/bench_stop_paths.py [--repeat 10] [--signal-repeat 5] [--json]``

What it measures: for each stop path, the wall time from the stop event to the moment
the emulated DRV2667 (hapticsdk-roughness's register-level emulator, behind the emulated
serial bridge on a pty with real pyserial, or behind the emulated MCP2221A with real
pyusb) stops driving the piezo (standby, GO cleared or amplitude 0). The emulator
timestamps the I2C write that silenced it, or the moment its synthesis sequence ran out
(the finite repeat count, the chip-side dead-man's switch), so no polling latency is
added. The piezo
plays a roughness texture (a realtime 1 kHz servo loop, a kinematic probe sliding at
80 mm/s) when each stop happens.

Stop events (t = 0):

* normal end: the last command of a run (the loop returns; ``with`` closes the actuator);
* exception: the moment a renderer raises KeyboardInterrupt / a simulated device's
  step raises OSError(ENOSPC);
* SIGINT/SIGTERM/SIGHUP: ``os.kill`` on a ``hapticsdk render --scene ...`` subprocess
  driving ``piezo-serial`` (its emulated bridge lives in this process);
* loop stall: the last command before a renderer sleeps 300 ms (the host watchdog);
* unplug: MCP2221A unplugged (every USB transfer fails), from the last command: time
  until the chip stops by itself (its synthesis sequence runs out; the host cannot reach
  it); serial cable pulled (bridge firmware watchdog at 0.25 s), from the pull: time until
  the piezo is silent (the chip's own stop comes first; polled every 1 ms).

What it does not measure: a real chip's I2C/USB/serial latencies (the emulators answer
in microseconds; a real MCP2221A takes about 1 ms per HID report, a serial bridge about
0.1-1 ms per frame at 115200 baud), nor the simulated actuators of the same runs (omni-
virtual, voicecoil-virtual: stopped in-process in the same unwinding, before the
piezo in these runs). The machine may be shared: times include scheduling delays of
other processes. A "failure" is a run where the output never went to zero within 2 s; a signal run
where the piezo was not playing when the signal was sent (the probe's slide had ended on
a loaded machine) or that could not start is not counted (``not_counted``).
"""

from __future__ import annotations

import argparse
import errno
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any, Callable

import numpy as np

from hapticsdk.perception.dimensions import DimensionRenderer
from hapticsdk.runtime import ServoLoop
from hapticsdk.sim.finger import press_slide
from hapticsdk.sim.probe import VirtualProbe
from hapticsdk_roughness.dimension import RoughnessDimension
from hapticsdk_roughness.emulation import DRV2667Emulator, SerialBridgeEmulator
from hapticsdk_roughness.hardware import PiezoMCP2221, PiezoSerial

GIVE_UP_S = 2.0
#: per normal-end run: watchdog trips while commands were flowing, largest command gap
NORMAL_RUNS: list[dict[str, Any]] = []
#: a run that could not be set up (the piezo was not playing when the stop came)
SKIP = -1.0
NOT_PLAYING = "not counted: piezo already silent at the stop event (a watchdog trip after a preempted tick)"


class TimedDRV(DRV2667Emulator):
    """The emulated chip, timestamping each I2C write that silenced it."""

    def __init__(self) -> None:
        super().__init__()
        self.silent_at: list[float] = []

    def i2c_write(self, data: bytes) -> None:
        before = self.driving
        try:
            super().i2c_write(data)
        finally:
            if before and not self.driving:
                self.silent_at.append(time.monotonic())

    def first_silent_after(self, t0: float) -> float | None:
        self.output()                  # bring the sequencer's time model up to now
        later = sorted(t for t in self.silent_at + self.sequence_ends if t >= t0)
        return later[0] if later else None


class _Timed:
    t_last = 0.0
    max_gap = 0.0

    def _command(self, cmd):  # type: ignore[no-untyped-def]
        super()._command(cmd)  # type: ignore[misc]
        now = time.monotonic()
        if self.t_last:
            self.max_gap = max(self.max_gap, now - self.t_last)
        self.t_last = now


class TSerial(_Timed, PiezoSerial):
    pass


class TMCP(_Timed, PiezoMCP2221):
    pass


def _make(transport: str, *, firmware_watchdog_s: float = 0.0) -> tuple[Any, TimedDRV, Any]:
    drv = TimedDRV()
    if transport == "serial":
        emu = SerialBridgeEmulator({0x59: drv}, watchdog_s=firmware_watchdog_s).start()
        return TSerial(port=emu.port, timeout=0.05, retries=1), drv, emu
    from hapticsdk_roughness.usb_emulation import EmulatedMCP2221, MCP2221Backend
    board = EmulatedMCP2221("BENCH1", targets={0x59: drv})
    return TMCP(backend=MCP2221Backend([board]), timeout_ms=20), drv, board


class Scripted(DimensionRenderer):
    """The roughness renderer; at ``at_s`` of servo time calls ``action`` once."""

    roles = ("vibration",)

    def __init__(self, action: Callable[[], None] | None, at_s: float = 0.2) -> None:
        self.inner = RoughnessDimension().renderer({"Fpeak": 100.0, "AFpeak": 2.0})
        self.action, self.at_s, self.done = action, at_s, False
        self.t_event: float | None = None

    def tick(self, inp):  # type: ignore[no-untyped-def]
        if self.action is not None and not self.done and inp.t >= self.at_s:
            self.done = True
            self.action()
        return self.inner.tick(inp)


class Probe(VirtualProbe):
    def __init__(self) -> None:
        super().__init__(trajectory=press_slide(press_s=0.05, hold_s=0.05, slide_s=2.0))
        self.raise_at: float | None = None
        self.t_event: float | None = None
        self.drv: TimedDRV | None = None
        self.playing = False

    def _step(self, dt: float) -> None:
        super()._step(dt)
        if self.raise_at is not None and self.t >= self.raise_at:
            self.raise_at = None
            self.t_event = time.monotonic()
            self.playing = self.drv is not None and self.drv.driving
            raise OSError(errno.ENOSPC, "No space left on device (injected)")


def one_loop_run(transport: str, path: str) -> tuple[float | None, str]:
    """One in-process run of stop path ``path``; returns (seconds to zero or None, note)."""
    act, drv, emu = _make(transport)
    probe = Probe()
    probe.drv = drv
    box: dict[str, float] = {}
    try:
        if path == "normal end":
            r = Scripted(None)
            with act:
                ServoLoop(probe, [r], {"vibration": act}, realtime=True).run(0.3)
                t0 = act.t_last
                playing = drv.driving
                NORMAL_RUNS.append({"transport": transport, "trips": act.describe()["watchdog"]["trips"],
                                    "max_gap_s": act.max_gap})
            if not playing:
                return SKIP, NOT_PLAYING
            t1 = drv.first_silent_after(t0)
            return (None if t1 is None or t1 - t0 > GIVE_UP_S else t1 - t0), ""
        elif path == "exception: KeyboardInterrupt in a renderer":
            def interrupt() -> None:
                box["t0"] = time.monotonic()
                box["playing"] = drv.driving
                raise KeyboardInterrupt
            r = Scripted(interrupt)
            try:
                with act:
                    ServoLoop(probe, [r], {"vibration": act}, realtime=True).run(1.0)
            except KeyboardInterrupt:
                pass
            t0 = box["t0"]
        elif path == "exception: OSError(ENOSPC) from a device step":
            probe.raise_at = 0.2
            try:
                with act:
                    ServoLoop(probe, [Scripted(None)], {"vibration": act}, realtime=True).run(1.0)
            except OSError:
                pass
            t0 = probe.t_event
            box["playing"] = probe.playing
        elif path == "loop stall (renderer sleeps 300 ms)":
            def stall() -> None:
                box["t0"] = act.t_last
                box["playing"] = drv.driving
                time.sleep(0.3)
            r = Scripted(stall)
            with act:
                ServoLoop(probe, [r], {"vibration": act}, realtime=True).run(0.4)
            t0 = box["t0"]
        else:
            raise ValueError(path)
        if not box.get("playing"):
            return SKIP, NOT_PLAYING
        t1 = drv.first_silent_after(t0)
        return (None if t1 is None or t1 - t0 > GIVE_UP_S else t1 - t0), ""
    finally:
        if act.is_open:
            act.close()
        if transport == "serial":
            emu.stop()


def one_unplug(transport: str) -> tuple[float | None, str]:
    """USB: unplug -> the chip's own stop (its finite sequence runs out). Serial: cable
    pulled -> the piezo silent (the chip's own stop, or the firmware watchdog, 0.25 s)."""
    act, drv, emu = _make(transport, firmware_watchdog_s=0.25)
    try:
        act.open()
        for _ in range(30):
            act.command(_cmd())
            time.sleep(0.001)
        if not drv.driving:
            return SKIP, NOT_PLAYING
        if transport == "usb":
            t0 = act.t_last
            emu.unplugged = True
            while time.monotonic() - t0 < GIVE_UP_S and drv.driving:
                time.sleep(0.0005)
            t1 = drv.first_silent_after(t0)     # when the sequence ran out (no write reached it)
            reported = act.describe()["watchdog"]["failures"] > 0
            emu.unplugged = False       # let the watchdog's retry land before closing
            return (None if t1 is None or t1 - t0 > GIVE_UP_S else t1 - t0,
                    "from the last command; the host reported the fault" if reported else
                    "from the last command; the host had not reported it yet")
        # pull the cable while the servo keeps commanding (so the host watchdog cannot
        # stop the chip through a link that is still up); t = 0 when the cable is pulled
        gone: dict[str, float] = {}

        def pull() -> None:
            gone["t"] = time.monotonic()   # the cable is pulled (the pty closes within ~20 ms)
            emu.unplug()
        th = threading.Thread(target=pull)
        th.start()
        while emu.master >= 0:
            try:
                act.command(_cmd())
            except Exception:
                break
            time.sleep(0.001)
        th.join()
        t0 = gone["t"]
        if not drv.driving:
            return SKIP, NOT_PLAYING
        while time.monotonic() - t0 < GIVE_UP_S and drv.driving:
            time.sleep(0.001)
        return (None if drv.driving else time.monotonic() - t0), \
            "from the cable pulled; chip sequence ran out, firmware watchdog 0.25 s as backup (polled 1 ms)"
    finally:
        act.close()
        if transport == "serial":
            emu.stop()


def _cmd():  # type: ignore[no-untyped-def]
    from hapticsdk.perception.dimensions import ChannelCommand
    return ChannelCommand("vibration", frequency_hz=120.0, amplitude=10.0)


def one_signal(signame: str, scene_path: str) -> tuple[float | None, str]:
    drv = TimedDRV()
    emu = SerialBridgeEmulator({0x59: drv}, watchdog_s=0).start()
    proc = subprocess.Popen([sys.executable, "-m", "hapticsdk", "render", "--scene", scene_path, "--seconds", "30",
                             "--device-option", f"vibration.port={emu.port}"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        t_start = time.monotonic()
        while time.monotonic() - t_start < 60 and proc.poll() is None:
            o = drv.output()
            if o["playing"] and o["amplitude_v"] > 1.0:
                break
            time.sleep(0.002)
        else:
            return SKIP, f"not counted: never played: {proc.communicate()[1][-300:]}"
        time.sleep(0.05)
        playing = drv.driving
        t0 = time.monotonic()
        proc.send_signal(getattr(signal, signame))
        _, err = proc.communicate(timeout=30)
        t1 = drv.first_silent_after(t0)
        code = proc.returncode
        if not playing:
            return SKIP, f"exit {code}; not counted: not playing when signalled"
        if t1 is None or t1 - t0 > GIVE_UP_S:
            return None, f"exit {code}; still driving={drv.driving}; stderr: {err.strip()[-200:]}"
        return t1 - t0, f"exit {code}"
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        emu.stop()


def summarise(name: str, transport: str, mechanism: str, results: list[tuple[float | None, str]]) -> dict:
    vals = np.array([r for r, _ in results if r is not None and r != SKIP]) * 1e3
    notes = sorted({n for _, n in results if n})
    row = {"path": name, "transport": transport, "stopped by": mechanism,
           "n": sum(r != SKIP for r, _ in results), "not_counted": sum(r == SKIP for r, _ in results),
           "failures": sum(r is None for r, _ in results),
           "median_ms": float(np.median(vals)) if vals.size else None,
           "p90_ms": float(np.percentile(vals, 90)) if vals.size else None,
           "max_ms": float(vals.max()) if vals.size else None, "notes": "; ".join(notes)}
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=10, help="runs per in-process stop path and transport")
    ap.add_argument("--signal-repeat", type=int, default=5, help="subprocess runs per signal")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    if not (1 <= a.repeat <= 1000 and 0 <= a.signal_repeat <= 100):
        ap.error("--repeat 1..1000, --signal-repeat 0..100")
    rows = []
    paths = [("normal end", "servo loop returns; `with` closes the actuator (standby)"),
             ("exception: KeyboardInterrupt in a renderer", "ServoLoop stops every actuator, then re-raises"),
             ("exception: OSError(ENOSPC) from a device step", "ServoLoop stops every actuator, then re-raises"),
             ("loop stall (renderer sleeps 300 ms)", "host watchdog thread (deadline 10 ms)")]
    for path, mech in paths:
        for transport in ("serial", "usb"):
            res = [one_loop_run(transport, path) for _ in range(a.repeat)]
            rows.append(summarise(path, transport, mech, res))
            print(f"done: {path} / {transport}", file=sys.stderr, flush=True)
    rows.append(summarise("unplug: MCP2221A gone", "usb", "chip: finite synthesis sequence runs out",
                          [one_unplug("usb") for _ in range(a.repeat)]))
    rows.append(summarise("unplug: serial cable pulled", "serial", "chip sequence runs out; firmware watchdog",
                          [one_unplug("serial") for _ in range(max(1, a.repeat // 2))]))
    if a.signal_repeat:
        with tempfile.TemporaryDirectory() as tmp:
            scene = os.path.join(tmp, "scene.json")
            with open(scene, "w") as f:
                json.dump({"schema_version": 1, "name": "bench-stop",
                           "objects": [{"name": "m", "material": {"name": "r", "intensities": {"roughness": 0.6}}}],
                           "devices": {"vibration": {"actuator": "piezo-serial"}},
                           "settings": {"servo": {"period_s": 0.001, "realtime": True}}}, f)
            for signame in ("SIGINT", "SIGTERM", "SIGHUP"):
                res = [one_signal(signame, scene) for _ in range(a.signal_repeat)]
                rows.append(summarise(f"signal: {signame} to `hapticsdk render`", "serial",
                                      "SafeStop -> ServoLoop stop -> close", res))
                print(f"done: {signame}", file=sys.stderr, flush=True)
    spurious = {}
    for transport in ("serial", "usb"):
        runs = [r for r in NORMAL_RUNS if r["transport"] == transport]
        spurious[transport] = {"runs": len(runs), "trips": sum(r["trips"] for r in runs),
                               "runs_with_trips": sum(r["trips"] > 0 for r in runs),
                               "max_command_gap_ms": 1e3 * max((r["max_gap_s"] for r in runs), default=0.0)}
    if a.json:
        print(json.dumps({"stop_paths": rows, "watchdog_trips_while_rendering": spurious}, indent=2))
        return 0
    print("time from the stop event until the piezo is silent (emulated DRV2667; ms)")
    print(f"{'stop path':<48} {'transport':<9} {'n':>3} {'median':>8} {'p90':>8} {'max':>8} {'fail':>4} "
          f"{'not counted':>11}  notes")
    for r in rows:
        f = (lambda v: f"{v:8.2f}" if v is not None else f"{'-':>8}")
        notes = "; ".join(n[:90] for n in r["notes"].split("; ")) if r["notes"] else ""
        print(f"{r['path']:<48} {r['transport']:<9} {r['n']:>3} {f(r['median_ms'])} {f(r['p90_ms'])} "
              f"{f(r['max_ms'])} {r['failures']:>4} {r['not_counted']:>11}  {notes}")
    for transport, d in spurious.items():
        print(f"watchdog trips while commands flowed ({transport}, {d['runs']} realtime runs of 0.3 s at 1 kHz): "
              f"{d['trips']} in {d['runs_with_trips']} runs; largest gap between two commands "
              f"{d['max_command_gap_ms']:.1f} ms (the servo thread preempted or late)")
    print("machine: shared (other processes running); emulated transports; see the module docstring")
    return 0


if __name__ == "__main__":
    sys.exit(main())

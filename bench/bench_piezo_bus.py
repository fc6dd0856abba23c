"""Bus cost per servo command of the DRV2667 backends (``piezo-serial``, ``piezo-mcp2221``).

``python bench/bench_piezo_bus.py [--commands 3000] [--json]``

What it measures: commands are sent back to back (no sleeping) to an open actuator, as a
1 kHz servo loop would send them (``period_s`` 1 ms), in two patterns: ``constant`` (fixed
frequency and amplitude after the ramp: only the chip-side re-arm writes remain) and
``sweep`` (the frequency changes every command, as the roughness texture does while the
finger's speed changes: one chunk write per command plus the re-arms). Per command:
I2C transactions the emulated DRV2667 received, transport requests (serial frames, or
64-byte USB HID reports), and the time per command (median, p90, max; wall clock), plus
the CPU time of the whole process per command (``time.process_time``; for the serial
bridge this includes the emulated firmware thread, which runs in the same process).

What it does not measure: real transport latencies. The emulators answer in
microseconds; a real MCP2221A needs about 1 ms per HID report (the kernel driver waits
about 1 ms between reports), a serial bridge at 115200 baud about 1-2 ms per request
frame and reply. Multiply the requests per command by those figures to get the real
budget per command. The machine may be shared with other processes.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np
from hapticsdk_roughness.emulation import SerialBridgeEmulator
from hapticsdk_roughness.hardware import PiezoMCP2221, PiezoSerial

from hapticsdk.perception.dimensions import ChannelCommand


def run(transport: str, pattern: str, n: int) -> dict:
    if transport == "serial":
        emu = SerialBridgeEmulator(watchdog_s=0).start()
        act = PiezoSerial(port=emu.port, timeout=0.2, retries=2, watchdog_s=0.25)
        drv, requests = emu.drv, (lambda: len(emu.requests))
    else:
        from hapticsdk_roughness.usb_emulation import EmulatedMCP2221, MCP2221Backend
        board = EmulatedMCP2221("BUS1")
        act = PiezoMCP2221(backend=MCP2221Backend([board]), watchdog_s=0.25)
        drv, requests = board.drv, (lambda: len(board.reports))
    try:
        act.open()
        for _ in range(20):                      # past the amplitude ramp
            act.command(ChannelCommand("vibration", frequency_hz=200.0, amplitude=10.0))
        tx0, rq0, cpu0 = len(drv.log), requests(), time.process_time()
        times = np.empty(n)
        for k in range(n):
            f = 200.0 + (150.0 * np.sin(k / 50.0) if pattern == "sweep" else 0.0)
            t0 = time.perf_counter()
            act.command(ChannelCommand("vibration", frequency_hz=f, amplitude=10.0))
            times[k] = time.perf_counter() - t0
        cpu = time.process_time() - cpu0
        return {"transport": transport, "pattern": pattern, "commands": n,
                "i2c_per_command": (len(drv.log) - tx0) / n, "requests_per_command": (requests() - rq0) / n,
                "median_ms": float(np.median(times) * 1e3), "p90_ms": float(np.percentile(times, 90) * 1e3),
                "max_ms": float(times.max() * 1e3), "cpu_ms_per_command": cpu / n * 1e3, "failures": 0}
    finally:
        act.close()
        if transport == "serial":
            emu.stop()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--commands", type=int, default=3000)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    if not 10 <= a.commands <= 1_000_000:
        ap.error("--commands 10..1000000")
    rows = [run(t, p, a.commands) for t in ("serial", "usb") for p in ("constant", "sweep")]
    if a.json:
        print(json.dumps(rows, indent=2))
        return 0
    print("per servo command, emulated transports (wall times include the emulator's answer)")
    print(f"{'transport':<8} {'pattern':<9} {'I2C/cmd':>8} {'requests/cmd':>12} {'median ms':>9} {'p90 ms':>8} "
          f"{'max ms':>8} {'CPU ms':>7} {'fail':>4}")
    for r in rows:
        print(f"{r['transport']:<8} {r['pattern']:<9} {r['i2c_per_command']:8.2f} {r['requests_per_command']:12.2f} "
              f"{r['median_ms']:9.3f} {r['p90_ms']:8.3f} {r['max_ms']:8.3f} {r['cpu_ms_per_command']:7.3f} "
              f"{r['failures']:>4}")
    print("requests: serial frames or USB HID reports (a real MCP2221A: about 1 ms each); machine shared")
    return 0


if __name__ == "__main__":
    sys.exit(main())

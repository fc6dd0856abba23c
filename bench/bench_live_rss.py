"""Resident memory of a live session's servo process over minutes, while it records.

``python bench/bench_live_rss.py [--seconds 300] [--format npz|h5|none] [--every 10] [--json]``

What it measures: a process-isolated ``Session`` at 1 kHz on simulated devices (the
S7-like pad of ``tests/runtime/test_session_recording.py``: probe-virtual, the hardness
voice coil and the roughness piezo; a finger pressed 2 mm into the pad, creeping 40 mm
in an hour, so the coil drives all the time, and the piezo, under its 20 mm/s gate,
synthesises silence: both synthesise a block of samples every tick whatever the
amplitude), recording every tick to a temporary ``.npz`` or ``.h5`` (or not at all).
Every ``--every`` seconds it reads the servo's ``VmRSS`` from ``/proc/<pid>/status``;
the result is the least-squares slope of RSS against wall time (MB per minute) over all
samples, and over the samples after the first 60 s (the default waveform window of the
simulated actuators), with the first and last RSS. Generated data (simulated devices).

What it does not measure: the application process, the page cache of the file written,
or a real device's transport. Linux only (``/proc``).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time

import numpy as np

import hapticsdk as hs
from hapticsdk.sim.finger import Trajectory

PAD = {"schema_version": 1, "name": "pad",
       "objects": [{"name": "pad", "material": {"intensities": {"hardness": 0.9, "roughness": 0.5}}}],
       "devices": {"force": "probe-virtual"}, "settings": {"solver": {"seed": 0}, "importance": {"enabled": False}}}


def rss_kb(pid: int) -> int:
    with open(f"/proc/{pid}/status") as fh:
        for ln in fh:
            if ln.startswith("VmRSS"):
                return int(ln.split()[1])
    raise RuntimeError("no VmRSS")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=300.0)
    ap.add_argument("--format", choices=("npz", "h5", "none"), default="npz")
    ap.add_argument("--every", type=float, default=10.0)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    finger = Trajectory([(0.0, -20.0, 2.0), (0.2, -20.0, -2.0), (3600.0, 20.0, -2.0)])
    kw = {} if a.format == "none" else {"record": f"{tempfile.mkdtemp()}/run.{a.format}"}
    samples = []
    with hs.Session(PAD, trajectory=finger, log_seconds=1.0, heartbeat_timeout_s=None, **kw) as s:
        t0 = time.monotonic()
        while time.monotonic() - t0 < a.seconds:
            time.sleep(a.every)
            samples.append((time.monotonic() - t0, s.state().ticks, rss_kb(s.servo_pid)))
            if not a.json:
                print(f"{samples[-1][0]:7.1f} s  {samples[-1][1]:8d} ticks  {samples[-1][2]:8d} kB", flush=True)
        summary = s.close()
    arr = np.array(samples, float)

    def slope(m: np.ndarray) -> float | None:
        return float(np.polyfit(arr[m, 0], arr[m, 2], 1)[0] * 60.0 / 1024.0) if m.sum() >= 2 else None

    out = {"format": a.format, "seconds": a.seconds, "ticks": int(arr[-1, 1]), "rss_kb_first": int(arr[0, 2]),
           "rss_kb_last": int(arr[-1, 2]), "slope_mb_per_min": slope(np.ones(len(arr), bool)),
           "slope_mb_per_min_after_60s": slope(arr[:, 0] > 60.0), "generated": True,
           "record_path": summary.get("record_path"), "record_finished_by": summary.get("record_finished_by", "servo"),
           "record_error": summary.get("record_error")}
    print(json.dumps(out) if a.json else
          f"servo RSS {out['rss_kb_first']} -> {out['rss_kb_last']} kB, slope {out['slope_mb_per_min']:+.3f} MB/min")


if __name__ == "__main__":
    main()

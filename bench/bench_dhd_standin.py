"""The ``dhd`` backend in the servo loop at 4 kHz (0.25 ms) on the stand-in libdrd of the
tests, with the vendor's binding (``forcedimension-core``) in the loop.

``python bench/bench_dhd_standin.py [--seconds 10] [--period 0.00025] [--fifo-priority 80] [--json]``

Needs gcc and ``pip install hapticsdk-hardness[dhd]``. It compiles
``plugins/hapticsdk-hardness/tests/dhd_standin.c`` (a STAND-IN for Force Dimension's
library: a simulated one-axis handle pressed 3 mm into a 1 N/mm wall), then runs the
hardness renderer with the passivity controller through ``ServoLoop`` paced on the
machine clock, with ``SCHED_FIFO`` when the machine grants it (reported).

What it measures (the loop's own report, wall clock): per-tick compute time (median,
p99) -- reading the state through the binding, the renderer, the passivity controller,
writing the force through the binding -- and the period jitter and missed-tick rate of
the loop. The same loop on the simulated ``omni-virtual`` at the same period runs right
after as the reference on this machine. What it does not measure: a real device's USB
round trip (DHD does it in its own thread on real devices), or a process-isolated
session (``hapticsdk bench live --period 0.00025`` does that on simulated devices).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _loop(device, period: float, seconds: float, fifo: int | None) -> dict:
    from hapticsdk.runtime import ServoLoop
    from hapticsdk_hardness.dimension import HardnessDimension
    from hapticsdk_hardness.voicecoil import VoiceCoilVirtual
    rt = {"fifo_priority": fifo} if fifo else None
    with device:
        loop = ServoLoop(device, [HardnessDimension().renderer({"GS": 1.0})],
                         {"force": device, "coil": VoiceCoilVirtual()}, period_s=period, realtime=True, rt=rt)
        rep = loop.run(seconds)
    d = rep.to_dict() if hasattr(rep, "to_dict") else {}
    jit = rep.jitter or {}
    return {"ticks": rep.ticks, "tick_median_us": rep.tick_median_us, "tick_p99_us": rep.tick_p99_us,
            "jitter_p99_us": jit.get("p99_us"), "missed_tick_rate": jit.get("missed_tick_rate"),
            "rt": d.get("rt")}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--period", type=float, default=0.00025)
    ap.add_argument("--fifo-priority", type=int, default=80)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    gcc = shutil.which("gcc") or shutil.which("cc")
    if gcc is None or importlib.util.find_spec("forcedimension_core") is None:
        print("missing: gcc (Debian gcc) or forcedimension-core (pip install hapticsdk-hardness[dhd])", file=sys.stderr)
        return 2
    spec = importlib.util.spec_from_file_location(
        "dhd_tests", ROOT / "plugins" / "hapticsdk-hardness" / "tests" / "test_hardness_dhd.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)   # type: ignore[union-attr]
    from hapticsdk.devices.safety import SafetyLayer
    from hapticsdk_hardness.dhd import DhdDevice
    from hapticsdk_hardness.omni import OmniVirtual
    with tempfile.TemporaryDirectory() as d:
        sdk = mod.build_standin(Path(d), gcc)
        import ctypes
        lib = ctypes.CDLL(str(next((sdk / "lib" / "release" / "lin-x86_64-gcc").glob("libdrd.so*"))))
        lib.standin_script.argtypes = [ctypes.c_double] * 3
        lib.standin_script(0.002, -0.003, 0.2)
        dev = DhdDevice(sdk=str(sdk), safety=SafetyLayer(DhdDevice.limits, ramp_time_s=0.0))
        out = {"period_s": a.period, "seconds": a.seconds, "dhd_standin": _loop(dev, a.period, a.seconds, a.fifo_priority)}
    out["reference_omni_virtual"] = _loop(OmniVirtual(), a.period, a.seconds, a.fifo_priority)
    if a.json:
        print(json.dumps(out, indent=1, default=str))
        return 0
    print(f"servo period {a.period * 1e3:g} ms ({1e-3 / a.period:g} kHz), {a.seconds:g} s, realtime")
    print(f"{'device':<22} {'ticks':>6}   tick median/p99 us   jitter p99 us   missed")
    for k in ("dhd_standin", "reference_omni_virtual"):
        r = out[k]
        print(f"{k:<22} {r['ticks']:6d}   {r['tick_median_us']:7.1f}/{r['tick_p99_us']:7.1f}     "
              f"{(r['jitter_p99_us'] or float('nan')):9.1f}     {(r['missed_tick_rate'] or 0) * 100:5.2f} %")
    print(f"scheduling: {out['dhd_standin']['rt']}")
    print("(the DHD figures are on a STAND-IN library; shared machines: other processes' load is in these figures)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

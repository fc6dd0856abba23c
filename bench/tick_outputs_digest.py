"""SHA-256 of everything the servo tick sends and logs over a long, eventful scene run:
the check that a change to the tick's code leaves its outputs bit-identical.

    python bench/tick_outputs_digest.py [--seconds 12]

Run it on two trees (the one on ``PYTHONPATH`` is imported) and compare the digests.

The scene is the one of ``hapticsdk bench timing`` (hardness + roughness on the simulated
Omni, voice coil and piezo, 1 ms period, simulated clock), with, on fixed ticks: a
non-finite state, a state beyond the position limit and a velocity spike (the device's
state read replaced on the instance), a pause, two material retargets (one stiffer, with
the roughness frequency beyond the piezo's band), tighter force, stiffness and force-rate limits, a safety fault on the voice coil (gate
and ramp again), new limits on the force channel mid-run (a speed limit the slide exceeds,
a force-rate limit), new safety settings, a safety layer replaced on the piezo, and the
force clamps of the stiff material. A second run ends with a backend fault (the voice
coil's ``_command`` raising). What is hashed, as ``float.hex`` text: every command each
backend received, every command the loop recorded as sent (role, force, frequency,
amplitude, direction), the loop's log columns (all but the compute times), its events
(but the overrun count, a clock reading), the passivity report, every safety layer's hits, events and phase, and the fault.
The last two lines are the same two runs without the recorder (so the loop takes its
steady-state tick between the events; the recorder's lines are then not hashed).
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import math
import os
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")

from hapticsdk.benchmarks.timing import build_scene  # noqa: E402
from hapticsdk.devices.safety import SafetyLayer  # noqa: E402
from hapticsdk.plugins import registry  # noqa: E402
from hapticsdk.runtime import ServoLoop  # noqa: E402


def _h(x: object) -> str:
    if isinstance(x, float):
        return x.hex()
    if isinstance(x, (list, tuple)):
        return "(" + ",".join(_h(v) for v in x) + ")"
    if isinstance(x, dict):
        return "{" + ",".join(f"{k}:{_h(x[k])}" for k in sorted(x)) + "}"
    if hasattr(x, "tolist"):
        return _h(x.tolist())
    return repr(x)


def _cmd(c: object) -> str:
    if c is None:
        return "None"
    return _h([getattr(c, f) for f in ("role", "force_n", "frequency_hz", "amplitude", "direction")])


class _Rec:
    def __init__(self, out: list) -> None:
        self.out = out

    def record(self, t: float, st: object, sent: dict) -> None:
        self.out.append(_h(t) + ";" + ";".join(f"{r}={_cmd(sent[r])}" for r in sorted(sent)))


def log_backend_commands(acts: dict, lines: list[str], fmt: Any = None) -> None:
    """Wrap each actuator's backend ``_command`` (on the instance) so every command it
    receives is appended to ``lines`` as ``role>`` and its text (``fmt(command)``, default
    :func:`_cmd`), then passed on."""
    fmt = fmt or _cmd
    for role, a in acts.items():
        inner = a._command

        def wrapped(c, inner=inner, role=role):
            lines.append(f"{role}>{fmt(c)}")
            return inner(c)
        a._command = wrapped


def _run(seconds: float, fault_at: int | None, record: bool = True) -> str:
    dims = registry("dimension")
    dev, renderers, acts = build_scene(seconds + 1.0)
    lines: list[str] = []
    log_backend_commands(acts, lines)
    read = dev._read_state
    k_box = [0]

    def read_state():
        st = read()
        k = k_box[0]
        if k % 997 == 500:
            st.py = math.nan
        elif k % 1499 == 700:
            st.px = 5000.0
        elif k % 733 == 300:
            st.vy += 5000.0
        elif k % 811 == 400:
            st.vx = math.inf
        return st
    dev._read_state = read_state
    loop = ServoLoop(dev, renderers, acts, period_s=0.001, recorder=_Rec(lines) if record else None)
    loop.start(seconds)
    n = int(round(seconds / 0.001))
    force, coil, vib = acts["force"], acts["coil"], acts["vibration"]
    limits0 = force.safety.limits
    for k in range(n):
        k_box[0] = k
        if k == 150:
            force.safety.limits = dataclasses.replace(limits0, max_force_rate_n_per_tick=0.004)
        elif k == 1000:
            force.safety.limits = dataclasses.replace(limits0, max_force_n=1.2, max_stiffness_n_per_mm=0.05)
        elif k == 2600:
            force.safety.limits = limits0
        elif k == 3000:
            loop.paused = True
        elif k == 3200:
            loop.paused = False
        elif k == 4000:
            loop.set_renderers(0, [dims.load("hardness")().renderer({"GS": 5.0}),
                                   dims.load("roughness")().renderer({"Fpeak": 400.0, "AFpeak": 9.0})])
        elif k == 4500:
            coil.safety.limits = dataclasses.replace(coil.limits, max_amplitude=0.3,
                                                     frequency_range_hz=(100.0, 180.0))
        elif k == 5000:
            coil.safety.fault("digest: a fault on the coil")
        elif k == 6000:
            force.safety.limits = dataclasses.replace(force.limits, max_velocity_mm_s=45.0,
                                                      max_force_rate_n_per_tick=0.02)
        elif k == 7000:
            loop.set_renderers(0, [dims.load("hardness")().renderer({"GS": 1.5}),
                                   dims.load("roughness")().renderer({"Fpeak": 150.0, "AFpeak": 5.0})])
        elif k == 8000:
            vib.safety = SafetyLayer(vib.limits, ramp_time_s=0.05, ramp_amplitude=True)
        elif k == 9000:
            force.safety.configure(stiffness_offset_n=0.25, velocity_knee=0.2)
        if fault_at is not None and k == fault_at:
            def boom(c):
                raise RuntimeError("digest: backend failure")
            coil._command = boom
        if not loop.tick():
            break
    rep = loop.finish() if fault_at is None else _finish_fault(loop)
    for key in sorted(rep.log):
        if key in ("compute_s", "compute_cpu_s"):
            continue
        lines.append(f"log {key} {_h(rep.log[key])}")
    # (not the overrun count: a tick's compute time against the period, a clock reading)
    lines.append(f"events {_h({k: v for k, v in rep.events.items() if k != 'overrun'})}")
    lines.append(f"passivity {_h(rep.passivity)}")
    lines.append(f"fault {_h(rep.fault)} ticks {rep.ticks}")
    for role, a in acts.items():
        lines.append(f"safety {role} {_h(a.safety.hits)} {_h(a.safety.events)} {a.safety.phase} "
                     f"{a.safety.last_fault!r} last={_cmd(a.last_command)}")
        a.close()
    if os.environ.get("DIGEST_SHOW"):
        print([l for l in lines if l.startswith(("events", "safety", "fault"))])
    return hashlib.sha256("\n".join(lines).encode()).hexdigest()


def _finish_fault(loop: ServoLoop):
    try:
        return loop.finish()
    except Exception as exc:   # raise_on_fault: the report rides on the error
        return exc.report  # type: ignore[attr-defined]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=12.0)
    a = ap.parse_args()
    print("eventful run:", _run(a.seconds, None))
    print("backend fault:", _run(4.0, 2500))
    # without a recorder the loop runs its steady-state tick wherever it can (issue 30)
    print("eventful run, no recorder:", _run(a.seconds, None, record=False))
    print("backend fault, no recorder:", _run(4.0, 2500, record=False))


if __name__ == "__main__":
    main()

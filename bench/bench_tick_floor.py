"""The floor of the servo tick in CPython: the least Python that does the work the tick of
``hapticsdk bench timing`` must do, inline, next to the servo loop's own tick.

    OMP_NUM_THREADS=1 python bench/bench_tick_floor.py [--seconds 10] [--rounds 4] [--json]

What it measures: the on-CPU time (``time.thread_time_ns``, read at the start and the end
of each tick, as ``ServoLoop._tick`` reads it for ``compute_cpu_s``) of each tick, median
and p99 over the ticks of a run, for four ticks on the scene of ``bench timing``
(hardness + roughness, simulated Omni, voice coil and piezo, 1 ms period, simulated
clock, GC off), each on a fresh scene, interleaved in ``--rounds`` rounds:

* ``loop``: ``ServoLoop.tick`` itself (its ``compute_cpu_s`` column);
* ``floor_full``: the configuration's whole work written inline in one function, no
  abstraction: the device's state read (its backend ``_read_state``), the finiteness,
  position, speed and acceleration checks with the last good state kept, the plane hit
  test with the contact hysteresis, the velocity filter, both renderers' arithmetic
  (spring, coil drive, the roughness speed gate and formula (9)), the passivity
  controller's ``step`` and ``commit`` (the loop's own controller object: its arithmetic is
  the work), the three safety clamps the declared limits of this configuration need
  (force limit, stiffness cap, frequency range, amplitude range, command gap), the three
  command writes (the record the safety layer keeps for ``current``, the backends'
  ``_command``) and the log row;
* ``floor_force_pc``: what the brief of issue 30 names as the least tick: state read,
  the same checks, plane hit test, the spring through the controller's step and commit,
  the force clamps, one command write (the two vibration channels are not sent: their
  layers go stale, as after a stop);
* ``floor_force``: the same without the controller (the spring is sent as it is).

The first 300 ticks of every run (the safety layers' start ramp, 0.2 s) are the loop's
own, so every floor tick runs with the layers in their ``running`` phase; the statistics
are over the ticks after them, for the loop too. Between ticks the simulated devices are
stepped as the loop steps them (``device.step`` and the stepped actuators' ``step``): their
numpy code evicts the interpreter's code from the caches, as in ``bench timing``, and it
is not timed. The bare references of :mod:`hapticsdk.benchmarks.reference` (an empty call
timed with the same clock, one bare-loop iteration) are measured in every round; the
ratios are per round, so they are comparable across machines and loads.

What it does not measure: the floors are not a servo loop. They drop what no
configuration-independent code can avoid (the events dict, observers, the material
switch, the op queue, per-command validation through the actuator and its safety layer's
state machine, the recorder hook, exceptions turned into faults), so they are a lower
bound for any tick that keeps all of that, not a replacement. Wall time is not reported.
"""

from __future__ import annotations

import argparse
import gc
import json
import math
import os
import statistics
import time
from typing import Any

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import numpy as np  # noqa: E402

from hapticsdk.benchmarks.reference import bare_reference, machine  # noqa: E402
from hapticsdk.benchmarks.timing import build_scene  # noqa: E402
from hapticsdk.perception.dimensions import ChannelCommand  # noqa: E402
from hapticsdk.runtime import ServoLoop  # noqa: E402

WARM = 300          # ticks run by the loop first (the safety layers' 0.2 s ramp)
T = 0.001


# The floor ticks, composed from these pieces into one function each (no call between
# them: the point of a floor), compiled once per run with the run's objects as globals.
_READ_CHECK = """
    q0 = tt()
    st = read()
    p0, p1, p2, v0, v1, v2 = st.px, st.py, st.pz, st.vx, st.vy, st.vz
    bad = False
    if not (isfinite(p0 + p1 + p2) and isfinite(v0 + v1 + v2)):
        bad = True
    elif (abs(p0) > max_pos or abs(p1) > max_pos or abs(p2) > max_pos
          or v0 * v0 + v1 * v1 + v2 * v2 > vmax2):
        bad = True
    else:
        lim = amax_acc * T
        l0, l1, l2 = last_vel
        if abs(v0 - l0) > lim or abs(v1 - l1) > lim or abs(v2 - l2) > lim:
            st_s["events"] += 1
            v0, v1, v2 = l0, l1, l2
    if bad:
        st_s["events"] += 1
        st = st_s["good"]
        p0, p1, p2, v0, v1, v2 = st.px, st.py, st.pz, st.vx, st.vy, st.vz
    else:
        st_s["good"] = st
        last_vel[0] = v0
        last_vel[1] = v1
        last_vel[2] = v2
    pen = -1.0 if bad else -p1
"""
# the plane hit test with the contact hysteresis, the velocity filter and both renderers
_RENDER = """
    if bad:
        # no object under a refused state: nothing rendered, the vibration roles silent
        st_s["contact"] = -1
        in_contact = False
        f_wall = 0.0
        amp_c = 0.0
        fr = st_s["last_f"]
        amp_v = 0.0
    else:
        pen_in = pen
        in_contact = pen > 0.0
        if not in_contact and st_s["contact"] == 0 and pen > -h:
            in_contact = True
            pen_in = 0.0
        st_s["contact"] = 0 if in_contact else -1
        vf0 = st_s["vf0"] = st_s["vf0"] + vf_a * (v0 - st_s["vf0"])
        f_wall = k_spring * pen_in if in_contact else 0.0
        amp_c = a_coil if in_contact else 0.0
        thr = vgate - v_step if st_s["gate"] else vgate
        gate = st_s["gate"] = abs(vf0) >= thr and in_contact
        if gate:
            fr = fpeak * abs(v0) / vref
            if fr < flo or fr > fhi:
                fr = flo if fr < flo else fhi
            st_s["last_f"] = fr
            amp_v = vout
        else:
            fr = st_s["last_f"]
            amp_v = 0.0
"""
_PLANE_SPRING = """
    f_wall = k_spring * pen if pen > 0.0 else 0.0
"""
_CONTROLLER = """
    if not bad:
        st_s["x"] = -pen
    f = pc.step(st_s["x"], T, f_wall)
"""
_NO_CONTROLLER = """
    f = f_wall
"""
_FORCE_SEND = """
    if bad:
        f = 0.0
    if not isfinite(f):
        raise ValueError("force")
    if t - sf._t_last > restart:
        raise RuntimeError("gap")
    if abs(f) > fmax:
        st_s["hits"] += 1
        f = math.copysign(fmax, f)
    cap_k = kmax * (pen if pen > 0.0 else 0.0) + koff
    if abs(f) > cap_k:
        st_s["hits"] += 1
        f = math.copysign(cap_k, f)
    rec_f.force_n = f
    sf._last = rec_f
    sf._t_last = t
    dev._f_set = f if f <= arm_fmax else arm_fmax
"""
_COMMIT = """
    pc.commit(f)
"""
_VIB_SEND_LOG = """
    if not (isfinite(f_coil) and isfinite(amp_c)):
        raise ValueError("coil")
    fc = f_coil if c_lo <= f_coil <= c_hi else (c_lo if f_coil < c_lo else c_hi)
    ac = amp_c if 0.0 <= amp_c <= c_amax else (0.0 if amp_c < 0.0 else c_amax)
    rec_c.frequency_hz = fc
    rec_c.amplitude = ac
    sc._last = rec_c
    sc._t_last = t
    coil_act._freq = fc
    coil_act._amp = ac
    if not (isfinite(fr) and isfinite(amp_v)):
        raise ValueError("vibration")
    if not v_lo <= fr <= v_hi:
        fr = v_lo if fr < v_lo else v_hi
    if not 0.0 <= amp_v <= v_amax:
        amp_v = 0.0 if amp_v < 0.0 else v_amax
    rec_v.frequency_hz = fr
    rec_v.amplitude = amp_v
    sv._last = rec_v
    sv._t_last = t
    vib_command(rec_v)
    row(lm, (k % cap) * ncol * 8, t, T, pen, 0.0, f, p0, p1, p2, v0, v1, v2,
        f, math.nan, 0.0, math.nan, fc, ac, math.nan, fr, amp_v)
"""


def _floor_source(variant: str) -> str:
    """The source of the floor tick ``tick(k, t)`` of ``variant``: its CPU time (ns)."""
    body = {"full": (_READ_CHECK, _RENDER, _CONTROLLER, _FORCE_SEND, _COMMIT, _VIB_SEND_LOG),
            "force_pc": (_READ_CHECK, _PLANE_SPRING, _CONTROLLER, _FORCE_SEND, _COMMIT),
            "force": (_READ_CHECK, _PLANE_SPRING, _NO_CONTROLLER, _FORCE_SEND)}[variant]
    return "def tick(k, t):" + "".join(body) + "    return tt() - q0\n"


def _scene(seconds: float, setup: Any = None) -> tuple[ServoLoop, int]:
    dev, renderers, acts = build_scene(seconds + 1.0)
    if setup is not None:
        setup(dev, acts)   # (tests: a state read replaced, other limits)
    loop = ServoLoop(dev, renderers, acts, period_s=T)
    loop.start(seconds)
    for _ in range(WARM):
        loop.tick()
    return loop, int(round(seconds / T))


def _close(loop: ServoLoop, n: int, log: list | None) -> None:
    if log is not None:
        log.append(loop._log[:n].copy())   # the log ring's rows (a run shorter than the ring)
    loop.finish()
    for a in {id(a): a for a in [loop.device, *loop.actuators.values()]}.values():
        a.close()


def run_loop(seconds: float, log: list | None = None, setup: Any = None) -> np.ndarray:
    """The loop's own ticks: per-tick CPU ns after WARM (``log``: its log rows appended;
    ``setup(device, actuators)``: called on the scene before the run)."""
    loop, n = _scene(seconds, setup)
    while loop.tick():
        pass
    cpu = loop._window(loop._log[:, loop._ncol - 2], loop._k)[WARM:n]
    _close(loop, n, log)
    return cpu * 1e9


def run_floor(seconds: float, variant: str, log: list | None = None, setup: Any = None) -> np.ndarray:
    """``variant``: ``full``, ``force_pc`` or ``force``; per-tick CPU ns after WARM
    (``log``: the loop's log rows appended, the floor's own from WARM on: ``full`` writes
    its row there as the loop does; ``setup`` as for :func:`run_loop`)."""
    loop, n = _scene(seconds, setup)
    dev = loop.device
    slots = loop._slots
    force, coil, vib = slots
    pc = force.pc
    sf, sc, sv = force.act.safety, coil.act.safety, vib.act.safety
    for s in (sf, sc, sv):
        assert s.phase == "running" and not s._overspeed, s.phase
    hard, rough = loop._objs[0].renderers
    read = dev._read_state
    stepped = [a.step for a in loop._stepped]
    dev_step = dev.step
    tt = time.thread_time_ns
    isfinite = math.isfinite
    max_pos, vmax2, amax_acc = loop.max_position_mm, loop.max_speed_mm_s ** 2, loop.max_accel_mm_s2
    h = loop.contact_hysteresis_mm
    vf_a = 1.0 - math.exp(-6.283185307179586 * loop.velocity_filter_hz * T)
    v_step = vf_a * h / T
    k_spring, f_coil, a_coil = hard._k, hard._f, hard._amp
    fpeak, vref, vgate, flo, fhi, vout = rough.fpeak_hz, rough.v_ref_mm_s, rough.v_gate_mm_s, rough.f_lo, rough.f_hi, rough.v_out
    fmax, kmax, koff = sf._fmax, sf._kmax, sf._k_offset
    arm_fmax = dev.arm.max_force_n
    c_lo, c_hi = sc._frange
    c_amax = sc._amax
    v_lo, v_hi = sv._frange
    v_amax = sv._amax
    restart = sf._restart_limit
    vib_command = vib.act._command
    coil_act = coil.act
    rec_f = ChannelCommand("force", 0.0)
    rec_c = ChannelCommand("coil", None, f_coil, 0.0)
    rec_v = ChannelCommand("vibration", None, rough._last_f, 0.0)
    lm = loop._log_mv
    row = loop._log_row
    ncol = loop._ncol
    cap = loop._cap
    st_s = {"last_vel": list(loop._last_vel), "good": loop._good_state, "contact": loop.contact,
            "vf0": loop._vf0, "gate": rough._gate_open, "last_f": rough._last_f, "hits": 0, "events": 0,
            "x": loop._last_x}
    last_vel = st_s["last_vel"]
    out = np.empty(n - WARM, np.int64)

    env = dict(locals())
    env.update(math=math, isfinite=isfinite, T=T)
    exec(compile(_floor_source(variant), f"<floor {variant}>", "exec"), env)   # noqa: S102
    tick = env["tick"]
    steps = [dev_step, *stepped] if variant == "full" else [dev_step]
    for k in range(WARM, n):
        out[k - WARM] = tick(k, k * T)
        for step in steps:
            step(T)
    loop._k = n
    _close(loop, n, log)
    return out


VARIANTS = ("loop", "floor_full", "floor_force_pc", "floor_force")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    before = machine()
    rounds = []
    for r in range(a.rounds):
        res: dict = {}
        order = VARIANTS if r % 2 == 0 else VARIANTS[::-1]
        for v in order:
            gc.collect()
            ns = run_loop(a.seconds) if v == "loop" else run_floor(a.seconds, v[len("floor_"):])
            res[v] = {"median_us": float(np.median(ns)) * 1e-3, "p99_us": float(np.percentile(ns, 99)) * 1e-3}
        ref = bare_reference("thread_cpu")
        res["empty_call_us"] = ref["empty_call_us"]
        res["bare_loop_us"] = ref["bare_loop_us"]
        rounds.append(res)
        if not a.json:
            print(f"round {r + 1}: " + ", ".join(f"{v} {res[v]['median_us']:.2f}/{res[v]['p99_us']:.2f}"
                                                 for v in VARIANTS)
                  + f" us (median/p99); empty call {ref['empty_call_us']:.3f} us", flush=True)
    summary = {}
    for v in VARIANTS:
        meds = [x[v]["median_us"] for x in rounds]
        summary[v] = {"median_us": statistics.median(meds),
                      "over_loop": statistics.median(x[v]["median_us"] / x["loop"]["median_us"] for x in rounds),
                      "over_empty_call": statistics.median(x[v]["median_us"] / x["empty_call_us"] for x in rounds),
                      "over_bare_loop": statistics.median(x[v]["median_us"] / x["bare_loop_us"] for x in rounds)}
    result = {"rounds": rounds, "summary": summary, "seconds": a.seconds, "clock": "thread_cpu",
              "statistic": "median over the ticks after the first 300; summary: median of rounds",
              "machine_before": before, "machine_after": machine()}
    if a.json:
        print(json.dumps(result, indent=1))
        return
    print("\nvariant          median (us)  / loop  / empty call  / bare-loop iteration")
    for v in VARIANTS:
        s = summary[v]
        print(f"{v:16s} {s['median_us']:10.2f}  {s['over_loop']:6.3f}  {s['over_empty_call']:10.1f}  "
              f"{s['over_bare_loop']:10.0f}")
    print(f"load {before.get('load_1min')} -> {result['machine_after'].get('load_1min')}")


if __name__ == "__main__":
    main()

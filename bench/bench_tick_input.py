"""Cost of handing renderers a read-only velocity array: whole-tick compute time of
``ServoLoop.tick`` with three ways of building the (3,) array, in one process.

``python bench/bench_tick_input.py [--ticks 20000] [--runs 5]``

What it measures: the loop's own per-tick compute time (its ``perf_counter`` column,
simulated time, GC off), median over the ticks of one run, then the median of ``--runs``
interleaved runs per variant, on two scenes: the version-1 plane (hardness + roughness
on the simulated devices of ``hapticsdk bench timing``; the array is the device state's
``velocity_mm_s``, built per tick) and a spatial scene (a box and a sphere, two no-op
renderers, 1000 ticks; the loop builds the contact-frame array on the sphere's flank).
Variants: ``frombuffer`` (the loop's: a view of packed immutable bytes, read-only),
``array+flag`` (``np.array`` then ``flags.writeable = False``, the previous state array)
and ``array`` (``np.array``, writable: the previous spatial array).

What it does not measure: anything outside the tick (device simulation steps are
logged apart), nor a real-time run's jitter. On a shared machine compare the variants
of one run, not runs of different days.
"""

from __future__ import annotations

import argparse
import gc

import numpy as np

import hapticsdk.devices.actuators as A
import hapticsdk.runtime.loop as L
from hapticsdk.benchmarks.timing import build_scene
from hapticsdk.perception.dimensions import DimensionRenderer
from hapticsdk.runtime import ServoLoop
from hapticsdk.scene.geometry import Box, HitTester, Pose, Sphere
from hapticsdk.sim.finger import Trajectory
from hapticsdk.sim.probe import VirtualProbe


def _array_flag(a: float, b: float, c: float) -> np.ndarray:
    out = np.array((a, b, c))
    out.flags.writeable = False
    return out


def _array(a: float, b: float, c: float) -> np.ndarray:
    return np.array((a, b, c))


VARIANTS = {"frombuffer": A._frozen3, "array+flag": _array_flag, "array": _array}


class _Idle(DimensionRenderer):
    roles = ()

    def tick(self, inp):
        return []


def _median_tick_us(loop: ServoLoop, ticks: int) -> float:
    loop.start(ticks / 1000)
    while loop.tick():
        pass
    loop.finish()
    n = min(ticks, loop._cap)
    return float(np.median(loop._log[100:n, loop._ncol - 3])) * 1e6


def plane(ticks: int) -> float:
    dev, rs, acts = build_scene(ticks / 1000 + 1)
    return _median_tick_us(ServoLoop(dev, rs, acts, period_s=0.001, realtime=False), ticks)


def spatial(ticks: int = 1000) -> float:
    tr = Trajectory([(0.0, -30.0, 5.0), (0.2, -30.0, -1.0), (0.6, 30.0, -1.0), (1.0, 30.0, 5.0)])
    box = Box((20.0, 10.0, 20.0), pose=Pose((-30.0, -10.0, 0.0)))
    ball = Sphere(20.0, pose=Pose((30.0, -19.0, 0.0)))
    loop = ServoLoop(VirtualProbe(trajectory=tr), (), passivity=False,
                     objects=[("box", [_Idle()]), ("ball", [_Idle()])],
                     hit_tester=HitTester([("box", box), ("ball", ball)]))
    return _median_tick_us(loop, ticks)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ticks", type=int, default=20_000)
    ap.add_argument("--runs", type=int, default=5)
    a = ap.parse_args()
    res: dict[str, list[float]] = {}
    own_state, own_loop = A._frozen3, L._frozen3
    gc.disable()
    try:
        for _ in range(a.runs):
            for name, f in VARIANTS.items():
                A._frozen3 = L._frozen3 = f
                res.setdefault(f"plane   {name}", []).append(plane(a.ticks))
                res.setdefault(f"spatial {name}", []).append(spatial())
    finally:
        A._frozen3, L._frozen3 = own_state, own_loop
        gc.enable()
    print(f"whole-tick compute time (us), median over ticks, median of {a.runs} interleaved runs")
    for k, v in sorted(res.items()):
        print(f"  {k:20s} {np.median(v):6.2f}   runs {[round(x, 2) for x in v]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

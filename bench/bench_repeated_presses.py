"""Repeated presses on one wall through the servo loop: the force the arm delivers on each
press against the wall's law, with the stiff-wall controller on and off.

    python bench/bench_repeated_presses.py [--gs 1 3] [--presses 10] [--finger medium]

Simulated Omni (``omni-virtual``: 45 g, declared damping 0.5 N s/m, 0.055 mm encoder,
3.3 N), 1 kHz, simulated time; the finger presses to 2 mm over 0.3 s, holds 0.3 s,
releases over 0.3 s and rests 0.2 s, ``--presses`` times on the same object (the
controller's energy bound is not restarted between presses: the probe never leaves the
object). The hardness renderer at ``GS`` N/mm; the voice coil is simulated and not
counted. Per press: the delivered ratio over the contact ticks, ``sum F / sum min(GS x
penetration, 3.3 N)`` (the force sent, the penetration as read), and for the whole run the
energy given to the finger (the arm's exact integral). Not measured: the voice coil's
share of the felt stiffness, realtime pacing, other fingers or devices unless asked.
Every figure comes from the simulated device (generated, not measured on hardware).
"""

from __future__ import annotations

import argparse

import numpy as np


def run(gs: float, presses: int, finger: str, passivity: bool) -> tuple[list[float], float]:
    from hapticsdk.plugins import registry
    from hapticsdk.runtime import ServoLoop
    from hapticsdk.sim.finger import press_slide
    dims, acts = registry("dimension"), registry("actuator")
    cycle = press_slide(depth_mm=2.0, press_s=0.3, hold_s=0.3, slide_s=0.0, release_s=0.3, rest_s=0.2)
    gap = 0.01
    tr = cycle
    for _ in range(presses - 1):
        tr = tr.then(cycle, gap_s=gap)
    dev = acts.load("omni-virtual")(trajectory=tr, finger=finger)
    loop = ServoLoop(dev, [dims.load("hardness")().renderer({"GS": gs})],
                     {"force": dev, "coil": acts.load("voicecoil-virtual")()}, period_s=0.001, passivity=passivity)
    rep = loop.run(tr.duration_s)
    t, pen, f = rep.log["t"], rep.log["penetration_mm"], rep.log["force_n"]
    per = cycle.duration_s + gap
    ratios = []
    for k in range(presses):
        m = (t >= k * per) & (t < (k + 1) * per) & (pen > 0)
        want = np.minimum(gs * pen[m], 3.3).sum()
        ratios.append(float(f[m].sum() / want) if want > 0 else float("nan"))
    return ratios, float(dev.energy_to_user_j())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--gs", type=float, nargs="+", default=[1.0, 3.0], help="wall stiffness GS (N/mm)")
    ap.add_argument("--presses", type=int, default=10)
    ap.add_argument("--finger", default="medium", help="finger preset of hapticsdk.sim.finger.FINGERS")
    a = ap.parse_args()
    print(f"simulated Omni (generated data), 1 kHz, {a.presses} presses to 2 mm, finger {a.finger!r}; "
          "delivered = sum F / sum min(GS x pen, 3.3 N) over each press's contact ticks")
    for gs in a.gs:
        for on in (True, False):
            r, e = run(gs, a.presses, a.finger, on)
            label = "controller on " if on else "controller off"
            print(f"GS {gs:g} N/mm, {label}: delivered per press " + " ".join(f"{x:.2f}" for x in r)
                  + f"; energy to the finger over the run {e * 1e3:+.3f} mJ")


if __name__ == "__main__":
    main()

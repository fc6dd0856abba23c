"""Fidelity against cost over the servo period (``hapticsdk bench fidelity``).

For each period T in 0.25 .. 4 ms, a hardness (+ roughness when installed) material is
rendered on the simulated Omni along a press / multi-speed slide / release path and
compared with the ideal continuous rendering:

* ``force_error_rms_n``: RMS over in-contact periods of (force held by the arm) minus
  (the spring law of formula (8), ``min(GS, 2.3) * Y``, at the *true* penetration
  averaged over the period: the arm is integrated exactly, so the end points are exact).
  It collects the hold lag, encoder quantisation and the passivity controller's action.
* ``frequency_error_hz``: RMS over a 25 us grid of (vibration frequency held by the
  actuator) minus (the same renderer evaluated on that fine grid with exact kinematics);
  the roughness channel when installed, else the voice coil. The piezo is the
  DRV2667-driven ``piezo-virtual`` with ``quantize=True``: it holds the synthesiser's
  frequency code, in 7.8125 Hz steps (read back from the actuator every tick), so this
  error includes the chip's frequency resolution. ``frequency_error_max_hz`` is the
  largest absolute error on the grid; ``frequency_error_unquantised_hz`` /
  ``..._max_hz`` are the same for the frequency *commanded* (before the chip's rounding,
  i.e. the hold's error alone), from the same run.
* ``tick_median_us``: median compute time per tick.

Not measured: the chip's own synthesis (phase continuity across code changes, its
output filter), the piezo's mechanical response, perception.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..perception.dimensions import TickInput
from ..plugins import registry
from ..runtime import ServoLoop
from ..sim.finger import Trajectory

PERIODS_S = (0.25e-3, 0.5e-3, 1e-3, 2e-3, 4e-3)
MATERIAL = {"GS": 2.0, "Fpeak": 150.0, "AFpeak": 5.0}
FINE_S = 25e-6


def fidelity_trajectory() -> Trajectory:
    """Rest 2 mm above the surface for 0.25 s (the safety layer's start ramp ends before
    contact), press to 3 mm (reference) in 0.3 s, slide with a smooth speed profile
    ``x = 20 (1 - cos(2 pi t / 1 s))`` mm (peak 126 mm/s; knots every 0.1 ms), release."""
    k = [(0.0, 0.0, 2.0), (0.25, 0.0, 2.0), (0.55, 0.0, -3.0), (0.65, 0.0, -3.0)]
    ts = np.arange(1, 10001) * 1e-4
    k += [(0.65 + t, 20.0 * (1.0 - np.cos(2 * np.pi * t)), -3.0) for t in ts]
    k += [(1.75, 0.0, -3.0), (2.05, 0.0, 2.0), (2.25, 0.0, 2.0)]
    return Trajectory(k, name="fidelity")


class _TruePen:
    """Recorder: true penetration (mm) of the simulated arm at every tick, and the
    frequency the vibration actuator holds (its read-back, Hz; NaN without one)."""

    def __init__(self, dev: Any, vib: Any = None) -> None:
        self.dev = dev
        self.vib = vib
        self.pen: list[float] = []
        self.held_hz: list[float] = []

    def record(self, t: float, state: Any, sent: Any) -> None:
        self.pen.append(-self.dev.true_position_mm)
        rb = self.vib.read_back() if self.vib is not None else None
        f = rb.frequency_hz if rb is not None else None
        self.held_hz.append(float(f) if f is not None else float("nan"))


def run_fidelity(periods: tuple[float, ...] = PERIODS_S, *, progress: Any = None) -> list[dict[str, Any]]:
    """Render a fixed material along a fixed trajectory at each servo period (s) and return
    one row per period: RMS force error against the ideal spring (N), RMS drive-frequency
    error against a 40 kHz reference (Hz), tick compute time (us). ``progress(stage,
    done, total)`` follows the periods.
    """
    dims = registry("dimension")
    acts = registry("actuator")
    traj = fidelity_trajectory()
    dur = traj.duration_s
    hard = dims.load("hardness")()
    have_rough = "roughness" in dims
    rough: Any = dims.load("roughness")() if have_rough else None
    role = "vibration" if have_rough else "coil"
    # reference frequencies on the fine grid: the renderer at 40 kHz with exact kinematics
    fine_t = np.arange(int(dur / FINE_S)) * FINE_S
    ref_r = (rough.renderer({"Fpeak": MATERIAL["Fpeak"], "AFpeak": MATERIAL["AFpeak"]}) if have_rough
             else hard.renderer({"GS": MATERIAL["GS"]}))
    ref_f = np.empty(fine_t.size)
    for i, t in enumerate(fine_t):
        x, y, vx, vy = traj.at(float(t))
        cmds = ref_r.tick(TickInput(t=float(t), dt=FINE_S, penetration_mm=1.0, velocity_mm_s=np.array([vx, vy, 0.0]),
                                    in_contact=True))
        c = [c for c in cmds if c.role == role][0]
        ref_f[i] = c.frequency_hz if (c.frequency_hz is not None and (c.amplitude or 0) > 0) else np.nan
    out = []
    for T in periods:
        dev = acts.load("omni-virtual")(trajectory=traj, finger="stiff")
        renderers = [hard.renderer({"GS": MATERIAL["GS"]})]
        actuators: dict[str, Any] = {"force": dev, "coil": acts.load("voicecoil-virtual")()}
        if have_rough:
            renderers.append(rough.renderer({"Fpeak": MATERIAL["Fpeak"], "AFpeak": MATERIAL["AFpeak"]},
                                            require_contact=False))
            actuators["vibration"] = acts.load("piezo-virtual")(period_s=T, quantize=True)
        rec = _TruePen(dev, actuators.get(role))
        rep = ServoLoop(dev, renderers, actuators, period_s=T, recorder=rec).run(dur)
        L = rep.log
        pen = np.asarray(rec.pen)
        # true penetration at tick k+1 is the one recorded at the next tick
        mid = 0.5 * (pen[:-1] + pen[1:])
        k_omni = min(MATERIAL["GS"], 2.3)
        ideal = np.clip(k_omni * np.maximum(mid, 0.0), 0.0, 3.3)
        f_held = L["force_n"][:-1]
        contact = mid > 0
        ferr = float(np.sqrt(np.mean((f_held[contact] - ideal[contact]) ** 2))) if contact.any() else float("nan")
        # held frequency on the fine grid
        idx = np.minimum((fine_t / T + 1e-9).astype(int), L["t"].size - 1)
        commanded = L[f"{role}.frequency_hz"][idx]
        held_rb = np.asarray(rec.held_hz, float)
        held = held_rb[np.minimum(idx, held_rb.size - 1)] if held_rb.size else commanded
        held = np.where(np.isfinite(held), held, commanded)  # no read-back: the commanded value
        amp = L[f"{role}.amplitude"][idx]

        def err(f_out: np.ndarray) -> tuple[float, float]:
            both = np.isfinite(ref_f) & (amp > 0) & np.isfinite(f_out)
            if not both.any():
                return 0.0, 0.0
            e = f_out[both] - ref_f[both]
            return float(np.sqrt(np.mean(e ** 2))), float(np.max(np.abs(e)))

        frerr, frmax = err(held)
        fuerr, fumax = err(commanded)
        out.append({"period_s": T, "force_error_rms_n": ferr, "frequency_error_hz": frerr,
                    "frequency_error_max_hz": frmax, "frequency_error_unquantised_hz": fuerr,
                    "frequency_error_unquantised_max_hz": fumax,
                    "frequency_quantised": bool(getattr(actuators.get(role), "quantize", False)),
                    "tick_median_us": rep.tick_median_us, "tick_p99_us": rep.tick_p99_us,
                    "frequency_channel": role})
        for a in {id(a): a for a in [dev, *actuators.values()]}.values():
            a.close()
        if progress is not None:  # progress(stage, done, total), see hapticsdk.progress
            progress("servo periods", len(out), len(periods))
    return out

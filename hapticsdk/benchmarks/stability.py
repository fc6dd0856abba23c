"""Stability matrix of a virtual wall on the simulated Omni (``hapticsdk bench stability``).

Every cell is one 10 s simulated run of a raw spring wall ``F = K * penetration``
(deliberately *not* split by formula (8), so stiffnesses far above the Omni's limit
reach the arm and test the passivity controller) on the simulated Omni axis
(:mod:`hapticsdk.sim.arm`: exact ZOH integration, force saturation 3.3 N, encoder
0.055 mm), pushed by a finger impedance along a scripted press/slide/tap trajectory,
then released for the last second. All cells of one servo period run together as numpy
arrays (one vectorised step per tick for the whole grid).

Per cell: ``energy_to_user_j`` = max over time of the energy the arm + wall gave to the
finger (the negative of the display-port energy ``W_d = 1/2 m v^2 + int b v^2 - int F v``;
exact under the hold), ``peak_force_n``, ``max_force_step_n`` (largest
change of the applied force between two ticks, N; includes the wall's own jump at
contact), ``delivered_force_ratio`` (sum of the force the arm applied over the ticks
the wall was touched, divided by the sum of the wall force asked there, capped at the
device limit: 1 = the wall was rendered as asked, lower = the controller or the damping
took force away; NaN when the wall was never touched), ``oscillation_after_release_n`` (largest wall
force over the last 0.5 s, when the finger rests 2 mm above the surface: any force
means the stylus still bounces on the wall), and ``stable`` = energy within
:data:`ENERGY_TOLERANCE_J`, no force after release (below
:data:`OSCILLATION_TOLERANCE_N`) and peak force within the device limit. Each cell is
run with the controller on and off; ``margin_ns_per_m`` is the Colgate prediction
(:func:`hapticsdk.passivity.passivity_margin`, d = 0).
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..errors import ValidationError
from ..passivity import (ControllerSettings, controller_commit_batch, controller_state_batch,
                         controller_step_batch, passivity_margin)
from ..sim.arm import ArmBatch, ArmParams
from ..sim.finger import FINGERS, Trajectory, press_slide, taps

#: Energy the wall may give to the user with the controller on (J): 2.5 mJ, i.e. the
#: controller's bound tolerance (1 mJ, ControllerSettings.bound_tolerance_j: lower values
#: make the controller chatter on encoder-quantisation noise, see docs/runtime.md) plus
#: 1.5 mJ for what a one-period prediction cannot see: the finger's own push during the
#: period and the encoder's quantisation (3.3 N x 0.055 mm = 0.18 mJ per count).
ENERGY_TOLERANCE_J = 2.5e-3
#: Wall force after release counted as continuing oscillation (N).
OSCILLATION_TOLERANCE_N = 1e-6

DEFAULT_GRID = {
    "stiffness_n_per_mm": [0.01, 0.1, 0.7, 2.3, 10.0, 100.0, 1000.0, 10000.0],
    "period_s": [0.25e-3, 0.5e-3, 1e-3, 2e-3, 4e-3],
    "damping_ns_per_m": [0.0, 0.25, 0.5],
    "finger": ["soft", "medium", "stiff"],
    "duration_s": 10.0,
}
QUICK_GRID = {
    "stiffness_n_per_mm": [0.1, 2.3, 100.0, 10000.0],
    "period_s": [1e-3, 4e-3],
    "damping_ns_per_m": [0.0, 0.5],
    "finger": ["medium"],
    "duration_s": 3.0,
}


def matrix_trajectory(duration_s: float = 10.0) -> Trajectory:
    """Press/slide/tap cycles (finger reference 5 mm deep) until 1 s before the end, then
    the finger rests 2 mm above the surface."""
    cycle = press_slide(depth_mm=5.0, approach_mm=2.0, press_s=0.3, hold_s=0.1, slide_s=0.5,
                        release_s=0.3, rest_s=0.1).then(
        taps(n=3, depth_mm=4.0, approach_mm=2.0, down_s=0.03, up_s=0.03, dwell_s=0.05, pause_s=0.1), gap_s=0.01)
    tr = cycle
    while tr.duration_s + cycle.duration_s < duration_s - 1.0:
        tr = tr.then(cycle, gap_s=0.01)
    end = tr.duration_s
    knots = list(zip(tr.t, tr.x, tr.y)) + [(max(duration_s, end + 1.0), float(tr.x[-1]), 2.0)]
    return Trajectory(knots, name="stability-matrix")


@dataclass
class StabilityResult:
    cells: list[dict[str, Any]]
    tolerance_j: float
    duration_s: float
    runtime_s: float

    def to_dict(self) -> dict[str, Any]:
        return {"cells": self.cells, "energy_tolerance_j": self.tolerance_j,
                "oscillation_tolerance_n": OSCILLATION_TOLERANCE_N, "duration_s": self.duration_s,
                "runtime_s": self.runtime_s, "summary": summarise(self.cells)}


def summarise(cells: Sequence[dict[str, Any]]) -> dict[str, Any]:
    on = [c for c in cells if c["controller"]]
    off = [c for c in cells if not c["controller"]]
    return {"cells": len(cells),
            "controller_on_unstable": sum(not c["stable"] for c in on),
            "controller_on_max_energy_j": max((c["energy_to_user_j"] for c in on), default=float("nan")),
            "controller_on_max_peak_force_n": max((c["peak_force_n"] for c in on), default=float("nan")),
            "controller_on_max_force_step_n": max((c.get("max_force_step_n", float("nan")) for c in on),
                                                  default=float("nan")),
            "controller_off_unstable": sum(not c["stable"] for c in off),
            "controller_off_predicted_active": sum(c["margin_ns_per_m"] < 0 for c in off)}


def run_period(period_s: float, K: np.ndarray, b: np.ndarray, fingers: Sequence[str], on: np.ndarray,
               duration_s: float, *, arm: ArmParams | None = None,
               settings: ControllerSettings | None = None,
               on_ticks: Any = None) -> dict[str, np.ndarray]:
    """Simulate all cells of one period together; returns per-cell metric arrays.
    ``on_ticks(done)`` (optional) is called every 1000 ticks and at the end."""
    arm = arm or ArmParams()
    arms = [arm.with_(damping_ns_per_m=float(bi)) for bi in b]
    fings = [FINGERS[f] for f in fingers]
    traj = matrix_trajectory(duration_s)
    n_ticks = int(round(duration_s / period_s))
    tt = np.arange(n_ticks + 1) * period_s
    _, r = traj.position(tt)
    x0 = float(r[0])
    batch = ArmBatch(period_s, arms, fings, y0_mm=x0, track_energy=True)
    st = controller_state_batch(len(arms))
    limit = batch.fmax
    peak = np.zeros(len(arms))
    e_max = np.zeros(len(arms))
    resid = np.zeros(len(arms))
    dmax = np.zeros(len(arms))
    f_last = np.zeros(len(arms))
    asked = np.zeros(len(arms))     # sum of the wall force asked (capped at the limit) in contact, N
    given = np.zeros(len(arms))     # sum of the force the arm applied on those ticks, N
    t_rel = duration_s - 0.5
    for k in range(n_ticks):
        if on_ticks is not None and k % 1000 == 0 and k:
            on_ticks(k)
        y_meas = batch.measured_mm()
        pen = -y_meas
        f_wall = np.where(pen > 0, K * pen, 0.0)
        f_cmd = controller_step_batch(st, y_meas, period_s, f_wall, on, settings, damping_ns_per_m=b,
                                      resolution_mm=batch.res_mm)
        f_cmd = np.nan_to_num(f_cmd, nan=0.0)
        f = batch.step(f_cmd, r[k], (r[k + 1] - r[k]) / period_s)  # one reference for all cells (broadcast)
        controller_commit_batch(st, f)
        touching = f_wall > 0
        asked += np.where(touching, np.minimum(f_wall, limit), 0.0)
        given += np.where(touching, f, 0.0)
        np.maximum(peak, np.abs(f), out=peak)
        np.maximum(dmax, np.abs(f - f_last), out=dmax)
        f_last = f
        np.maximum(e_max, batch.energy_to_user_j(), out=e_max)
        if tt[k] >= t_rel:
            np.maximum(resid, np.abs(f), out=resid)
    if on_ticks is not None:
        on_ticks(n_ticks)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(asked > 0, given / np.where(asked > 0, asked, 1.0), np.nan)
    return {"energy_to_user_j": e_max, "peak_force_n": peak, "oscillation_after_release_n": resid,
            "max_force_step_n": dmax, "delivered_force_ratio": ratio,
            "limit_n": limit, "observed_energy_j": st["energy"], "dissipated_j": st["dissipated"]}


def run_matrix(grid: dict[str, Any] | None = None, *, arm: ArmParams | None = None,
               settings: ControllerSettings | None = None, progress: Any = None) -> StabilityResult:
    """Run the stability matrix over ``grid`` (keys as :data:`DEFAULT_GRID`).

    ``progress(stage, done, total)`` (:mod:`hapticsdk.progress`) follows the simulated
    servo ticks of all periods."""
    g = dict(DEFAULT_GRID)
    g.update(grid or {})
    if not float(g["duration_s"]) >= 3.0:
        raise ValidationError("a stability cell needs >= 3 s (one press/slide/tap cycle, then 1 s of release)",
                              field="duration_s")
    t0 = time.perf_counter()
    cells: list[dict[str, Any]] = []
    from ..progress import report
    total = sum(int(round(float(g["duration_s"]) / float(T))) for T in g["period_s"])
    before = 0
    for T in g["period_s"]:
        combos = list(itertools.product(g["stiffness_n_per_mm"], g["damping_ns_per_m"], g["finger"], (True, False)))
        K = np.array([c[0] for c in combos], float)
        b = np.array([c[1] for c in combos], float)
        fn = [c[2] for c in combos]
        on = np.array([c[3] for c in combos], bool)
        res = run_period(float(T), K, b, fn, on, float(g["duration_s"]), arm=arm, settings=settings,
                         on_ticks=lambda k, b0=before: report(progress, "simulated servo ticks", b0 + k, total))
        before += int(round(float(g["duration_s"]) / float(T)))
        for i, (Ki, bi, fi, oi) in enumerate(combos):
            e = float(res["energy_to_user_j"][i])
            pk = float(res["peak_force_n"][i])
            osc = float(res["oscillation_after_release_n"][i])
            stable = bool(e <= ENERGY_TOLERANCE_J and osc <= OSCILLATION_TOLERANCE_N
                          and pk <= float(res["limit_n"][i]) + 1e-9)
            cells.append({"stiffness_n_per_mm": float(Ki), "period_s": float(T), "damping_ns_per_m": float(bi),
                          "finger": fi, "controller": bool(oi), "energy_to_user_j": e, "peak_force_n": pk,
                          "oscillation_after_release_n": osc, "stable": stable,
                          "max_force_step_n": float(res["max_force_step_n"][i]),
                          "delivered_force_ratio": float(res["delivered_force_ratio"][i]),
                          "margin_ns_per_m": float(passivity_margin(Ki, 0.0, bi, T, 0))})
    return StabilityResult(cells=cells, tolerance_j=ENERGY_TOLERANCE_J, duration_s=float(g["duration_s"]),
                           runtime_s=time.perf_counter() - t0)

"""Stability and transparency matrix of a virtual wall on the simulated Omni
(``hapticsdk bench stability``).

Every cell is one 10 s simulated run of a raw spring wall ``F = K * penetration``
(deliberately *not* split by formula (8), so stiffnesses far above the Omni's limit
reach the arm and test the passivity controller) on the simulated Omni axis
(:mod:`hapticsdk.sim.arm`: exact ZOH integration, force saturation 3.3 N, encoder
0.055 mm), pushed by a finger impedance along a scripted press/slide/tap trajectory,
then released for the last second. All cells of one servo period run together as numpy
arrays (one vectorised step per tick for the whole grid). Each cell runs with the
passivity controller on and off.

What a cell measures (all from the simulation, nothing from the controller's own
bookkeeping):

* ``energy_to_user_j``: max over time of the energy the arm + wall gave to the finger
  (the negative of the display-port energy ``W_d = 1/2 m v^2 + int b v^2 - int F v``;
  exact under the hold).
* ``peak_commanded_force_n``: largest force the renderer + controller *commanded*, before
  the arm's 3.3 N saturation; ``peak_force_n``: largest force the arm applied (after it).
* ``max_force_step_n``: largest change of the applied force between two ticks (N;
  includes the wall's own jump at contact).
* Transparency over the *contact ticks* (reading inside the wall), the applied force
  against a target evaluated at the same reading the wall was computed from, each target
  capped at the arm's force limit (it cannot push harder):
  ``delivered_vs_wall_ratio`` = sum(applied) / sum(min(K pen, limit));
  ``delivered_vs_wall_min_ratio_above_1mm`` = the smallest per-tick ratio of the same on
  ticks deeper than 1 mm; ``delivered_vs_passive_ratio`` = sum(applied) /
  sum(min(min(K, K_pass) pen, limit)) against the stiffest passive spring of the cell;
  ``min_force_above_1mm_n`` and ``felt_force_ratio_min`` = min over ticks deeper than
  1 mm of applied / min(:data:`FELT_FORCE_N`, :data:`FELT_FRACTION` K pen) (>= 1: a
  person feels the wall on every such tick).
* ``passive_stiffness_n_per_mm`` (K_pass): the stiffest wall the same cell (period,
  device damping, finger; same trajectory, same simulation) keeps *stable with the
  controller off*, found per (T, b, finger) on a log grid of :data:`KPASS_GRID_POINTS`
  stiffnesses over :data:`KPASS_RANGE_N_PER_MM`, refined once on
  :data:`KPASS_REFINE_POINTS` log-spaced points between the last stable and the first
  unstable grid stiffness (so within a factor ``KPASS_REFINE_RATIO`` below the true
  boundary, assuming stability is monotone in K, which the grid checks only at its
  points). 0 when even the softest grid wall is unstable.
* ``stable``: energy to the user <= :data:`ENERGY_TOLERANCE_J` and no wall force after
  release (<= :data:`OSCILLATION_TOLERANCE_N`, the finger rests 2 mm above the surface).
  The peak force is reported, not judged: a saturated command is not an instability.
* ``outcome``: ``"unstable"``, ``"stable and transparent"`` (delivered >=
  :data:`TRANSPARENT_FRACTION` of min(K, K_pass) x penetration) or ``"stable by
  withholding"``.

Not measured: Coulomb friction (the simulator has none, so the quantisation mode of
Abbott & Okamura is not damped by it), computation delay beyond the zero-order hold,
multi-axis coupling, loop jitter (the period is exact), a human's reaction (the finger is
a fixed impedance following a script).

The tolerances here are the benchmark's own, set from what a user must get (the wall
felt, no energy handed out), independent of any constant of the controller.
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

#: Energy the wall may give to the user over a 10 s cell (J): 0.1 mJ, about what the
#: finger gets from one tap on a 2 x 2b/T wall (a small fraction of the ~10 mJ of work the
#: finger does on the wall per press). Set from the goal, not from the controller.
ENERGY_TOLERANCE_J = 1.0e-4
#: Wall force after release counted as continuing oscillation (N).
OSCILLATION_TOLERANCE_N = 1e-6
#: Fraction of min(K, K_pass) x penetration that must be delivered over the contact ticks.
TRANSPARENT_FRACTION = 0.9
#: Force a person must feel on every contact tick deeper than FELT_DEPTH_MM (N), or
#: FELT_FRACTION x K x penetration for a softer wall.
FELT_FORCE_N = 0.5
FELT_FRACTION = 0.9
FELT_DEPTH_MM = 1.0
#: K_pass search: log grid (N/mm), points, then one refinement between the bracket.
KPASS_RANGE_N_PER_MM = (1e-4, 1e2)
KPASS_GRID_POINTS = 25
KPASS_REFINE_POINTS = 16
KPASS_REFINE_RATIO = float((KPASS_RANGE_N_PER_MM[1] / KPASS_RANGE_N_PER_MM[0])
                           ** (1.0 / (KPASS_GRID_POINTS - 1) / (KPASS_REFINE_POINTS + 1)))

STABLE_TRANSPARENT = "stable and transparent"
STABLE_WITHHOLDING = "stable by withholding"
UNSTABLE = "unstable"

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


def check_cell_duration(duration_s: Any) -> float:
    """A fixed-grid cell's length (s): at least 3 s (one press/slide/tap cycle, then 1 s of
    release) and at most the longest render, :data:`hapticsdk.scene.limits.MAX_SECONDS`
    (24 h); else ValidationError."""
    from ..argcheck import number
    from ..scene.limits import MAX_SECONDS
    v = number(duration_s, "duration_s")
    if not 3.0 <= v <= MAX_SECONDS:
        raise ValidationError(f"a stability cell needs >= 3 s (one press/slide/tap cycle, then 1 s of release) and "
                              f"at most {MAX_SECONDS:g} s (24 h), got {duration_s!r}", field="duration_s")
    return v


def matrix_trajectory(duration_s: float = 10.0) -> Trajectory:
    """Press/slide/tap cycles (finger reference 5 mm deep) until 1 s before the end, then
    the finger rests 2 mm above the surface."""
    cycle = press_slide(depth_mm=5.0, approach_mm=2.0, press_s=0.3, hold_s=0.1, slide_s=0.5,
                        release_s=0.3, rest_s=0.1).then(
        taps(n=3, depth_mm=4.0, approach_mm=2.0, down_s=0.03, up_s=0.03, dwell_s=0.05, pause_s=0.1), gap_s=0.01)
    check_cell_duration(duration_s)
    tr = cycle.repeated(lambda d: d + cycle.duration_s < duration_s - 1.0, gap_s=0.01)
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
        """The matrix as JSON-ready data: every cell, the tolerances it was judged with, the
        passive-stiffness search and the summary counts.
        """
        return {"cells": self.cells, "energy_tolerance_j": self.tolerance_j,
                "oscillation_tolerance_n": OSCILLATION_TOLERANCE_N,
                "transparent_fraction": TRANSPARENT_FRACTION,
                "felt_force_n": FELT_FORCE_N, "felt_fraction": FELT_FRACTION, "felt_depth_mm": FELT_DEPTH_MM,
                "passive_stiffness_search": {
                    "method": "log grid then one log refinement between the last stable and first unstable "
                              "grid stiffness, same simulation with the controller off",
                    "range_n_per_mm": list(KPASS_RANGE_N_PER_MM), "grid_points": KPASS_GRID_POINTS,
                    "refine_points": KPASS_REFINE_POINTS, "resolution_ratio": KPASS_REFINE_RATIO},
                "duration_s": self.duration_s, "runtime_s": self.runtime_s, "summary": summarise(self.cells)}


def _nanmin(vals: Sequence[float]) -> float:
    v = [x for x in vals if x == x]
    return min(v) if v else float("nan")


def summarise(cells: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Counts per outcome and worst figures, controller on and off, and with the controller
    on how many cells meet each goal: energy to the user <= :data:`ENERGY_TOLERANCE_J`,
    delivered >= :data:`TRANSPARENT_FRACTION` of min(K, K_pass) x penetration (a cell
    without contact ticks owes nothing), the felt force on every tick deeper than
    :data:`FELT_DEPTH_MM` (met / missed / never that deep), and all three."""
    on = [c for c in cells if c["controller"]]
    off = [c for c in cells if not c["controller"]]

    def count(group: Sequence[dict[str, Any]], outcome: str) -> int:
        return sum(c["outcome"] == outcome for c in group)

    felt_miss = [c for c in on if c["felt_force_ratio_min"] == c["felt_force_ratio_min"]
                 and c["felt_force_ratio_min"] < 1.0]
    felt_na = [c for c in on if c["felt_force_ratio_min"] != c["felt_force_ratio_min"]]
    energy_ok = [c for c in on if c["energy_to_user_j"] <= ENERGY_TOLERANCE_J]
    # a cell without contact ticks (NaN ratio) has nothing to deliver
    deliver_ok = [c for c in on if not c["delivered_vs_passive_ratio"] < TRANSPARENT_FRACTION]
    all_ok = [c for c in on if c["energy_to_user_j"] <= ENERGY_TOLERANCE_J
              and not c["delivered_vs_passive_ratio"] < TRANSPARENT_FRACTION
              and not c["felt_force_ratio_min"] < 1.0]
    return {"cells": len(cells),
            "controller_on_cells": len(on),
            "controller_on_energy_within_tolerance": len(energy_ok),
            "controller_on_delivered_within_tolerance": len(deliver_ok),
            "controller_on_felt_force_met": len(on) - len(felt_miss) - len(felt_na),
            "controller_on_felt_force_not_applicable": len(felt_na),
            "controller_on_all_three_met": len(all_ok),
            "controller_on_stable_transparent": count(on, STABLE_TRANSPARENT),
            "controller_on_stable_withholding": count(on, STABLE_WITHHOLDING),
            "controller_on_unstable": count(on, UNSTABLE),
            "controller_on_felt_force_missed": len(felt_miss),
            "controller_on_max_energy_j": max((c["energy_to_user_j"] for c in on), default=float("nan")),
            "controller_on_min_delivered_vs_passive": _nanmin([c["delivered_vs_passive_ratio"] for c in on]),
            "controller_on_min_delivered_vs_wall": _nanmin([c["delivered_vs_wall_ratio"] for c in on]),
            "controller_on_min_felt_force_ratio": _nanmin([c["felt_force_ratio_min"] for c in on]),
            "controller_on_max_peak_force_n": max((c["peak_force_n"] for c in on), default=float("nan")),
            "controller_on_max_peak_commanded_force_n": max((c["peak_commanded_force_n"] for c in on),
                                                            default=float("nan")),
            "controller_on_max_force_step_n": max((c["max_force_step_n"] for c in on), default=float("nan")),
            "controller_off_stable_transparent": count(off, STABLE_TRANSPARENT),
            "controller_off_stable_withholding": count(off, STABLE_WITHHOLDING),
            "controller_off_unstable": count(off, UNSTABLE),
            "controller_off_predicted_active": sum(c["margin_ns_per_m"] < 0 for c in off)}


def run_period(period_s: float, K: np.ndarray, b: np.ndarray, fingers: Sequence[str], on: np.ndarray,
               duration_s: float, *, arm: ArmParams | None = None,
               settings: ControllerSettings | None = None, k_pass: Any = None,
               on_ticks: Any = None) -> dict[str, np.ndarray]:
    """Simulate all cells of one period together; returns per-cell metric arrays (see the
    module docstring). ``k_pass`` (N/mm, per cell; optional) is the stiffest passive
    spring the delivered force is also compared with (``delivered_vs_passive_ratio``,
    NaN without it). ``on_ticks(done)`` (optional) is called every 1000 ticks and at the
    end. ``energy_bound_j`` is the controller's bound ``U`` at the end; with ``on`` False in
    every cell the controller's tick is skipped (the forces are the same) and it stays 0."""
    arm = arm or ArmParams()
    K = np.asarray(K, float)
    n = K.size
    arms = [arm.with_(damping_ns_per_m=float(bi)) for bi in b]
    fings = [FINGERS[f] for f in fingers]
    traj = matrix_trajectory(duration_s)
    n_ticks = int(round(duration_s / period_s))
    tt = np.arange(n_ticks + 1) * period_s
    _, r = traj.position(tt)
    x0 = float(r[0])
    batch = ArmBatch(period_s, arms, fings, y0_mm=x0, track_energy=True)
    st = controller_state_batch(n)
    limit = batch.fmax
    batch_m = np.array([a.mass_kg for a in arms])
    kp = np.full(n, np.nan) if k_pass is None else np.broadcast_to(np.asarray(k_pass, float), (n,))
    k_eff = np.minimum(K, kp)
    peak = np.zeros(n)
    peak_cmd = np.zeros(n)
    e_max = np.zeros(n)
    resid = np.zeros(n)
    dmax = np.zeros(n)
    f_last = np.zeros(n)
    given = np.zeros(n)      # sum of the applied force over the contact ticks (N)
    asked = np.zeros(n)      # sum of min(K pen, limit) there (N)
    asked_p = np.zeros(n)    # sum of min(min(K, K_pass) pen, limit) there (N)
    contact = np.zeros(n, int)
    min_wall = np.full(n, np.inf)   # min over ticks deeper than FELT_DEPTH_MM of applied / min(K pen, limit)
    min_felt = np.full(n, np.inf)   # ... of applied / min(FELT_FORCE_N, FELT_FRACTION K pen)
    min_f = np.full(n, np.inf)      # ... of the applied force (N)
    t_rel = duration_s - 0.5
    # with the controller off in every cell (passive_stiffness's runs) its tick is skipped:
    # the forces are the same floats, in about a third of the time
    controlled = bool(np.any(on))
    for k in range(n_ticks):
        if on_ticks is not None and k % 1000 == 0 and k:
            on_ticks(k)
        y_meas = batch.measured_mm()
        pen = -y_meas
        touching = pen > 0
        f_wall = np.where(touching, K * pen, 0.0)
        if controlled:
            f_cmd = controller_step_batch(st, y_meas, period_s, f_wall, on, settings, damping_ns_per_m=b,
                                          resolution_mm=batch.res_mm, max_force_n=limit, mass_kg=batch_m)
        else:   # the wall's force as the controller passes it through for a cell that is off
            f_cmd = np.nan_to_num(f_wall, nan=0.0, posinf=0.0, neginf=0.0)
        f_cmd = np.nan_to_num(f_cmd, nan=0.0)
        np.maximum(peak_cmd, np.abs(f_cmd), out=peak_cmd)
        f = batch.step(f_cmd, r[k], (r[k + 1] - r[k]) / period_s)  # one reference for all cells (broadcast)
        if controlled:
            controller_commit_batch(st, f)
        if touching.any():
            law = np.minimum(f_wall, limit)
            given += np.where(touching, f, 0.0)
            asked += np.where(touching, law, 0.0)
            asked_p += np.where(touching, np.minimum(k_eff * pen, limit), 0.0)
            contact += touching
            deep = pen > FELT_DEPTH_MM
            if deep.any():
                with np.errstate(invalid="ignore", divide="ignore"):
                    np.minimum(min_wall, np.where(deep, f / law, np.inf), out=min_wall)
                    floor = np.minimum(FELT_FORCE_N, FELT_FRACTION * f_wall)
                    np.minimum(min_felt, np.where(deep, f / floor, np.inf), out=min_felt)
                np.minimum(min_f, np.where(deep, f, np.inf), out=min_f)
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
        ratio_p = np.where(asked_p > 0, given / np.where(asked_p > 0, asked_p, 1.0), np.nan)
    none = ~np.isfinite(min_wall)
    return {"energy_to_user_j": e_max, "peak_force_n": peak, "peak_commanded_force_n": peak_cmd,
            "oscillation_after_release_n": resid, "max_force_step_n": dmax,
            "delivered_vs_wall_ratio": ratio, "delivered_vs_passive_ratio": ratio_p,
            "delivered_vs_wall_min_ratio_above_1mm": np.where(none, np.nan, min_wall),
            "felt_force_ratio_min": np.where(none, np.nan, min_felt),
            "min_force_above_1mm_n": np.where(none, np.nan, min_f), "contact_ticks": contact,
            "limit_n": limit, "energy_bound_j": st["energy"]}


def _is_stable(res: dict[str, np.ndarray]) -> np.ndarray:
    return (res["energy_to_user_j"] <= ENERGY_TOLERANCE_J) & (res["oscillation_after_release_n"]
                                                               <= OSCILLATION_TOLERANCE_N)


def passive_stiffness(period_s: float, b: Sequence[float], fingers: Sequence[str], duration_s: float, *,
                      arm: ArmParams | None = None, on_ticks: Any = None) -> np.ndarray:
    """K_pass (N/mm) per (b, finger) pair at one period: the stiffest wall the same
    simulation keeps stable (:func:`_is_stable`) with the controller *off*.

    A log grid of :data:`KPASS_GRID_POINTS` stiffnesses over :data:`KPASS_RANGE_N_PER_MM`
    (one vectorised run for all pairs), then :data:`KPASS_REFINE_POINTS` log-spaced
    stiffnesses strictly between the last stable grid point below the first unstable one
    and that unstable one (a second run). Returns the largest stable stiffness below the
    first unstable one (0 if the softest is unstable; the range's top if none is)."""
    b = [float(x) for x in b]
    m = len(b)
    lo, hi = KPASS_RANGE_N_PER_MM
    grid = np.geomspace(lo, hi, KPASS_GRID_POINTS)

    def first_stable_run(ks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """ks (m, p): per pair the index of the last stable point before the first unstable one (-1)."""
        p = ks.shape[1]
        K = ks.reshape(-1)
        bb = np.repeat(b, p)
        ff = [f for f in fingers for _ in range(p)]
        res = run_period(period_s, K, bb, ff, np.zeros(K.size, bool), duration_s, arm=arm, on_ticks=on_ticks)
        ok = _is_stable(res).reshape(m, p)
        bad = ~ok
        first_bad = np.where(bad.any(axis=1), bad.argmax(axis=1), p)
        return first_bad - 1, first_bad

    ks = np.tile(grid, (m, 1))
    last, first_bad = first_stable_run(ks)
    out = np.where(last >= 0, grid[np.maximum(last, 0)], 0.0)
    need = first_bad < grid.size
    if need.any():
        a = np.where(last >= 0, grid[np.maximum(last, 0)], lo / (grid[1] / grid[0]))
        z = grid[np.minimum(first_bad, grid.size - 1)]
        frac = np.arange(1, KPASS_REFINE_POINTS + 1) / (KPASS_REFINE_POINTS + 1)
        fine = a[:, None] * (z / a)[:, None] ** frac[None, :]
        last2, _ = first_stable_run(fine)
        refined = np.where(last2 >= 0, fine[np.arange(m), np.maximum(last2, 0)], out)
        out = np.where(need, refined, out)
    return out


def classify(stable: bool, delivered_vs_passive: float) -> str:
    """Outcome label of a cell (see the module docstring)."""
    if not stable:
        return UNSTABLE
    if delivered_vs_passive == delivered_vs_passive and delivered_vs_passive < TRANSPARENT_FRACTION:
        return STABLE_WITHHOLDING
    return STABLE_TRANSPARENT


def run_matrix(grid: dict[str, Any] | None = None, *, arm: ArmParams | None = None,
               settings: ControllerSettings | None = None, progress: Any = None) -> StabilityResult:
    """Run the stability matrix over ``grid`` (keys as :data:`DEFAULT_GRID`).

    Per period: K_pass per (b, finger) (:func:`passive_stiffness`, two runs with the
    controller off), then all cells with the controller on and off.
    ``progress(stage, done, total)`` (:mod:`hapticsdk.progress`) follows the simulated
    servo ticks of all runs."""
    g: dict[str, Any] = dict(DEFAULT_GRID)
    g.update(grid or {})
    check_cell_duration(g["duration_s"])
    t0 = time.perf_counter()
    cells: list[dict[str, Any]] = []
    from ..progress import report
    dur = float(g["duration_s"])
    total = sum(3 * int(round(dur / float(T))) for T in g["period_s"])
    done = [0]

    def ticker(k: int, base: list[int] = done) -> None:
        report(progress, "simulated servo ticks", base[0] + k, total)

    for T in g["period_s"]:
        T = float(T)
        nt = int(round(dur / T))
        pairs = list(itertools.product(g["damping_ns_per_m"], g["finger"]))
        kp_pairs = passive_stiffness(T, [p[0] for p in pairs], [p[1] for p in pairs], dur, arm=arm,
                                     on_ticks=ticker)
        done[0] += 2 * nt
        kp_of = {p: float(k) for p, k in zip(pairs, kp_pairs)}
        combos = list(itertools.product(g["stiffness_n_per_mm"], g["damping_ns_per_m"], g["finger"], (True, False)))
        K = np.array([c[0] for c in combos], float)
        b = np.array([c[1] for c in combos], float)
        fn = [c[2] for c in combos]
        on = np.array([c[3] for c in combos], bool)
        kp = np.array([kp_of[(c[1], c[2])] for c in combos])
        res = run_period(T, K, b, fn, on, dur, arm=arm, settings=settings, k_pass=kp, on_ticks=ticker)
        done[0] += nt
        stable = _is_stable(res)
        for i, (Ki, bi, fi, oi) in enumerate(combos):
            cell = {"stiffness_n_per_mm": float(Ki), "period_s": T, "damping_ns_per_m": float(bi),
                    "finger": fi, "controller": bool(oi), "stable": bool(stable[i]),
                    "passive_stiffness_n_per_mm": float(kp[i]),
                    "margin_ns_per_m": float(passivity_margin(Ki, 0.0, bi, T, 0))}
            for key in ("energy_to_user_j", "peak_force_n", "peak_commanded_force_n", "oscillation_after_release_n",
                        "max_force_step_n", "delivered_vs_wall_ratio", "delivered_vs_wall_min_ratio_above_1mm",
                        "delivered_vs_passive_ratio", "felt_force_ratio_min", "min_force_above_1mm_n"):
                cell[key] = float(res[key][i])
            cell["contact_ticks"] = int(res["contact_ticks"][i])
            cell["outcome"] = classify(cell["stable"], cell["delivered_vs_passive_ratio"])
            cells.append(cell)
    return StabilityResult(cells=cells, tolerance_j=ENERGY_TOLERANCE_J, duration_s=dur,
                           runtime_s=time.perf_counter() - t0)

"""The same controller over many independent cells at once (numpy arrays): the benchmark's
and the property tests' path; equal to :class:`~hapticsdk.passivity.PassivityController`
tick by tick (``tests/sim/test_sim_passivity.py``)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import ValidationError
from .plan import _BRANCH_TOL, _HIST, _ROUNDING_SLACK, _SCALES, affordable_force, below_ramp_force, plan_cost_j
from .settings import ControllerSettings


def controller_state_batch(n: int) -> dict[str, np.ndarray]:
    """Fresh state arrays for :func:`controller_step_batch` over ``n`` cells."""
    z = np.zeros(n)
    return {"energy": z.copy(), "q1": z.copy(), "q2": z.copy(), "f1": z.copy(), "f2": z.copy(),
            "out": z.copy(), "app1": z.copy(), "app2": z.copy(), "app3": z.copy(), "started": np.zeros(n, bool),
            "overdrawn": z.copy(), "still": z.copy(),
            "spring": z.copy(), "kf": z.copy(), "kc": z.copy(), "full": z.copy(), "hist": np.zeros((_HIST, n)),
            "jh": np.zeros((_HIST, n)), "j3h": np.zeros((_HIST, n)),
            "hp": np.zeros(1, int), "sent": z.copy(), "pending": np.zeros(1, bool), "anchor": z.copy(),
            "below_ramp": np.zeros(n, bool)}


def _colgate_n_per_m(b_lo: Any, dt: Any, step_n: Any, q_m: Any) -> np.ndarray:
    """The Colgate spring's stiffness (N/m) per cell: ``2 b_lo / dt`` for the spring's damping
    ``b_lo`` (:meth:`ControllerSettings.spring_damping_ns_per_m`), at most one ramp step
    ``step_n`` per encoder count ``q_m`` (m) where both are > 0 (docs/runtime.md, Passivity
    item 0; :class:`PassivityController` computes the same in floats)."""
    kc = 2.0 * np.asarray(b_lo, float) / dt
    cap = (q_m > 0.0) & (step_n > 0.0)
    return np.where(cap, np.minimum(kc, step_n / np.where(cap, q_m, 1.0)), kc)


def _moving_wall_credit_batch(b_lo: Any, b_x: np.ndarray, ks: np.ndarray, span: np.ndarray, a: np.ndarray,
                              c: np.ndarray, q: Any) -> np.ndarray:
    """:func:`~hapticsdk.passivity.controller._moving_wall_credit` per cell: ``min_d b_lo (a +
    d)^2 / span - K_s (a + d) (c + d) / 2`` over ``d`` in ``[-q, q]`` (J)."""
    q = np.broadcast_to(np.asarray(q, float), a.shape)
    qa = b_x / span
    qb = 2.0 * b_lo * a / span - 0.5 * ks * (a + c)
    qc = b_lo * a * a / span - 0.5 * ks * a * c
    best = np.minimum(qc - qb * q + qa * q * q, qc + qb * q + qa * q * q)
    convex = qa > 0.0
    d = np.where(convex, -qb / (2.0 * np.where(convex, qa, 1.0)), 0.0)
    inside = convex & (np.abs(d) < q)
    best = np.where(inside, np.minimum(best, qc + d * (qb + qa * d)), best)
    finite = np.isfinite(a)
    if not finite.all():
        # a reading that is not a number earns no credit: the deficit alone
        ex = np.abs(c) + q
        best = np.where(finite, best, np.where(b_x < 0.0, b_x * ex * ex / span, 0.0))
    return best


def controller_step_batch(state: dict[str, np.ndarray], x_mm: np.ndarray, dt: "float | np.ndarray",
                          f_wall: np.ndarray, on: "np.ndarray | bool" = True,
                          settings: ControllerSettings | None = None,
                          damping_ns_per_m: "np.ndarray | float | None" = None,
                          resolution_mm: "np.ndarray | float | None" = None,
                          max_force_n: "np.ndarray | float | None" = None,
                          mass_kg: "np.ndarray | float | None" = None,
                          trusted_damping_ns_per_m: "np.ndarray | float | None" = None,
                          own_mm: "np.ndarray | None" = None) -> np.ndarray:
    """Vectorised :class:`PassivityController` over many independent cells (same law;
    forces equal to the scalar controller's to rounding, about 1e-8 N, not bit for bit).
    ``dt``, ``damping_ns_per_m`` (declared), ``resolution_mm`` and ``max_force_n`` may be
    per cell and override ``settings``; ``trusted_damping_ns_per_m`` (per cell or one
    number) is the damping credited in place of the settings' (a measured lower bound,
    :meth:`ControllerSettings.trusted_damping_ns_per_m`). ``own_mm`` (per cell), where the
    objects moved: the stylus's own displacement since the last reading (mm; the scalar
    step's ``own_mm``, its damping credit on it). Cells where ``on`` is False pass
    the wall force through. Call :func:`controller_commit_batch` after (without it, the next
    step takes the forces this one returned as applied). A period that is not
    > 0 (or NaN) in any cell raises :class:`~hapticsdk.errors.ValidationError` (field
    ``dt``), a reading that is not finite likewise (field ``x_mm``)."""
    pending = state.get("pending")
    if pending is not None and pending[0]:
        # no commit since the last step: the forces it returned are taken as applied
        controller_commit_batch(state, state["sent"])
    s = settings or ControllerSettings()
    x = np.asarray(x_mm, float)
    fw = np.nan_to_num(np.asarray(f_wall, float), nan=0.0, posinf=0.0, neginf=0.0)
    dt = np.broadcast_to(np.asarray(dt, float), x.shape)
    if not (dt > 0.0).all():
        # a period of 0 divides the damping credit by 0 (an infinite credit) and NaN
        # poisons the state; the servo's scalar controller sends 0 N on such a tick
        raise ValidationError(f"the period must be > 0 s in every cell, got {dt[~(dt > 0.0)][0]!r}", field="dt")
    if not np.isfinite(x).all():
        raise ValidationError(f"the readings must be finite numbers (mm), got {x[~np.isfinite(x)][0]!r}",
                              field="x_mm")
    bd = np.asarray(s.device_damping_ns_per_m if damping_ns_per_m is None else damping_ns_per_m, float)
    q = np.asarray(s.position_resolution_mm if resolution_mm is None else resolution_mm, float) * 1e-3
    fm = s.max_force_n if max_force_n is None else max_force_n
    started = state["started"]
    q1 = np.where(started, state["q1"], x)
    q2 = np.where(started, state["q2"], x)
    dq = (x - q1) * 1e-3
    f1 = state["f1"]
    b_lo = s.trusted_damping_ns_per_m(bd) if trusted_damping_ns_per_m is None \
        else np.asarray(trusted_damping_ns_per_m, float)
    u = state["energy"] + f1 * dq + 0.5 * q * np.abs(f1 - state["f2"])
    if "dw" in state:
        u = u + 0.5 * (state["f2"] - f1) * state["dw"]   # the last wall move at the mean extra (the scalar tick's)
    ex = np.maximum(np.abs(dq) - q, 0.0)
    ahead = 0.5 * (x - q2) * 1e-3
    hist = state["hist"]
    hist[:, ~started] = x[~started]
    hp = state["hp"][0] = (state["hp"][0] + 1) % _HIST
    hist[hp] = x
    d1 = np.abs(x - 2.0 * hist[hp - 1] + hist[hp - 2]) * 1e-3   # this tick's second difference (m)
    jerk = d1 - 2.0 * q
    for span in _SCALES[1:]:
        d2 = np.abs(x - 2.0 * hist[hp - span] + hist[hp - 2 * span]) * 1e-3 - 2.0 * q
        np.maximum(jerk, d2 / (span * span), out=jerk)
    np.maximum(jerk, 0.0, out=jerk)
    m = s.trusted_mass_kg(mass_kg)   # mass_trust x the declared mass (None: none declared)
    if m is not None:
        # the largest change of motion the readings allow (2 counts above the second
        # difference), up to what the held force's change over the last two ticks gives
        # the free arm (docs/runtime.md, Passivity item 5)
        dF = np.maximum(np.abs(state["app1"] - state["app2"]), np.abs(state["app1"] - state["app3"]))
        free = dF * (dt * dt / np.asarray(m, float))
        seen = d1 + 2.0 * q
        np.maximum(jerk, np.minimum(seen, free), out=jerk)
    jh = state["jh"]
    jh[hp] = jerk
    jerk = jh.max(axis=0)
    # the third difference beyond its quantisation (4 counts), largest over the window
    j3h = state["j3h"]
    j3h[hp] = np.maximum(np.abs(x - 3.0 * (hist[hp - 1] - hist[hp - 2]) - hist[hp - 3]) * 1e-3 - 4.0 * q, 0.0)
    j3 = j3h.max(axis=0)
    rest = state["still"]   # ticks the reading had rested before this one
    still = np.where(dq == 0.0, rest + 1.0, 0.0)
    state["still"] = still
    state["q2"] = q1
    state["q1"] = x.copy()
    out_prev = state["out"]
    if fm is None:
        full = np.maximum(state["full"], np.maximum(np.abs(fw), np.abs(out_prev)))
        state["full"] = full
    else:
        full = np.broadcast_to(np.asarray(fm, float), x.shape)
    depth = np.maximum(-x * 1e-3, 0.0)
    step = full * np.minimum(dt / s.ramp_time_s, 1.0)
    tn = dt if s.period_s is None else s.period_s      # the spring's period (the scalar tick's rule)
    sp = full * np.minimum(tn / s.ramp_time_s, 1.0)   # the ramp step at the spring's period
    kc = _colgate_n_per_m(s.spring_damping_ns_per_m(bd, b_lo), tn, sp, q)
    if s.period_s is not None:
        # never stiffer while compressed
        kc = np.where((state["kc"] > 0.0) & (kc > state["kc"]), state["kc"], kc)
    # the spring K_c (depth - o) and its anchor o (the scalar tick's rule): the anchor
    # follows the reading out where the reading is above it, and moves in where the
    # spring's rise is held to one ramp step
    incontact = (fw > 0.0) & (depth > 0.0)
    o = np.where(incontact, np.minimum(state.get("anchor", 0.0), depth), 0.0)
    spring = np.where(incontact, np.minimum(kc * (depth - o), fw), 0.0)
    if fm is not None:
        spring = np.minimum(spring, full)
    lim = state["spring"] + sp
    held = (spring > lim) & (kc > 0.0)
    spring = np.where(held, lim, spring)
    o = np.where(held, depth - spring / np.where(held, kc, 1.0), o)
    # and only as the reading moves in (the scalar tick's rule: a spring born compressed)
    inward = np.where(dq < 0.0, state["spring"] - kc * dq, state["spring"])
    held = (spring > inward * _ROUNDING_SLACK) & (kc > 0.0)
    spring = np.where(held, inward, spring)
    o = np.where(held, depth - spring / np.where(held, kc, 1.0), o)
    # the damping credited to the extra: b_lo less the spring's need, its secant stiffness
    # at the interval's start, or its full slope K_c on an interval entering from outside
    # (the scalar tick's rule)
    ks = np.where((state["kf"] == 0.0) & (spring > 0.0), kc, state["kf"])
    b_x = b_lo - 0.5 * ks * dt
    # a deficit (a late tick: the spring needs more than b_lo) is charged with the largest
    # displacement the readings allow
    if own_mm is None:
        ex = np.where(b_x < 0.0, np.abs(dq) + q, ex)
        u = u - b_x * ex * ex / dt
        if "dw" in state:
            state["dw"] = np.zeros_like(x)   # at rest this tick
    else:
        # a moving object: the credit on the stylus's own motion (the scalar tick's rule)
        own = np.asarray(own_mm, float) * 1e-3
        u = u - _moving_wall_credit_batch(b_lo, b_x, ks, dt, own, dq, q)
        state["dw"] = np.nan_to_num(own - dq, nan=0.0, posinf=0.0, neginf=0.0)   # the wall's move (the scalar tick's)
    c_m = 0.0 if m is None else dt * dt / (2.0 * np.asarray(m, float))
    e0 = np.minimum(full * 0.5 * q, s.energy_allowance_j)
    idle = (fw == 0.0) & (out_prev == 0.0) & (f1 == 0.0)
    u = np.where(idle, np.maximum(u, 0.0), u)
    state["energy"] = np.where(started, u, 0.0)
    state["overdrawn"] = np.maximum(state["overdrawn"], np.where(started & ~idle, u - e0, 0.0))
    sg = np.where((fw > 0.0) | ((fw == 0.0) & (out_prev >= 0.0)), 1.0, -1.0)
    target = sg * fw
    if fm is not None:
        target = np.minimum(target, full)
    target = target - spring
    p = sg * f1
    lo = np.where(p - step >= 0.0, p - step, np.minimum(p + step, 0.0))
    if fm is not None:
        lo = np.minimum(lo, full - spring)   # not past the device's limit (see the scalar tick)
    rise = np.maximum(spring - state["spring"], 0.0)   # the whole force rises by at most s (item 3)
    hi = np.maximum(np.minimum(p + step - rise, target), lo)
    # and falls by at most s where the book affords it: the extra takes up what the spring
    # gave up this tick, never above what it held (the scalar tick's rule, item 7)
    fall = np.maximum(state["spring"] - spring, 0.0)
    hi = np.where(p > 0.0, np.maximum(hi, np.minimum(p - step + fall, p)), hi)
    a = hi
    stuck = np.zeros(x.shape, bool)
    if s.energy_bound:
        lead = sg * ahead + (1.5 + 0.5 * hi / np.where(step > 0, step, 1.0)) * jerk + j3 + q / np.maximum(still, 2.0)
        a = affordable_force(e0 - u, lo, hi, p, lead, c_m, step, 0.5 * q)
        # the book overdrawn and even the ramp down unaffordable: below the ramp (the scalar tick's rule)
        stuck = (a == lo) & (lo > 0.0) & (u > e0) & (plan_cost_j(lo, p, lead, c_m, step, 0.5 * q) > e0 - u)
        if stuck.any():
            a = np.where(stuck, below_ramp_force(e0 - u, lo, p, lead, c_m, step, 0.5 * q), a)
        # one count out after a rest of more than 2 ticks and nothing fits, not even the ramp
        # down (taken anyway): the take-up of the spring's fall priced at what it adds to
        # that ramp, within what is left of the allowance (the scalar tick's rule, item 3,
        # "the count crossing")
        one = np.abs(dq) <= q + _BRANCH_TOL * (np.abs(x) + np.abs(q1)) * 1e-3
        cross = ~stuck & (a == lo) & (p > 0.0) & (fall > 0.0) & (u < e0) & one & (rest > 2.0)
        if cross.any():
            base = plan_cost_j(lo, p, lead, c_m, step, 0.5 * q)
            hold = np.minimum(p - step + fall, p)
            cross &= (base > e0 - u) & (hold > lo)
            if cross.any():
                a = np.where(cross, affordable_force(e0 - u + base, lo, np.where(cross, hold, hi), p, lead, c_m, step,
                                                     0.5 * q), a)
    if "below_ramp" in state:
        state["below_ramp"] = stuck & started & ~idle
    spring = np.where(started & ~idle, spring, 0.0)
    state["spring"] = spring
    if "anchor" in state:
        state["anchor"] = np.where(started & ~idle, o, 0.0)   # a first reading books nothing (the scalar tick's rule)
    state["kf"] = np.where(spring > 0.0, np.where(o == 0.0, spring / np.where(depth > 0.0, depth, 1.0), kc), 0.0)
    state["kc"] = np.where(spring > 0.0, kc, 0.0)
    out = np.where(started & ~idle, spring + sg * a, 0.0)
    state["out"] = out
    state["started"] = np.ones_like(started)
    sent = np.where(on, out, fw)
    if pending is not None:
        state["sent"] = sent.copy()
        pending[0] = True
    return sent


def controller_commit_batch(state: dict[str, np.ndarray], f_applied: np.ndarray) -> None:
    """Record the forces actually applied over the coming interval (N)."""
    if "pending" in state:
        state["pending"][0] = False
    f = np.nan_to_num(np.asarray(f_applied, float), nan=0.0, posinf=0.0, neginf=0.0)
    sp = state["spring"]
    low = (sp > 0.0) & (f < sp)
    if low.any():
        # a spring the device did not apply (the scalar commit's rule): lowered to the force
        # applied, its anchor moved in, the energy the move took out credited on its K_c branch
        kc = state["kc"]
        depth = -state["q1"] * 1e-3
        fa = np.maximum(f, 0.0)
        kc1 = np.where(low, kc, 1.0)
        o = state.get("anchor", np.zeros_like(sp))
        branch = low & (np.abs(sp - kc * (depth - o)) <= _BRANCH_TOL * sp)
        state["energy"] = state["energy"] - np.where(branch, (sp * sp - fa * fa) / (2.0 * kc1), 0.0)
        dw = state.get("dw")
        if dw is not None:
            # the part of the spring's rise the wall's move did not pay (the scalar commit's rule)
            unpaid = np.where(branch | (dw > 0.0), 0.5 * (sp - fa) * dw, 0.0)
            state["energy"] = state["energy"] + np.where(low, unpaid, 0.0)
        pos = low & (fa > 0.0)
        if "anchor" in state:
            state["anchor"] = np.where(pos, depth - fa / kc1, np.where(low, np.maximum(depth, 0.0), o))
        state["kf"] = np.where(pos, kc, np.where(low, 0.0, state["kf"]))
        state["kc"] = np.where(low & ~pos, 0.0, kc)
        state["spring"] = np.where(low, fa, sp)
    state["f2"] = state["f1"]
    state["app3"] = state["app2"]
    state["app2"] = state["app1"]
    state["app1"] = f.copy()
    state["f1"] = f - state["spring"]   # the extra actually held (its ramp starts from it)
    state["out"] = f.copy()

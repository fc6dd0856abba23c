"""The arm's damping, measured hands off: a lower bound the stiff-wall controller may
credit in place of the declared damping, which it does not credit by default (docs/runtime.md, Passivity,
"Measured damping").

Nobody holds the stylus. The arm is driven by a force doublet pair (``+F, -F, -F, +F``,
each for ``tau``; net impulse 0 and first moment 0, so an undamped arm ends where it
started, at most ``F tau^2 / m`` away), repeated with rests between
(:func:`excitation`). Its encoder readings are fitted with the exact zero-order-hold
response of ``m y'' = F + F_0 - b y'`` (:func:`fit_damping`): ``alpha = b/m`` by a 1-D
search, the rest (start, start velocity, ``1/m``, ``F_0/m``) by linear least squares at
each ``alpha``. ``F_0`` takes up a constant force the arm feels on its own (gravity left
over, a cable).

The bound is a worst case, not a confidence level: ``b_lo = max(0, b_hat - e_max
||w||_1)``. To first order the fitted damping moves by ``w . e`` when the readings move by
``e`` (``w = J (J'J)^-1 grad b``, ``J`` the fit's Jacobian), and a reading's error is at
most ``e_max``: half an encoder count, or the largest residual where the model explains
the readings less well than that. Quantisation errors are not independent noise (a
repeated run crosses the same counts at the same places), so a standard error would not
bound them: measured, a bound of 3.09 standard errors was exceeded in 1 % to 11 % of
simulated arms; the worst case in none (docs/runtime.md, "Measured damping"). The
standard error is reported (``damping_se_ns_per_m``: residual variance at least
``Delta^2/12``, inflated by the residuals' lag-1 correlation ``(1 + rho)/(1 - rho)``).

A run paced on a clock (:func:`measure_damping` with ``realtime=True``,
:func:`play_damping_run`) is fitted with each step as long as it was
measured, and the margin also covers what the timestamps leave open: forces reaching the
arm late, readings sampled off their timestamps, forces dropped as stale
(:func:`timing_error_ns_per_m`; docs/calibration.md, "A run timed by the loop's clock").

What the fit does not see: Coulomb friction (a viscous fit to a Coulomb decay over-states
the damping at speed: the residuals grow, so the bound shrinks, but it is not proved to
stay below), a damping that changes over the workspace, a hand on the stylus. The
simulated arms of the benchmark have none of these.
"""

from __future__ import annotations

import gc
import math
import time
from dataclasses import MISSING, asdict, dataclass, field, fields
from typing import Any

import numpy as np

from ..argcheck import number, number_array
from ..errors import ValidationError

#: Largest excursion of the hands-off run (m): 5 mm, well inside any desktop device's
#: workspace and many counts of any encoder the SDK meets (0.001-0.2 mm).
TRAVEL_M = 5.0e-3
#: Share of the force limit the run uses: gentle on the arm, and far from saturation.
FORCE_SHARE = 0.25
#: Shortest segment of the doublet in ticks: the response within a segment is then
#: resolved by ten readings.
MIN_SEGMENT_TICKS = 10
#: Doublet pairs in one run, each followed by a rest of ``4 tau`` (free decay).
PATTERNS = 6


def excitation(period_s: float, max_force_n: float, mass_kg: float, *, travel_m: float = TRAVEL_M
               ) -> np.ndarray:
    """The hands-off run's forces (N), one per period: :data:`PATTERNS` doublet pairs
    ``+F, -F, -F, +F`` (each segment ``tau``) with rests of ``4 tau``; ``F`` at most
    :data:`FORCE_SHARE` of the force limit and ``F tau^2 / m <= travel_m`` for the declared
    mass ``mass_kg``; ``tau`` at least :data:`MIN_SEGMENT_TICKS` periods."""
    for name, v in (("period_s", period_s), ("max_force_n", max_force_n), ("mass_kg", mass_kg),
                    ("travel_m", travel_m)):
        number(v, name, lo=0.0, lo_open=True)
    f = FORCE_SHARE * max_force_n
    ticks = math.sqrt(travel_m * mass_kg / f) / period_s
    if not 8 * PATTERNS * ticks <= MAX_RUN_TICKS:
        raise ValidationError(f"the run would take {8 * PATTERNS * ticks:.3g} periods, more than the {MAX_RUN_TICKS} "
                              f"a run file can hold (period {period_s!r} s, mass {mass_kg!r} kg, force limit "
                              f"{max_force_n!r} N)", field="period_s")
    n = max(int(round(ticks)), MIN_SEGMENT_TICKS)
    tau = n * period_s   # whole ticks; the force then keeps F tau^2 / m within the travel
    f = min(f, travel_m * mass_kg / (tau * tau))
    one = np.concatenate([np.full(n, f), np.full(2 * n, -f), np.full(n, f), np.zeros(4 * n)])
    return np.tile(one, PATTERNS)


def _hg(alpha: float, dt: float) -> tuple[float, float, float]:
    """``a = exp(-alpha T)``, ``h = (1 - a)/alpha``, ``g = (T - h)/alpha`` (series near 0)."""
    x = alpha * dt
    a = math.exp(-x)
    if x < 1e-4:
        h = dt * (1.0 - x / 2.0 + x * x / 6.0)
        g = dt * dt * (0.5 - x / 6.0 + x * x / 24.0)
    else:
        h = -math.expm1(-x) / alpha
        g = (dt - h) / alpha
    return a, h, g


def _basis(alpha: float, dt: float, f: np.ndarray) -> np.ndarray:
    """Readings' model columns at ``alpha``: start, start velocity, force/m, 1/m (offset)."""
    from scipy.signal import lfilter

    a, h, g = _hg(alpha, dt)
    n = f.size
    u = np.stack([np.zeros(n), f, np.ones(n)])
    # v_{k+1} = a v_k + h u_k (v_0 = 0), y_{k+1} = y_k + h v_k + g u_k
    v = lfilter([0.0, h], [1.0, -a], u, axis=1)
    dy = h * v + g * u
    cols = np.zeros((n + 1, 4))
    cols[:, 0] = 1.0
    cols[1:, 1] = np.cumsum(h * a ** np.arange(n))   # unit start velocity, no force
    cols[1:, 2] = np.cumsum(dy[1])
    cols[1:, 3] = np.cumsum(dy[2])
    return cols


def _hg_steps(alpha: float, dt: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_hg` of every step of durations ``dt`` (s): arrays ``a``, ``h``, ``g``."""
    x = alpha * dt
    a = np.exp(-x)
    h = dt * (1.0 - x / 2.0 + x * x / 6.0)
    g = dt * dt * (0.5 - x / 6.0 + x * x / 24.0)
    big = x >= 1e-4
    if big.any():
        h[big] = -np.expm1(-x[big]) / alpha
        g[big] = (dt[big] - h[big]) / alpha
    return a, h, g


def _scan(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``x_0 = 0``, ``x_{k+1} = a_k x_k + b_k``: the ``len(a) + 1`` values (a recurrence
    whose coefficient changes per step, which ``lfilter`` does not take)."""
    from itertools import accumulate

    return np.fromiter(accumulate(zip(a.tolist(), b.tolist()), lambda x, ab: ab[0] * x + ab[1], initial=0.0),
                       float, count=a.size + 1)


def _basis_steps(alpha: float, dt: np.ndarray, f: np.ndarray, on: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_basis` of a run whose steps last ``dt`` (s, one per force), force ``k`` held
    for ``on[k] <= dt[k]`` (s; default the whole step) and then 0 N: the readings' columns,
    and the velocities at the readings (same columns: start, start velocity, force/m,
    1/m). With every ``dt`` equal and the forces held it is :func:`_basis` to rounding."""
    a, h, g = _hg_steps(alpha, dt)
    n = f.size
    cols = np.zeros((n + 1, 4))
    vel = np.zeros((n + 1, 4))
    cols[:, 0] = 1.0
    vel[0, 1] = 1.0
    vel[1:, 1] = np.cumprod(a)              # unit start velocity, no force
    cols[1:, 1] = np.cumsum(h * vel[:-1, 1])
    # a force held for p of a step of T, then 0: v gains exp(-alpha (T - p)) h(p) u, y
    # gains (g(p) + h(p) h(T - p)) u (the semigroup of the hold's response)
    if on is None:
        hf, gf = h, g
    else:
        _, hp, gp = _hg_steps(alpha, on)
        ar, hr, _ = _hg_steps(alpha, dt - on)
        hf, gf = ar * hp, gp + hp * hr
    for j, u, hu, gu in ((2, f, hf, gf), (3, np.ones(n), h, g)):
        # v_{k+1} = a_k v_k + hu_k u_k (v_0 = 0), y_{k+1} = y_k + h_k v_k + gu_k u_k
        v = _scan(a, hu * u)
        vel[:, j] = v
        cols[1:, j] = np.cumsum(h * v[:-1] + gu * u)
    return cols, vel


@dataclass
class DampingFit:
    """Result of :func:`fit_damping` (scipy.optimize style: ``x``, ``fun``, ``success``,
    ``message``, ``nfev``).

    Attributes:
        x: ``[mass_kg, damping_ns_per_m, offset_n]``, the fitted arm.
        fun: root-mean-square residual of the readings (m).
        damping_se_ns_per_m: standard error of the fitted damping (N*s/m).
        trusted_damping_ns_per_m: the lower bound ``max(0, b - worst_error_ns_per_m)`` (0
            when the fit failed): what :class:`~hapticsdk.passivity.ControllerSettings`
            takes as ``measured_damping_ns_per_m``.
        worst_error_ns_per_m: the largest change of the fitted damping the readings' errors
            can make (first order, see the module docstring).
        residual_correlation: lag-1 correlation of the residuals (the variance's inflation
            is ``(1 + rho)/(1 - rho)`` for ``rho > 0``).
        readings: number of readings fitted.
        runtime_s: wall time of the fit (s).
        timing_error_ns_per_m: the part of ``worst_error_ns_per_m`` that covers a run's
            timing: forces reaching the arm late, readings sampled off their timestamps,
            forces dropped as stale (0 for a run without timestamps).
    """

    x: np.ndarray
    fun: float
    success: bool
    message: str
    nfev: int
    damping_se_ns_per_m: float
    trusted_damping_ns_per_m: float
    worst_error_ns_per_m: float = float("nan")
    residual_correlation: float = 0.0
    readings: int = 0
    runtime_s: float = 0.0
    timing_error_ns_per_m: float = 0.0

    @property
    def mass_kg(self) -> float:
        """Fitted moving mass m (kg), ``x[0]``."""
        return float(self.x[0])

    @property
    def damping_ns_per_m(self) -> float:
        """Fitted damping b (N s/m), ``x[1]``: the estimate, not the bound the controller trusts."""
        return float(self.x[1])

    @property
    def offset_n(self) -> float:
        """Fitted constant force F0 (N), ``x[2]``: gravity and cable pull the run saw."""
        return float(self.x[2])

    def to_dict(self) -> dict[str, Any]:
        """Every field as plain JSON values (``x`` as a list)."""
        d = asdict(self)
        d["x"] = [float(v) for v in self.x]
        return d


def _per_step(v: Any, n: int, name: str) -> np.ndarray:
    """A timing bound given once for the run or once per step/reading: ``n`` values >= 0
    (NaN or inf: not bounded, which the fit reports)."""
    a = np.asarray(number_array(v, name, ndim=(0, 1), finite=False), float)
    if a.ndim == 0:
        a = np.full(n, float(a))
    if a.size != n:
        raise ValidationError(f"needs one value or {n}, got {a.size}", field=name)
    if (a < 0).any():
        raise ValidationError("must be >= 0 s", field=name)
    return a


def _window_max(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``max(x[lo_k .. hi_k])`` for each k (``lo <= k <= hi``, windows of a few entries)."""
    n = x.size
    k = np.arange(n)
    out = x.copy()
    for d in range(1, int(max((k - lo).max(initial=0), (hi - k).max(initial=0))) + 1):
        i = np.clip(k - d, 0, n - 1)
        out = np.where(k - d >= lo, np.maximum(out, x[i]), out)
        i = np.clip(k + d, 0, n - 1)
        out = np.where(k + d <= hi, np.maximum(out, x[i]), out)
    return out


def timing_error_ns_per_m(w: np.ndarray, kappa: float, alpha: float, t: np.ndarray, f: np.ndarray,
                          speed: np.ndarray, force_delay_s: np.ndarray, reading_delay_s: np.ndarray,
                          may_drop_after_s: float | None = None) -> float:
    """The most the fitted damping can exceed the truth (first order, as the readings'
    term) because forces reached the arm later than their ticks' timestamps, readings were
    sampled off theirs, or forces were dropped as stale (docs/calibration.md, "A run timed
    by the loop's clock").

    ``w``: the fit's sensitivity of the damping to each reading (N s/m per m); ``kappa``,
    ``alpha``: the fitted ``1/m`` and ``b/m``; ``t``: the readings' timestamps (s, one more
    than the forces ``f``, N); ``speed``: the model's |velocity| at each reading (m/s);
    ``force_delay_s`` (per force): the most force k may lag its timestamp (forces arrive in
    order); ``reading_delay_s`` (per reading): the most a reading's sample instant may be
    off its timestamp, either way; ``may_drop_after_s``: a force not followed within this
    may have been dropped to 0 N (None: it was held).

    A force error ``c`` lasting ``l`` inside step ``i`` changes the velocity at
    ``t_{i+1}`` by ``kappa c [0, l]`` and the position by ``kappa c [0, l h_i]``; both
    then move freely, so the fitted damping rises by at most ``|c| l sigma_i`` with
    ``sigma_i = kappa (h_i (s W_{i+1})^+ + (s S_{i+1})^+)``, ``s`` the sign of ``c``,
    ``W_m = sum_{j>=m} w_j``, ``S_m = sum_{j>=m} w_j G(t_j - t_m)``, ``G(u) = (1 -
    exp(-alpha u))/alpha``. Force k's switch from ``f_{k-1}`` (``f_{-1}`` = 0 N: the run
    starts from the held 0 N) is such an error, ``c = f_{k-1} - f_k``, for at most
    ``force_delay_s[k]``; a dropped force is one of ``c = -f_k`` for at most ``dt_k +
    force_delay_s[k+1] - may_drop_after_s``. Both signs are known, so only the rise
    counts. A reading sampled up to ``rho`` off its timestamp is off by at most ``rho``
    times the largest model speed within ``rho`` of it (within a step the speed is
    monotone: the ends of the steps there bound it), either sign."""
    n = f.size
    dt = np.diff(t)
    a, h, _ = _hg_steps(alpha, dt)
    W = np.concatenate([np.cumsum(w[::-1])[::-1], [0.0]])     # W_m, m = 0..n+1
    # S_m = h_m W_{m+1} + a_m S_{m+1}, S_n = 0: a scan run backwards
    S = _scan(a[::-1], (h * W[1:n + 1])[::-1])[::-1]          # S_m, m = 0..n
    Wn, Sn = W[1:n + 1], S[1:]
    rise = {1.0: kappa * (h * np.maximum(Wn, 0.0) + np.maximum(Sn, 0.0)),    # per step i = 0..n-1
            -1.0: kappa * (h * np.maximum(-Wn, 0.0) + np.maximum(-Sn, 0.0))}
    steps = np.arange(n)

    def pulses(c: np.ndarray, length: np.ndarray, span: np.ndarray) -> float:
        # error k lies within [t_k, t_k + span_k]: the largest rise of the steps there
        last = np.clip(np.searchsorted(t, t[:-1] + span, side="left") - 1, steps, n - 1)
        worst = np.where(c >= 0.0, _window_max(rise[1.0], steps, last), _window_max(rise[-1.0], steps, last))
        return float(np.sum(np.abs(c) * length * worst))

    f_prev = np.concatenate([[0.0], f[:-1]])
    err = pulses(f_prev - f, force_delay_s, force_delay_s)
    if may_drop_after_s is not None:
        d_next = np.concatenate([force_delay_s[1:], [force_delay_s.max(initial=0.0)]])
        lost = np.maximum(dt + d_next - may_drop_after_s, 0.0)
        if lost.any():
            err += pulses(-f, lost, dt + d_next)
    if reading_delay_s.any():
        # the steps within rho of the reading: their ends' speeds bound the speed there
        lo = np.clip(np.searchsorted(t, t - reading_delay_s, side="right") - 1, 0, n)
        hi = np.clip(np.searchsorted(t, t + reading_delay_s, side="left"), 0, n)
        err += float(np.sum(np.abs(w) * reading_delay_s * _window_max(speed, lo, hi)))
    return err


def fit_damping(forces_n: Any, readings_mm: Any, period_s: float, resolution_mm: float = 0.0, *,
                times_s: Any = None, force_delay_s: Any = 0.0, reading_delay_s: Any = 0.0,
                hold_s: float | None = None, may_drop_after_s: float | None = None) -> DampingFit:
    """Fit a hands-off run: ``forces_n`` (N, one per period, as applied) and the encoder
    readings ``readings_mm`` (mm, ``len(forces_n) + 1``: before each force, then the last),
    ``period_s`` (s), the encoder resolution ``resolution_mm`` (mm; 0 = exact). See the
    module docstring for the model and the bound.

    A run paced on a clock (:func:`measure_damping` with ``realtime=True``) gives the
    readings' timestamps ``times_s`` (s, one per reading): each step then lasts as
    measured, and the bound also covers what the timestamps do not pin down
    (:func:`timing_error_ns_per_m`): ``force_delay_s`` (one, or one per force), the most
    a force may reach the arm after its tick's timestamp; ``reading_delay_s`` (one, or
    one per reading), the most a reading's sample instant may be off its timestamp;
    ``hold_s``, the time after which the device drops a force not followed by another
    (a simulated device's safety layer drops a stale command; modelled, and only with
    no force delay); ``may_drop_after_s``, the same where it is not known whether the
    device drops it (bounded). A delay that is not finite is not bounded: the fit then
    fails and credits nothing. Without ``times_s`` every step lasts ``period_s`` (the result
    is the one of a fit without these arguments, bit for bit)."""
    # scipy's modules are imported here, lazily (not at the calibration package's import,
    # which a render pays) and before the clock: runtime_s is the fit's, not the import's
    import scipy.optimize  # noqa: F401
    import scipy.signal  # noqa: F401
    t0 = time.perf_counter()
    f = number_array(forces_n, "forces_n", ndim=(1,), finite=False)
    y = number_array(readings_mm, "readings_mm", ndim=(1,), finite=False) * 1e-3
    if f.size < 8 or y.size != f.size + 1:
        raise ValidationError(f"need at least 8 forces and one reading more than forces, got {f.size} and {y.size}",
                              field="readings_mm")
    if not (np.isfinite(f).all() and np.isfinite(y).all()):
        raise ValidationError("forces and readings must be finite", field="readings_mm")
    number(period_s, "period_s", lo=0.0, lo_open=True)
    number(resolution_mm, "resolution_mm", lo=0.0)
    q = resolution_mm * 1e-3
    nfev = 0
    if times_s is None:
        tt = None
        dur = f.size * period_s

        def basis(alpha: float) -> np.ndarray:
            return _basis(alpha, period_s, f)
    else:
        tt = number_array(times_s, "times_s", ndim=(1,))
        dts = np.diff(tt)
        if tt.size != y.size or not (dts > 0).all():
            raise ValidationError(f"needs one increasing timestamp per reading ({y.size}), got {tt.size}",
                                  field="times_s")
        fd = _per_step(force_delay_s, f.size, "force_delay_s")
        rd = _per_step(reading_delay_s, y.size, "reading_delay_s")
        on = None
        if hold_s is not None:
            number(hold_s, "hold_s", lo=0.0)
            if fd.any():
                raise ValidationError("a drop is modelled only where forces reach the arm at their timestamps "
                                      "(force_delay_s 0); give may_drop_after_s instead", field="hold_s")
            on = np.minimum(dts, hold_s)
        if may_drop_after_s is not None:
            number(may_drop_after_s, "may_drop_after_s", lo=0.0)
        dur = float(tt[-1] - tt[0])

        def basis(alpha: float) -> np.ndarray:
            return _basis_steps(alpha, dts, f, on)[0]

    def solve(alpha: float) -> tuple[float, np.ndarray, np.ndarray]:
        nonlocal nfev
        nfev += 1
        B = basis(alpha)
        c, *_ = np.linalg.lstsq(B, y, rcond=None)
        r = y - B @ c
        return float(r @ r), c, B

    def failed(msg: str) -> DampingFit:
        return DampingFit(x=np.full(3, np.nan), fun=float("nan"), success=False, message=msg, nfev=nfev,
                          damping_se_ns_per_m=float("nan"), trusted_damping_ns_per_m=0.0,
                          readings=int(y.size), runtime_s=time.perf_counter() - t0)

    if tt is not None and not (np.isfinite(fd).all() and np.isfinite(rd).all()):
        return failed("the timing of the forces or the readings is not bounded (no latency declared or "
                      "measured): the damping cannot be bounded")
    if np.ptp(y) < 4.0 * max(q, 1e-12):
        return failed("the arm did not move by 4 encoder counts: nothing to fit (is it held or blocked?)")
    # alpha = b/m: 0, then a log grid from a decay too slow to see in the run to one within a tick
    grid = np.concatenate([[0.0], np.geomspace(1e-2 / dur, 2.0 / period_s, 60)])
    ss = np.array([solve(a)[0] for a in grid])
    i = int(np.argmin(ss))
    lo = grid[max(i - 1, 0)]
    hi = grid[min(i + 1, grid.size - 1)]
    alpha = float(grid[i])
    if hi > lo:
        from scipy.optimize import minimize_scalar

        res = minimize_scalar(lambda a: solve(a)[0], bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-10 * max(hi, 1.0)})
        if res.fun <= ss[i]:
            alpha = float(res.x)
    sse, c, B = solve(alpha)
    kappa = float(c[2])
    if not kappa > 0:
        return failed("the fitted mass is not positive: the readings do not follow the forces")
    # covariance of (alpha, start, v0, kappa, kappa F0): the Jacobian with d/d alpha by
    # central differences of the model at the fitted linear coefficients
    d_a = max(abs(alpha), 1.0 / dur) * 1e-4
    model = lambda a: basis(a) @ c  # noqa: E731
    ja = (model(alpha + d_a) - model(max(alpha - d_a, 0.0))) / (alpha + d_a - max(alpha - d_a, 0.0))
    J = np.column_stack([ja, B])
    r = y - B @ c
    dof = max(y.size - J.shape[1], 1)
    s2 = max(sse / dof, q * q / 12.0)
    rc = r - r.mean()
    den = float(rc @ rc)
    rho = float(rc[1:] @ rc[:-1] / den) if den > 0 else 0.0
    rho = min(max(rho, 0.0), 0.999)
    infl = (1.0 + rho) / (1.0 - rho)
    b = alpha / kappa
    g = np.zeros(J.shape[1])   # the gradient of b = alpha / kappa
    g[0] = 1.0 / kappa
    g[3] = -alpha / (kappa * kappa)
    try:
        z = np.linalg.solve(J.T @ J, g)   # (J'J)^-1 g: the variance's and the worst case's
    except np.linalg.LinAlgError:
        return failed("the run does not determine the damping (singular fit)")
    var_b = float(g @ z) * s2 * infl
    if not (math.isfinite(var_b) and var_b >= 0):
        return failed("the fit's covariance is not usable")
    se = math.sqrt(var_b)
    # worst case: the fitted damping moves by w . e for reading errors e (linearised,
    # w = J (J'J)^-1 g), at most e_max ||w||_1 for |e_k| <= e_max; e_max is half a count,
    # or the largest residual where the model explains the readings less well than that
    w = J @ z
    e_max = max(0.5 * q, float(np.abs(r).max()))
    worst = e_max * float(np.abs(w).sum())
    timing = 0.0
    if tt is not None:
        speed = np.abs(_basis_steps(alpha, dts, f, on)[1] @ c)
        timing = timing_error_ns_per_m(w, kappa, alpha, tt, f, speed, fd, rd, may_drop_after_s)
        worst += timing
    trusted = max(0.0, b - worst)
    return DampingFit(x=np.array([1.0 / kappa, b, float(c[3]) / kappa]), fun=math.sqrt(sse / y.size),
                      success=True, message="fitted", nfev=nfev, damping_se_ns_per_m=se,
                      trusted_damping_ns_per_m=trusted, worst_error_ns_per_m=worst,
                      residual_correlation=rho,
                      readings=int(y.size), runtime_s=time.perf_counter() - t0, timing_error_ns_per_m=timing)


@dataclass
class DampingCalibration:
    """A saved hands-off damping measurement of one device (calibration kind
    ``"damping"``, docs/calibration.md): what :meth:`ControllerSettings.for_device
    <hapticsdk.passivity.ControllerSettings.for_device>` credits as the arm's damping.

    Attributes:
        trusted_damping_ns_per_m: the fit's lower bound (N*s/m), the figure credited.
        damping_ns_per_m: the fitted damping (N*s/m).
        worst_error_ns_per_m: the bound's margin (N*s/m).
        mass_kg: the fitted apparent mass (kg).
        period_s: the run's period (s).
        resolution_mm: the encoder resolution the fit assumed (mm).
        readings: readings fitted.
        serial: the device's serial number (None: any device).
        generated: True when the run was simulated, not measured.
        source: provenance in words.
        extra: free details.
    """

    trusted_damping_ns_per_m: float
    damping_ns_per_m: float
    worst_error_ns_per_m: float
    mass_kg: float
    period_s: float
    resolution_mm: float
    readings: int
    serial: str | None = None
    generated: bool = False
    source: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("trusted_damping_ns_per_m", "damping_ns_per_m", "worst_error_ns_per_m", "resolution_mm",
                     "mass_kg", "period_s"):
            number(getattr(self, name), name, lo=0.0, lo_open=name in ("mass_kg", "period_s"))
        # a count of readings is a whole number >= 1 (the schema's rule; "1", True, 1e308 are not)
        if number(self.readings, "readings", lo=1, integer=True) > 2 ** 53:
            raise ValidationError(f"must be a whole number of readings, got {self.readings!r}", field="readings")
        if not isinstance(self.generated, (bool, np.bool_)):
            raise ValidationError(f"must be True or False, got {self.generated!r:.60}", field="generated")
        if self.trusted_damping_ns_per_m > self.damping_ns_per_m:
            raise ValidationError(f"the lower bound {self.trusted_damping_ns_per_m!r} exceeds the fitted damping "
                                  f"{self.damping_ns_per_m!r}", field="trusted_damping_ns_per_m")
        # the bound is the fit less its margin (fit_damping: max(0, b - worst)); a bound
        # above that was not produced by a fit (an edited file), and the controller would
        # credit damping that nothing measured. Rounding of a stored decimal is allowed.
        top = max(0.0, self.damping_ns_per_m - self.worst_error_ns_per_m)
        if self.trusted_damping_ns_per_m > top + 1e-9 * max(1.0, self.damping_ns_per_m):
            raise ValidationError(f"the lower bound {self.trusted_damping_ns_per_m!r} exceeds the fitted damping less "
                                  f"its margin, {top!r}: not a fit's bound", field="trusted_damping_ns_per_m")

    @classmethod
    def from_fit(cls, fit: DampingFit, *, period_s: float, resolution_mm: float, serial: str | None = None,
                 generated: bool = False, source: str = "") -> "DampingCalibration":
        """The calibration of a successful :func:`fit_damping` result."""
        if not fit.success:
            raise ValidationError(f"the fit failed: {fit.message}", field="fit")
        return cls(trusted_damping_ns_per_m=fit.trusted_damping_ns_per_m,
                   damping_ns_per_m=max(fit.damping_ns_per_m, fit.trusted_damping_ns_per_m),
                   worst_error_ns_per_m=fit.worst_error_ns_per_m, mass_kg=fit.mass_kg, period_s=float(period_s),
                   resolution_mm=float(resolution_mm), readings=fit.readings, serial=serial,
                   generated=bool(generated), source=source)

    def to_dict(self) -> dict[str, Any]:
        """The stored form (``kind`` ``"damping"``), as the calibration schema describes it."""
        d = {"kind": "damping", **asdict(self)}
        d["readings"] = int(self.readings)
        return d

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "DampingCalibration":
        """Inverse of :meth:`to_dict` (``kind`` and unknown keys are ignored; the store validates first)."""
        if not isinstance(data, dict):
            raise ValidationError(f"must be a mapping, got {type(data).__name__}", field="damping")
        own = fields(cls)
        missing = [f.name for f in own if f.default is MISSING and f.default_factory is MISSING
                   and f.name not in data]
        if missing:
            raise ValidationError(f"missing {', '.join(missing)}", field="damping")
        return cls(**{f.name: data[f.name] for f in own if f.name in data})


def simulated_run(period_s: float, mass_kg: float, damping_ns_per_m: float, resolution_mm: float,
                  max_force_n: float = 3.3, *, declared_mass_kg: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A GENERATED hands-off run on the simulated arm (:func:`hapticsdk.sim.arm.free_arm_readings_mm`)
    of mass ``mass_kg``: ``(forces_n, readings_mm)`` of :func:`excitation` sized by
    ``declared_mass_kg`` (the mass the device declares; default ``mass_kg``), as a run on a
    device is sized by its declaration."""
    from ..sim.arm import ArmParams, free_arm_readings_mm

    f = excitation(period_s, max_force_n, mass_kg if declared_mass_kg is None else declared_mass_kg)
    arm = ArmParams(mass_kg=mass_kg, damping_ns_per_m=damping_ns_per_m, max_force_n=max_force_n,
                    encoder_resolution_mm=resolution_mm)
    return f, free_arm_readings_mm(period_s, arm, f)


#: Largest run or excitation CSV read (bytes): an hour at 4 kHz is about 14 M rows of a
#: few bytes; a hands-off run is a few thousand.
MAX_CSV_BYTES = 64 * 1024 * 1024
#: Longest run (periods) :func:`excitation` makes: the most rows a run file of
#: :data:`MAX_CSV_BYTES` holds at two floats per row (``repr`` takes at most 24 characters,
#: plus a comma and a newline: 50 bytes), so the SDK can read back every run it asks for.
MAX_RUN_TICKS = MAX_CSV_BYTES // 50


def _csv_table(path: Any, field_name: str, columns: tuple[str, ...]) -> tuple[dict[str, int], list[list[str]]]:
    """``(column -> index, rows below the header)`` of a CSV that has ``columns`` (read by
    :func:`hapticsdk.schemas_io.read_csv_rows`: UTF-8, bounded, well-formed)."""
    from ..schemas_io import csv_header, read_csv_rows

    _, rows = read_csv_rows(path, field=field_name, max_bytes=MAX_CSV_BYTES)
    header = csv_header(rows[0], path, field=field_name) if rows else []
    if len(rows) < 2 or not set(columns) <= set(header):
        raise ValidationError(f"{path}: needs the column(s) {', '.join(columns)} and one row at least",
                              field=field_name)
    return {c: header.index(c) for c in columns}, rows[1:]


def _column(rows: list[list[str]], i: int, col: str, path: Any, field_name: str) -> np.ndarray:
    try:
        v = np.array([float(r[i]) for r in rows])
    except (TypeError, ValueError, IndexError) as exc:
        raise ValidationError(f"{path}: column {col}: not a number: {exc}", field=field_name) from None
    if not np.isfinite(v).all():
        raise ValidationError(f"{path}: column {col}: not finite", field=field_name)
    return v


def read_excitation_csv(path: Any) -> np.ndarray:
    """The forces (N) of an excitation file (column ``force_n``, one row per period)."""
    at, rows = _csv_table(path, "excitation", ("force_n",))
    return _column(rows, at["force_n"], "force_n", path, "excitation")


def write_excitation_csv(path: Any, forces_n: Any) -> Any:
    """Write :func:`excitation`'s forces to ``path`` (column ``force_n``), atomically and
    read back with :func:`read_excitation_csv` before it replaces the file."""
    from ..fileio import atomic_write_text

    f = np.asarray(forces_n, float).ravel()
    if not np.isfinite(f).all():
        raise ValidationError("forces must be finite", field="forces_n")
    return atomic_write_text(path, "force_n\n" + "".join(f"{v!r}\n" for v in f.tolist()), field="excitation",
                             verify=read_excitation_csv)


def read_run_csv(path: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(forces_n, readings_mm)`` of a recorded hands-off run: columns ``position_mm`` and
    ``force_n``, one row per period, the reading then the force applied after it (the last
    row's force is not used)."""
    at, rows = _csv_table(path, "run", ("position_mm", "force_n"))
    return (_column(rows[:-1], at["force_n"], "force_n", path, "run"),
            _column(rows, at["position_mm"], "position_mm", path, "run"))


def declared_limits(device: Any, mass_kg: float | None = None, max_force_n: float | None = None
                    ) -> tuple[float, float]:
    """``(mass_kg, max_force_n)`` that size a device's hands-off run: those given, else the
    device's ``apparent_mass_kg`` and ``limits.max_force_n``; a :class:`ValidationError`
    naming them when one is neither given nor declared."""
    m = mass_kg if mass_kg is not None else getattr(device, "apparent_mass_kg", None)
    fm = max_force_n if max_force_n is not None else getattr(getattr(device, "limits", None), "max_force_n", None)
    if m is None or fm is None:
        raise ValidationError("the device declares no apparent_mass_kg or limits.max_force_n; pass mass_kg= and "
                              "max_force_n=", field="device")
    return float(m), float(fm)


#: Time held at 0 N before the run beyond the safety layer's start ramp (s): the arm
#: settles, and the layer is past its gate and ramp before the first force.
SETTLE_EXTRA_S = 0.1


def _settle_ticks(device: Any, period_s: float) -> int:
    """Ticks held at 0 N before a run: the device's safety layer's start ramp plus
    :data:`SETTLE_EXTRA_S`."""
    ramp = float(getattr(getattr(getattr(device, "safety", None), "settings", None), "ramp_time_s", 0.0) or 0.0)
    return int(math.ceil((ramp + SETTLE_EXTRA_S) / period_s))


def _send_along(device: Any, role: str, axis: int, f: float, now: float) -> float:
    """Command force ``f`` (N, signed) along ``axis`` at ``now``; the force the device
    applied along the axis (its read-back, signed: projected where the read-back names a
    direction, else already along the device's axis; 0 N without one)."""
    from ..perception.dimensions import ChannelCommand

    e = [0.0, 0.0, 0.0]
    e[axis] = 1.0 if f >= 0.0 else -1.0
    device.command(ChannelCommand(role, force_n=abs(f), direction=(e[0], e[1], e[2])), now=now)
    back = device.read_back()
    if back is None or back.force_n is None:
        return 0.0
    return float(back.force_n) * (1.0 if back.direction is None else back.direction[axis])


def measure_damping(device: Any, *, period_s: float = 1e-3, axis: int = 1, role: str = "force",
                    mass_kg: float | None = None, max_force_n: float | None = None, realtime: bool = False,
                    latency_s: float | None = None) -> tuple[DampingFit, np.ndarray, np.ndarray]:
    """Run :func:`excitation` on a force device nobody holds and fit it: returns ``(fit,
    forces_n, readings_mm)``, the forces as the device applied them (its safety layer's
    read-back) and its readings along ``axis`` (0, 1, 2: x, y, z; 1 is the simulated
    Omni's normal).

    ``realtime=True`` plays the run in real time, paced on the machine's clock, on any
    device, real or simulated (a simulated one is stepped by the time that really
    passed), and fits it with each step's measured length and a bound that covers the
    run's timing: :func:`play_damping_run` (which also
    returns the timestamps), ``latency_s`` as there. The default plays a *simulated*
    device in simulated time (``device.step(period_s)`` per period; its class must
    declare ``simulated = True``), every step exactly a period. Before the run the
    device is held at 0 N for its safety layer's start ramp (``ramp_time_s``) plus 0.1
    s; after it, on every exit path, it is sent 0 N, and closed if this function opened
    it."""
    if realtime:
        run = play_damping_run(device, period_s=period_s, axis=axis, role=role, mass_kg=mass_kg,
                               max_force_n=max_force_n, latency_s=latency_s)
        return run.fit, run.forces_n, run.readings_mm
    if not getattr(type(device), "simulated", False):
        raise ValidationError(f"{type(device).__name__} is not a simulated device: in simulated time measure_damping "
                              "drives only simulated devices. On a real arm, pass realtime=True (hapticsdk calibrate "
                              "damping --device NAME), or write the excitation (--write-excitation), play it hands "
                              "off in your servo loop and fit the recording (--run)", field="device")
    if axis not in (0, 1, 2):
        raise ValidationError(f"must be 0, 1 or 2, got {axis!r}", field="axis")
    m, fm = declared_limits(device, mass_kg, max_force_n)
    forces = excitation(period_s, fm, m)
    settle = _settle_ticks(device, period_s)
    opened = not device.is_open
    applied = np.empty(forces.size)
    readings = np.empty(forces.size + 1)
    t = 0.0   # simulated time (s): the safety layer's ramp and staleness run on it
    if opened:
        device.open()
    try:
        for _ in range(settle):
            _send_along(device, role, axis, 0.0, t)
            device.step(period_s)
            t += period_s
        for k, f in enumerate(forces.tolist()):
            readings[k] = float(device.read_state().position_mm[axis])
            applied[k] = _send_along(device, role, axis, f, t)
            device.step(period_s)
            t += period_s
        readings[-1] = float(device.read_state().position_mm[axis])
    finally:
        try:
            _send_along(device, role, axis, 0.0, t)
        finally:
            if opened:
                device.close()
    res = getattr(device, "encoder_resolution_mm", 0.0) or 0.0
    return fit_damping(applied, readings, period_s, float(res)), applied, readings


# ----------------------------------------------------------------------
# The run played in real time (docs/calibration.md, "A run timed by the loop's clock").
# A dedicated loop, not hapticsdk.runtime.loop.ServoLoop: the run plays a fixed force
# sequence with no renderer and no passivity controller (a controller would change the
# forces the fit needs), and records what the fit needs per tick: each reading's
# timestamp on the pacing clock, how long the read and the command took. A simulated
# device is stepped by the time that really passed between ticks, as the servo loop's
# real-time mode steps it: its physics runs at the loop's timestamps (latency 0), and it
# drops a command older than its safety layer's stale_after_s (it applies
# SafetyLayer.current, the layer's contract), which the fit models. A real device may or
# may not drop a stale command; the bound covers both.
# ----------------------------------------------------------------------

@dataclass
class DampingRun:
    """A hands-off run played in real time (:func:`play_damping_run`).

    Attributes:
        fit: the fit of the run (:class:`~hapticsdk.calibration.damping.DampingFit`).
        forces_n: the forces as applied (the safety layer's read-back), one per tick (N).
        readings_mm: the encoder readings along the axis, one before each force and the
            last (mm).
        times_s: each reading's timestamp on the loop's clock, from the first reading (s).
        read_s: per reading, how long after its timestamp the read returned (s; 0 on a
            simulated device).
        command_s: per force, how long after its tick's timestamp the command returned
            (s; 0 on a simulated device).
        latency_s: the transport latency the bound took (declared or given, s).
        period_s: the period the loop was paced at (s).
        late_ticks: steps longer than 1.5 periods.
        simulated: the device was simulated (generated data).
    """

    fit: DampingFit
    forces_n: np.ndarray
    readings_mm: np.ndarray
    times_s: np.ndarray
    read_s: np.ndarray
    command_s: np.ndarray
    latency_s: float
    period_s: float
    late_ticks: int
    simulated: bool


def play_damping_run(device: Any, *, period_s: float = 1e-3, axis: int = 1, role: str = "force",
                     mass_kg: float | None = None, max_force_n: float | None = None,
                     latency_s: float | None = None, clock: Any = None) -> DampingRun:
    """Play the hands-off run on ``device`` (nobody holds the stylus) in real time and fit it.

    ``period_s``: the loop's period (s); ``axis``: 0, 1, 2 (x, y, z) the one driven and
    read; ``mass_kg``, ``max_force_n``: size the run where the device declares no
    ``apparent_mass_kg`` / ``limits.max_force_n`` (refused when neither); ``latency_s``:
    the most time between a position's sample and the read returning it, and between a
    command returning and its force at the motor, where the device declares no
    ``transport_latency_s`` (a real device with neither is refused before it is opened);
    ``clock``: the pacing clock (default :class:`~hapticsdk.runtime.clock.MonotonicClock`;
    a :class:`~hapticsdk.runtime.clock.SimulatedClock` with stalls makes late ticks on
    purpose).

    The device is opened if it is not open (and then closed), held at 0 N for its safety
    layer's start ramp plus :data:`SETTLE_EXTRA_S`, driven along ``axis`` through its
    command path, and on every exit path (an error, ``KeyboardInterrupt``) sent 0 N
    (stopped if that fails). A failed fit is returned, not raised: ``fit.success`` is
    False and it credits nothing."""
    from ..runtime.clock import MonotonicClock

    number(period_s, "period_s", lo=0.0, lo_open=True)
    if axis not in (0, 1, 2):
        raise ValidationError(f"must be 0, 1 or 2, got {axis!r}", field="axis")
    m, fm = declared_limits(device, mass_kg, max_force_n)
    simulated = bool(getattr(type(device), "simulated", False))
    if simulated:
        lat = 0.0   # stepped from the loop's timestamps: its clock is the loop's
    else:
        lat_d = latency_s if latency_s is not None else getattr(device, "transport_latency_s", None)
        if lat_d is None:
            raise ValidationError(f"{type(device).__name__} declares no transport_latency_s: when its forces reach "
                                  "the arm and when its readings were sampled is not bounded, so its damping cannot "
                                  "be; pass latency_s= (--latency) from the device's documentation", field="latency_s")
        lat = float(number(lat_d, "latency_s", lo=0.0))
    forces = excitation(period_s, fm, m)
    safety = getattr(device, "safety", None)
    settle = _settle_ticks(device, period_s)
    n = forces.size
    clock = clock if clock is not None else MonotonicClock()
    now = clock.now
    applied = np.zeros(n)
    readings = np.zeros(n + 1)
    times = np.zeros(n + 1)
    read_s = np.zeros(n + 1)
    command_s = np.zeros(n)
    t_last = 0.0

    def send(f: float, t: float) -> float:
        return _send_along(device, role, axis, f, t)

    observe = getattr(safety, "observe", None)
    opened = not device.is_open
    gc_was = gc.isenabled()
    origin = now()
    t_dev = 0.0
    if opened:
        device.open()
    try:
        if safety is not None and hasattr(safety, "set_period"):
            safety.set_period(period_s)   # a command older than a period is stale, as in the servo loop
        # a simulated device's own clock (its state's t) may not start at 0 (opened and
        # stepped before): commands carry its time, so its safety layer ages them right
        t_dev = float(getattr(device.read_state(), "t", 0.0) or 0.0) if simulated else 0.0
        gc.collect()
        gc.disable()                      # no collection pauses a tick
        deadline = origin = now()
        for i in range(settle + n + 1):
            clock.wait_until(deadline)
            t = now() - origin
            if i and simulated:
                device.step(t - t_last)   # physics advances by the time that really passed
            t_last = t
            k = i - settle
            st = device.read_state()
            if observe is not None:
                observe(st)   # the layer's speed limits see each tick's state, as in the servo loop
            if k >= 0:
                times[k] = t
                readings[k] = float(st.position_mm[axis])
                read_s[k] = 0.0 if simulated else now() - origin - t
            if k < 0:
                send(0.0, t_dev + t)
            elif k < n:
                applied[k] = send(float(forces[k]), t_dev + t)
                command_s[k] = 0.0 if simulated else now() - origin - t
            clock.work(i, 0.0)     # a simulated clock charges the tick here (a test's stalls)
            deadline += period_s
            if now() > deadline + period_s:
                deadline = now()   # behind by more than a period: on from now (the fit takes any step)
    finally:
        if gc_was:
            gc.enable()
        try:
            try:
                send(0.0, t_dev + now() - origin)
            except Exception:
                device.stop()      # the safe state when even a 0 N command fails
        finally:
            if opened:
                device.close()
    times -= times[0]
    stale = getattr(getattr(safety, "settings", None), "stale_after_s", None)
    res = float(getattr(device, "encoder_resolution_mm", 0.0) or 0.0)
    # a command older than stale_after_s is dropped to 0 N by a simulated device (it
    # applies SafetyLayer.current, the layer's contract): the fit models the drop; a real
    # device may or may not drop it: the bound covers both
    drop = None if stale is None else float(stale)
    fit = fit_damping(applied, readings, period_s, res, times_s=times, force_delay_s=command_s + lat,
                      reading_delay_s=np.maximum(read_s, lat), hold_s=drop if simulated else None,
                      may_drop_after_s=None if simulated else drop)
    late = int(np.sum(np.diff(times) > 1.5 * period_s))
    return DampingRun(fit=fit, forces_n=applied, readings_mm=readings, times_s=times, read_s=read_s,
                      command_s=command_s, latency_s=lat, period_s=float(period_s), late_ticks=late,
                      simulated=simulated)

"""The hands-off damping fit of a run timed by the loop's clock (issue 23, the real-arm
gap): each step lasts as measured, and the bound covers what the timestamps do not pin
down (forces reaching the arm late, readings sampled off their timestamps, forces dropped
as stale). docs/calibration.md, "A run timed by the loop's clock".

The runs are simulated by :func:`hapticsdk.sim.arm.timed_free_arm_readings_mm`, whose
untimed case is checked here against :func:`~hapticsdk.sim.arm.free_arm_readings_mm`
(``expm`` of the arm's own system), so an error in the fit's response shows.
"""

import functools
import math

import numpy as np
import pytest

from hapticsdk.calibration.damping import excitation, fit_damping
from hapticsdk.errors import ValidationError
from hapticsdk.sim.arm import ArmParams, free_arm_readings_mm, timed_free_arm_readings_mm

hyp = pytest.importorskip("hypothesis", reason="hypothesis (the test extra) is not installed")
from hypothesis import given, settings, strategies as st  # noqa: E402


def _lu(lo, hi):
    return st.floats(math.log(lo), math.log(hi)).map(math.exp)


def _arm(m, b, q):
    return ArmParams(mass_kg=m, damping_ns_per_m=b, encoder_resolution_mm=q)


@pytest.mark.parametrize("T, q, m, b", [(1e-3, 0.0, 0.045, 0.5), (0.25e-3, 0.0, 0.1, 2.0), (10e-3, 0.0, 0.02, 0.0),
                                        (1e-3, 0.055, 0.045, 0.5), (2e-3, 0.01, 0.05, 1e-3)])
def test_the_timed_simulator_meets_the_expm_one_when_nothing_is_late(T, q, m, b):
    f = excitation(T, 3.3, m)
    y1 = free_arm_readings_mm(T, _arm(m, b, q), f)
    y2 = timed_free_arm_readings_mm(np.arange(f.size + 1) * T, f, _arm(m, b, q))
    # exact: rounding; quantised: a position at half a count may round either way
    assert np.abs(y1 - y2).max() <= (1e-9 if q == 0 else q * (1 + 1e-9))
    if q:
        assert np.mean(y1 != y2) < 0.01


@pytest.mark.parametrize("T, q, m, b", [(1e-3, 0.055, 0.045, 0.5), (0.25e-3, 0.001, 0.1, 2.0),
                                        (10e-3, 0.2, 0.02, 0.0), (2e-3, 0.01, 0.05, 1.0)])
def test_equal_steps_give_the_untimed_fit_to_rounding(T, q, m, b):
    """The timed fit (its own response, a recurrence per step) on timestamps k T is the fit
    without timestamps (``lfilter`` of a constant step) to rounding; a fit without
    timestamps runs the code it ran before, unchanged."""
    f = excitation(T, 3.3, m)
    y = free_arm_readings_mm(T, _arm(m, b, q), f)
    a = fit_damping(f, y, T, q)
    g = fit_damping(f, y, T, q, times_s=np.arange(y.size) * T)
    assert g.timing_error_ns_per_m == 0.0
    for name in ("damping_ns_per_m", "trusted_damping_ns_per_m", "worst_error_ns_per_m", "mass_kg", "fun"):
        assert getattr(g, name) == pytest.approx(getattr(a, name), rel=1e-8, abs=1e-12), name


#: the randomised stability benchmark's space, with the timing of a loop that does not hold
#: its period: per-step jitter, late ticks, forces late by up to L, readings off by up to P
timed_arms = st.fixed_dictionaries({
    "T": _lu(0.25e-3, 10e-3), "q": _lu(0.001, 0.2), "m": _lu(0.02, 0.1),
    "b": st.one_of(st.just(0.0), _lu(0.05, 2.0)), "mass_off": _lu(0.5, 2.0),
    "jitter": st.floats(0.0, 0.5), "late_share": st.sampled_from([0.0, 0.005, 0.02]),
    "L": st.one_of(st.just(0.0), _lu(0.01, 2.0)), "P": st.one_of(st.just(0.0), _lu(0.01, 1.0)),
    "lam": st.sampled_from(["random", "all-late", "none"]), "rho": st.sampled_from(["random", "late", "early"]),
    "drop": st.sampled_from(["held", "dropped", "may-drop"]), "seed": st.integers(0, 2 ** 32 - 1)})


def _timed_run(d):
    """(forces, readings, timestamps, fit keywords, true damping) of a drawn arm and timing."""
    T, m = d["T"], d["m"]
    rng = np.random.default_rng(d["seed"])
    f = excitation(T, 3.3, m * d["mass_off"])
    n = f.size
    dt = T * (1.0 + rng.uniform(-d["jitter"], d["jitter"], n))
    late = rng.random(n) < d["late_share"]
    dt[late] += rng.uniform(0.0, 3.0 * T, int(late.sum()))
    t = np.concatenate([[0.0], np.cumsum(dt)])
    L, P = d["L"] * T, d["P"] * T
    lam = {"random": rng.uniform(0.0, L, n), "all-late": np.full(n, L), "none": np.zeros(n)}[d["lam"]]
    rho = {"random": rng.uniform(-P, P, n + 1), "late": np.full(n + 1, P), "early": np.full(n + 1, -P)}[d["rho"]]
    drop = d["drop"] if (d["drop"] != "dropped" or L == 0.0) else "may-drop"   # a drop is modelled only at L = 0
    y = timed_free_arm_readings_mm(t, f, _arm(m, d["b"], d["q"]), force_delays_s=lam, reading_offsets_s=rho,
                                   hold_s=None if drop == "held" else T)
    kw = {"times_s": t, "force_delay_s": L, "reading_delay_s": P}
    if drop == "dropped":
        kw["hold_s"] = T
    elif drop == "may-drop":
        kw["may_drop_after_s"] = T
    return f, y, kw


@settings(max_examples=60, deadline=None, derandomize=True, database=None)
@given(timed_arms)
def test_the_lower_bound_stays_below_the_true_damping_under_jitter_and_latency(d):
    """The property the controller relies on, for a run timed by a clock: any period,
    encoder, mass and damping of the benchmark's space, steps up to 50 % off the period and
    late ticks up to 4 periods, forces late by any amount within the declared spread L,
    readings sampled early or late within P, stale forces held, dropped or either: what
    the fit credits is never above the truth (or it fails and credits nothing)."""
    f, y, kw = _timed_run(d)
    fit = fit_damping(f, y, d["T"], d["q"], **kw)
    assert 0.0 <= fit.trusted_damping_ns_per_m <= d["b"], (d, fit)
    if fit.success:
        assert abs(fit.damping_ns_per_m - d["b"]) <= fit.worst_error_ns_per_m, (d, fit)


def _switches(f):
    return np.flatnonzero(np.diff(np.concatenate([[0.0], f])))


@functools.lru_cache(maxsize=None)
def _one_late_force(T, m, b):
    """The excitation's run of an exact-reading arm timed at k T, and per switch k of the
    force, that switch alone late by L = 0.02 T: ``(forces, timestamps, arm, L, base,
    [(k, readings, d_k)])``, d_k the fitted damping (timestamps, no timing terms) less
    ``base`` (the fit of the run with nothing late). A pure function of (T, m, b), computed
    once for the two tests below that both need every d_k (read-only: the arrays are not
    writable)."""
    L = 0.02 * T
    f = excitation(T, 3.3, m)
    t = np.arange(f.size + 1) * T
    arm = _arm(m, b, 0.0)
    base = fit_damping(f, timed_free_arm_readings_mm(t, f, arm), T, 0.0, times_s=t).damping_ns_per_m
    late = []
    for k in _switches(f):
        lam = np.zeros(f.size)
        lam[k] = L
        y = timed_free_arm_readings_mm(t, f, arm, force_delays_s=lam)
        y.flags.writeable = False
        late.append((k, y, fit_damping(f, y, T, 0.0, times_s=t).damping_ns_per_m - base))
    f.flags.writeable = t.flags.writeable = False
    return f, t, arm, L, base, tuple(late)


@pytest.mark.parametrize("T, m, b", [(1e-3, 0.045, 0.5), (0.5e-3, 0.1, 1.5), (4e-3, 0.02, 0.1)])
def test_the_latency_term_is_the_worst_delay_pattern_to_first_order(T, m, b):
    """The force-latency term is a worst case that is reached: delaying each switch of the
    force alone moves the fitted damping by d_k; delaying just those that raise it (the
    worst pattern within the spread) raises it by sum(d_k^+), which the term bounds and
    is not far above (a small spread, so first order; exact readings)."""
    f, t, arm, L, base, late = _one_late_force(T, m, b)
    sw = np.array([k for k, _, _ in late])
    d = [dk for _, _, dk in late]
    worst = np.zeros(f.size)
    worst[sw[np.array(d) > 0]] = L
    y = timed_free_arm_readings_mm(t, f, arm, force_delays_s=worst)
    fit = fit_damping(f, y, T, 0.0, times_s=t, force_delay_s=L)
    rise = fit.damping_ns_per_m - base
    assert rise > 0
    assert rise <= fit.timing_error_ns_per_m
    assert rise >= 0.5 * fit.timing_error_ns_per_m
    # and the bound's margin carries it: the readings' term of the same readings, plus it
    plain = fit_damping(f, y, T, 0.0, times_s=t)
    assert fit.worst_error_ns_per_m == pytest.approx(plain.worst_error_ns_per_m + fit.timing_error_ns_per_m,
                                                     rel=1e-12)
    assert fit.trusted_damping_ns_per_m == max(0.0, fit.damping_ns_per_m - fit.worst_error_ns_per_m)


@pytest.mark.parametrize("T, m, b", [(1e-3, 0.045, 0.5), (0.5e-3, 0.1, 1.5), (4e-3, 0.02, 0.1)])
def test_each_late_force_and_a_late_reading_are_bounded_one_by_one(T, m, b):
    """Per switch of the force: delaying it alone moves the fitted damping by d_k, and the
    term for that switch alone is at least d_k (0 where the delay lowers the damping: a
    late force only ever counts against the bound one way). A late step whose force was
    dropped is covered by the term of a device that may drop it. Readings all sampled late by
    P raise the damping by less than the readings' timing term; early, they lower it."""
    f, t, arm, L, base, late = _one_late_force(T, m, b)
    P = L
    n = f.size
    for k, y, d in late:
        lam = np.zeros(n)
        lam[k] = L
        fit = fit_damping(f, y, T, 0.0, times_s=t, force_delay_s=lam)
        assert d <= fit.timing_error_ns_per_m, k
    for k in _switches(f)[:8] + 3:
        # step k 2 % longer than a period, its force dropped after one (first order, as
        # the delays): the term of a device that may drop a stale force covers the loss
        tk = np.concatenate([t[:k + 1], t[k + 1:] + 0.02 * T])
        held = fit_damping(f, timed_free_arm_readings_mm(tk, f, arm), T, 0.0, times_s=tk).damping_ns_per_m
        y = timed_free_arm_readings_mm(tk, f, arm, hold_s=T)
        fit = fit_damping(f, y, T, 0.0, times_s=tk, may_drop_after_s=T)
        # first order: the remainder is of the order of the lost share of the segment's
        # impulse (0.02 T of a segment of tau >= 10 T) relative to the term
        tau = np.diff(_switches(f))[0] * T
        d = fit_damping(f, y, T, 0.0, times_s=tk).damping_ns_per_m - held
        assert d <= fit.timing_error_ns_per_m * (1.0 + 0.02 * T / tau), k
    for sign in (1.0, -1.0):
        y = timed_free_arm_readings_mm(t, f, arm, reading_offsets_s=sign * P)
        fit = fit_damping(f, y, T, 0.0, times_s=t, reading_delay_s=P)
        assert 0.0 < sign * (fit.damping_ns_per_m - base) <= fit.timing_error_ns_per_m


def test_the_bound_is_worth_having_under_jitter():
    """With steps 30 % off the period and 2 % of them late by up to 3 periods (their forces
    dropped as stale, as a simulated device drops them), the Omni's fine encoder still
    gives a bound above the half of a declaration the controller could be told to trust,
    over a spread of arms (median): the measured step lengths and the modelled drops are
    what make it so."""
    rng = np.random.default_rng(7)
    ratios = []
    for _ in range(12):
        d = {"T": float(np.exp(rng.uniform(np.log(0.5e-3), np.log(2e-3)))), "q": 0.055,
             "m": float(rng.uniform(0.03, 0.08)), "b": float(rng.uniform(0.3, 1.5)), "mass_off": 1.0,
             "jitter": 0.3, "late_share": 0.02, "L": 0.0, "P": 0.0, "lam": "none", "rho": "random",
             "drop": "dropped", "seed": int(rng.integers(2 ** 32))}
        f, y, kw = _timed_run(d)
        fit = fit_damping(f, y, d["T"], d["q"], **kw)
        assert fit.success and fit.trusted_damping_ns_per_m <= d["b"]
        ratios.append(fit.trusted_damping_ns_per_m / d["b"])
    assert np.median(ratios) > 0.5, ratios


def test_a_timing_that_is_not_bounded_credits_nothing():
    T = 1e-3
    f = excitation(T, 3.3, 0.045)
    t = np.arange(f.size + 1) * T
    y = timed_free_arm_readings_mm(t, f, _arm(0.045, 0.5, 0.055))
    for kw in ({"force_delay_s": math.inf}, {"reading_delay_s": math.nan}):
        fit = fit_damping(f, y, T, 0.055, times_s=t, **kw)
        assert not fit.success and fit.trusted_damping_ns_per_m == 0.0 and "not bounded" in fit.message


@pytest.mark.parametrize("kw, match", [
    (lambda n: {"times_s": np.arange(10) * 1e-3}, "timestamp"),
    (lambda n: {"times_s": -np.arange(n + 1) * 1e-3}, "increasing"),
    (lambda n: {"times_s": np.arange(n + 1) * 1e-3, "force_delay_s": -1e-3}, ">= 0"),
    (lambda n: {"times_s": np.arange(n + 1) * 1e-3, "force_delay_s": np.zeros(3)}, "one value or"),
    (lambda n: {"times_s": np.arange(n + 1) * 1e-3, "force_delay_s": 1e-4, "hold_s": 1e-3}, "may_drop_after_s"),
    (lambda n: {"times_s": np.arange(n + 1) * 1e-3, "hold_s": -1.0}, "hold_s"),
])
def test_bad_timing_is_named(kw, match):
    f = excitation(1e-3, 3.3, 0.045)
    with pytest.raises(ValidationError, match=match):
        fit_damping(f, np.zeros(f.size + 1), 1e-3, 0.055, **kw(f.size))

"""The arm's damping measured hands off (issue 23, "as far as the controller measures it"):
the fit's lower bound holds, the calibration is stored per serial, and the controller
credits it.

The runs are simulated by :func:`hapticsdk.sim.arm.free_arm_readings_mm` (``expm`` of the
arm's own system), not by the fit's closed-form response, so an error in either shows.
"""

import dataclasses
import math

import numpy as np
import pytest

from hapticsdk.calibration.damping import (DampingCalibration, excitation, fit_damping, read_excitation_csv,
                                           read_run_csv, simulated_run, write_excitation_csv)
from hapticsdk.calibration.store import load_calibration, save_calibration
from hapticsdk.errors import ValidationError
from hapticsdk.passivity import ControllerSettings
from hapticsdk.passivity.settings import colgate_stiffness_n_per_mm
from hapticsdk.sim.arm import ArmParams, free_arm_readings_mm
from hapticsdk.sim.finger import FingerParams

hyp = pytest.importorskip("hypothesis", reason="hypothesis (the test extra) is not installed")
from hypothesis import given, settings, strategies as st  # noqa: E402


def _lu(lo, hi):
    return st.floats(math.log(lo), math.log(hi)).map(math.exp)


#: the randomised stability benchmark's space (period, encoder, arm mass, true damping)
arms = st.tuples(_lu(0.25e-3, 10e-3), _lu(0.001, 0.2), _lu(0.02, 0.1),
                 st.one_of(st.just(0.0), _lu(0.05, 1.0)), _lu(0.5, 2.0))


@settings(max_examples=60, deadline=None, derandomize=True, database=None)
@given(arms)
def test_the_lower_bound_is_below_the_true_damping(arm):
    """The property the controller relies on: what it credits is never above the truth,
    for any period, encoder, mass and damping of the benchmark's space, and a mass declared
    up to a factor 2 off (it only sizes the excitation)."""
    T, q, m, b, mass_off = arm
    f = excitation(T, 3.3, m * mass_off)
    y = free_arm_readings_mm(T, ArmParams(mass_kg=m, damping_ns_per_m=b, encoder_resolution_mm=q), f)
    fit = fit_damping(f, y, T, q)
    assert fit.success, fit.message
    assert 0.0 <= fit.trusted_damping_ns_per_m <= b, (arm, fit)
    # the bound's margin covers the fit's actual error
    assert abs(fit.damping_ns_per_m - b) <= fit.worst_error_ns_per_m, (arm, fit)


def test_the_bound_is_worth_having_where_the_encoder_is_fine():
    """Measured beats declared: with a fine encoder (0.055 mm, the Omni's) the lower bound is
    above the half a declaration is trusted with even when the declaration is exact, over a
    spread of arms (median; the reasoning: otherwise the calibration would not be worth
    running)."""
    rng = np.random.default_rng(5)
    ratios = []
    for _ in range(20):
        T = float(np.exp(rng.uniform(np.log(0.25e-3), np.log(4e-3))))
        m = float(np.exp(rng.uniform(np.log(0.02), np.log(0.1))))
        b = float(np.exp(rng.uniform(np.log(0.05), np.log(1.0))))
        f, y = simulated_run(T, m, b, 0.055)
        ratios.append(fit_damping(f, y, T, 0.055).trusted_damping_ns_per_m / b)
    assert np.median(ratios) > 0.5, ratios


def test_an_arm_that_does_not_move_gives_no_credit():
    """A held or blocked arm: nothing to fit, nothing credited."""
    f = excitation(1e-3, 3.3, 0.045)
    fit = fit_damping(f, np.zeros(f.size + 1), 1e-3, 0.055)
    assert not fit.success and fit.trusted_damping_ns_per_m == 0.0
    assert "did not move" in fit.message


def test_readings_the_model_does_not_explain_widen_the_margin():
    """A hand that pushes during the run (a force the fit does not know of): the largest
    residual, not half a count, sizes the margin, so the bound drops."""
    T, q = 1e-3, 0.055
    f, y = simulated_run(T, 0.045, 0.5, q)
    clean = fit_damping(f, y, T, q)
    rng = np.random.default_rng(1)
    push = np.cumsum(rng.normal(0.0, 0.02, f.size))   # an unknown, wandering force (N)
    y2 = free_arm_readings_mm(T, ArmParams(mass_kg=0.045, damping_ns_per_m=0.5, encoder_resolution_mm=q), f + push)
    dirty = fit_damping(f, y2, T, q)
    assert dirty.worst_error_ns_per_m > clean.worst_error_ns_per_m
    assert dirty.trusted_damping_ns_per_m < clean.trusted_damping_ns_per_m


def test_the_excitation_is_bounded_and_balanced():
    for T, m in ((0.25e-3, 0.02), (1e-3, 0.045), (10e-3, 0.1)):
        f = excitation(T, 3.3, m)
        assert np.abs(f).max() <= 0.25 * 3.3 + 1e-12
        assert abs(f.sum()) <= 1e-9 * np.abs(f).sum()   # no net impulse
        y = free_arm_readings_mm(T, ArmParams(mass_kg=m, damping_ns_per_m=0.0, encoder_resolution_mm=0.0), f)
        assert np.abs(y).max() <= 5.0 * (1 + 1e-9) + 1e-9   # the stated 5 mm travel, undamped
    with pytest.raises(ValidationError):
        excitation(0.0, 3.3, 0.045)


def test_bad_input_is_named():
    f = excitation(1e-3, 3.3, 0.045)
    with pytest.raises(ValidationError, match="one reading more"):
        fit_damping(f, np.zeros(f.size), 1e-3, 0.055)
    with pytest.raises(ValidationError):
        fit_damping(f, np.full(f.size + 1, np.nan), 1e-3, 0.055)
    with pytest.raises(ValidationError):
        fit_damping(f, np.zeros(f.size + 1), -1.0, 0.055)


def _cal(serial="OMNI-1", trusted=0.4):
    return DampingCalibration(trusted_damping_ns_per_m=trusted, damping_ns_per_m=0.45, worst_error_ns_per_m=0.05,
                              mass_kg=0.045, period_s=1e-3, resolution_mm=0.055, readings=817, serial=serial,
                              generated=True, source="test")


def test_the_calibration_round_trips_through_the_store(tmp_path):
    p = save_calibration(_cal(), tmp_path)
    assert p.name == "damping-OMNI-1.json"
    got = load_calibration("damping", "OMNI-1", directory=tmp_path)
    assert got.origin == "file" and got.calibration == _cal()
    assert load_calibration("damping", "OTHER", directory=tmp_path).calibration is None


def test_a_bound_above_the_fit_is_refused():
    with pytest.raises(ValidationError, match="exceeds"):
        _cal(trusted=0.5)
    with pytest.raises(ValidationError):
        _cal(trusted=-0.1)


class _Dev:
    apparent_mass_kg = 0.045
    damping_ns_per_m = 0.5
    encoder_resolution_mm = 0.055

    def __init__(self, serial=None):
        if serial is not None:
            self.serial_number = serial


def test_the_controller_credits_the_measurement_for_its_own_serial_only(tmp_path):
    save_calibration(_cal(), tmp_path)
    save_calibration(_cal(serial=None, trusted=0.3), tmp_path)   # a file for any device
    mine = ControllerSettings.for_device(_Dev("OMNI-1"), directory=tmp_path)
    assert mine.measured_damping_ns_per_m == 0.4
    assert mine.trusted_damping_ns_per_m() == 0.4
    # the fit replaces the declaration as the device's damping; the spring sits at half
    # Colgate's limit of it (at most the limit of the bound)
    assert mine.device_damping_ns_per_m == 0.45
    assert colgate_stiffness_n_per_mm(mine, 1e-3) == pytest.approx(2 * min(0.4, 0.45 / 2) / 1e-3 / 1000, rel=1e-12)
    other = ControllerSettings.for_device(_Dev("OMNI-2"), directory=tmp_path)
    assert other.measured_damping_ns_per_m is None
    assert other.trusted_damping_ns_per_m() == 0.0        # a declaration is not credited
    assert ControllerSettings.for_device(_Dev(), directory=tmp_path).measured_damping_ns_per_m is None
    # given in code
    assert ControllerSettings.for_device(_Dev(), damping=_cal(trusted=0.2)).measured_damping_ns_per_m == 0.2
    assert ControllerSettings.for_device(_Dev(), damping=0.1).measured_damping_ns_per_m == 0.1
    for bad in (-1.0, float("nan"), "0.3", True):
        with pytest.raises(ValidationError):
            ControllerSettings.for_device(_Dev(), damping=bad)


@pytest.mark.parametrize("bound", [0.9, 0.3])
def test_scalar_and_batch_controllers_credit_the_same_measured_damping(bound):
    """The servo tick's controller and the benchmark's batch take the measurement alike: the
    spring's damping is half the fit (0.5) or the bound where that is lower (0.3, a coarse
    encoder's wide margin)."""
    from hapticsdk.passivity import PassivityController, controller_commit_batch, controller_state_batch, \
        controller_step_batch
    s = ControllerSettings(device_damping_ns_per_m=1.0, position_resolution_mm=0.01, max_force_n=3.3,
                           device_mass_kg=0.045, measured_damping_ns_per_m=bound)
    c = PassivityController(s)
    st_ = controller_state_batch(1)
    rng = np.random.default_rng(3)
    x = -np.cumsum(np.abs(rng.normal(0.0, 0.02, 400))) + 0.5
    x = np.round(x / 0.01) * 0.01
    for xi in x:
        fw = max(-xi, 0.0) * 2.0
        a = c.step(float(xi), 1e-3, fw)
        b = controller_step_batch(st_, np.array([xi]), 1e-3, np.array([fw]), True, s)[0]
        assert a == pytest.approx(b, abs=1e-12)
        # the spring itself, from the derivation: 2 min(bound, fit / 2) / T times the depth
        spring = min(2 * min(bound, 0.5) / 1e-3 * max(-xi, 0.0) * 1e-3, fw, 3.3)   # at most F_max
        assert c._spring == pytest.approx(spring, abs=1e-12) == st_["spring"][0]
        c.commit(a)
        controller_commit_batch(st_, np.array([a]))
    # the spring at half Colgate's limit of the fit, the bound credited to the extra
    assert c._spring > 0.0
    assert s.trusted_damping_ns_per_m() == bound
    assert colgate_stiffness_n_per_mm(s, 1e-3) == pytest.approx(2 * min(bound, 0.5) / 1e-3 / 1000, rel=1e-12)


def test_run_and_excitation_files_round_trip(tmp_path):
    f, y = simulated_run(1e-3, 0.045, 0.5, 0.055)
    p = tmp_path / "run.csv"
    rows = ["position_mm,force_n"] + [f"{float(yi)!r},{float(fi)!r}" for yi, fi in zip(y, list(f) + [0.0])]
    p.write_text("\n".join(rows) + "\n")
    f2, y2 = read_run_csv(p)
    assert np.array_equal(f2, f) and np.array_equal(y2, y)
    e = tmp_path / "ex.csv"
    write_excitation_csv(e, f)
    assert np.array_equal(read_excitation_csv(e), f)
    bad = tmp_path / "bad.csv"
    bad.write_text("position_mm\n1\n")
    with pytest.raises(ValidationError, match="force_n"):
        read_run_csv(bad)


def _omni(**kw):
    from hapticsdk.devices.actuators import create_actuator
    return create_actuator("omni-virtual", **kw)


def test_measured_on_the_simulated_omni_hands_off_then_rendered_with():
    """The product path: the simulated Omni nobody holds is driven through its safety
    layer, fitted, and the calibration's settings drive a press through the servo loop."""
    from hapticsdk.calibration.damping import measure_damping
    from hapticsdk.plugins import registry
    from hapticsdk.runtime import ServoLoop
    from hapticsdk.sim.finger import FingerParams, press_slide

    free = _omni(finger=FingerParams(0.0, 0.0, 0.0))
    fit, forces, readings = measure_damping(free)
    true_b = free.arm.damping_ns_per_m
    assert fit.success and 0.5 * true_b < fit.trusted_damping_ns_per_m <= true_b   # beats half a declaration
    assert not free.is_open
    assert np.array_equal(forces, excitation(1e-3, 3.3, free.apparent_mass_kg))   # the safety layer let it through
    cal = DampingCalibration.from_fit(fit, period_s=1e-3, resolution_mm=free.encoder_resolution_mm, generated=True,
                                      source="test: simulated Omni, hands off")
    tr = press_slide(depth_mm=2.0, press_s=0.3, hold_s=0.3, slide_s=0.0, release_s=0.3, rest_s=0.2)
    dev = _omni(trajectory=tr)
    st_ = ControllerSettings.for_device(dev, damping=cal)
    assert st_.measured_damping_ns_per_m == cal.trusted_damping_ns_per_m
    dims, acts = registry("dimension"), registry("actuator")
    loop = ServoLoop(dev, [dims.load("hardness")().renderer({"GS": 1.0})],
                     {"force": dev, "coil": acts.load("voicecoil-virtual")()}, period_s=0.001,
                     passivity_settings=st_)
    rep = loop.run(tr.duration_s)
    # the loop's controllers run on these settings (a copy carrying the loop's period)
    assert loop.passivity_settings == dataclasses.replace(st_, period_s=0.001)
    pen, f = rep.log["penetration_mm"], rep.log["force_n"]
    assert dev.energy_to_user_j() <= 1e-4                 # the bound
    assert f[pen > 0].min() >= 0.0                        # never pulls


def test_a_hand_on_the_stylus_gives_little_credit():
    """The simulated Omni held by its default finger: the fit takes the hand for damping
    (several N s/m), and its residuals shrink the bound to at most the truth."""
    from hapticsdk.calibration.damping import measure_damping
    held = _omni()
    fit, _, _ = measure_damping(held)
    assert fit.damping_ns_per_m > held.arm.damping_ns_per_m          # the hand is in the fit
    assert fit.trusted_damping_ns_per_m <= held.arm.damping_ns_per_m  # and not in the bound


def test_every_exit_of_a_measurement_leaves_the_device_at_zero_and_closed():
    from hapticsdk.calibration.damping import measure_damping
    from hapticsdk.sim.finger import FingerParams

    from damping_faults import fail_at_step

    dev = _omni(finger=FingerParams(0.0, 0.0, 0.0))
    sent = fail_at_step(dev, 310, RuntimeError)   # 0.3 s of settling at 1 ms, then the first +F segment
    with pytest.raises(RuntimeError, match="mid-run"):
        measure_damping(dev)
    assert sent[-1] == 0.0 and not dev.is_open


def test_a_real_device_is_not_driven_from_python():
    from hapticsdk.calibration.damping import measure_damping

    class Real:
        simulated = False
    with pytest.raises(ValidationError, match="write-excitation"):
        measure_damping(Real())


@pytest.mark.parametrize("period, res", [(0.0, 0.05), (float("nan"), 0.05), ("1e-3", 0.05), (1e-3, -0.1),
                                         (1e-3, float("inf")), (1e-3, None), (True, 0.05)])
def test_bad_period_or_resolution_is_named(period, res):
    f = excitation(1e-3, 3.3, 0.045)
    with pytest.raises(ValidationError):
        fit_damping(f, np.zeros(f.size + 1), period, res)


def test_doctor_says_what_the_controller_credits_without_a_measurement(tmp_path):
    got = load_calibration("damping", "NONE-1", directory=tmp_path)
    assert got.calibration is None and got.origin == "none"
    assert "credits none of the declared damping" in got.source
    save_calibration(_cal(serial="NONE-1"), tmp_path)
    assert "none of the declared" not in load_calibration("damping", "NONE-1", directory=tmp_path).source


def test_the_standard_error_matches_the_spread_of_refits_under_independent_noise():
    """The fit's covariance (and with it the worst case's first-order sensitivity ``w``,
    from the same ``(J'J)^-1 grad b``): under independent Gaussian reading noise, the
    reported standard error matches the spread of the fitted damping over 60 noisy copies
    of one run. The arm (5 ms, 20 g, 1 N s/m) is one where mass and damping are fitted
    with correlated errors, so the gradient's mass term matters (its sign flipped gives
    4x). Band: the spread of 60 draws is known to about 9 % (1/sqrt(2 x 59)); 0.7-1.4 is
    about four of those either side."""
    T, m, b = 5e-3, 0.02, 1.0
    f = excitation(T, 3.3, m)
    y0 = free_arm_readings_mm(T, ArmParams(mass_kg=m, damping_ns_per_m=b, encoder_resolution_mm=0.0), f)
    rng = np.random.default_rng(0)
    fits = [fit_damping(f, y0 + rng.normal(0.0, 0.01, y0.size), T, 0.0) for _ in range(60)]
    spread = np.std([r.damping_ns_per_m for r in fits], ddof=1)
    assert 0.7 < np.median([r.damping_se_ns_per_m for r in fits]) / spread < 1.4


def test_a_run_s_last_force_may_be_left_empty(tmp_path):
    """The last row's force follows the last reading and is not used: it may be empty."""
    p = tmp_path / "run.csv"
    p.write_text("position_mm,force_n\n0.0,0.5\n0.1,-0.5\n0.3,\n")
    f, y = read_run_csv(p)
    assert f.tolist() == [0.5, -0.5] and y.tolist() == [0.0, 0.1, 0.3]


def test_a_bound_above_the_fit_less_its_margin_is_refused():
    """A fit's bound is the fit less its margin (``max(0, b - worst)``): a bound between
    the two was not produced by a fit, and the controller would credit damping nothing
    measured."""
    _cal(trusted=0.4)   # 0.45 - 0.05, up to rounding
    with pytest.raises(ValidationError, match="not a fit's bound"):
        _cal(trusted=0.42)


def test_an_edited_damping_file_is_skipped_and_not_credited(tmp_path):
    """A saved calibration whose bound was raised by hand (the fit and margin left as
    they were) fails validation: the store skips it and names it, and the controller
    credits what it does with no file: none of the declared damping."""
    import json
    p = save_calibration(_cal(), tmp_path)
    data = json.loads(p.read_text())
    data["trusted_damping_ns_per_m"] = 0.44
    p.write_text(json.dumps(data))
    got = load_calibration("damping", "OMNI-1", directory=tmp_path)
    assert got.calibration is None and str(p) in got.skipped
    cs = ControllerSettings.for_device(_Dev("OMNI-1"), directory=tmp_path)
    assert cs.measured_damping_ns_per_m is None
    assert _Dev.damping_ns_per_m > 0 and cs.trusted_damping_ns_per_m() == 0.0


@pytest.mark.parametrize("data, match", [
    ({"trusted_damping_ns_per_m": 0.1}, "missing damping_ns_per_m"),
    ([0.1, 0.2], "mapping"),
])
def test_from_dict_names_what_is_wrong(data, match):
    with pytest.raises(ValidationError, match=match):
        DampingCalibration.from_dict(data)


@pytest.mark.parametrize("forces, readings", [
    (["a"] * 20, np.zeros(21)),
    (np.zeros((2, 20)), np.zeros((2, 21))),
    (None, np.zeros(21)),
])
def test_a_run_that_is_not_numbers_is_named(forces, readings):
    with pytest.raises(ValidationError):
        fit_damping(forces, readings, 1e-3, 0.055)


@pytest.mark.parametrize("period, force, mass", [(1e-300, 3.3, 0.045), (1e-3, 3.3, 1e300), (1e-3, 1e-300, 0.045)])
def test_a_run_longer_than_a_run_file_holds_is_named(period, force, mass):
    """The excitation's length follows from the period, force limit and mass; a run the
    SDK could not read back from its own run file is refused by name (was an internal
    ValueError from numpy, or memory exhausted)."""
    with pytest.raises(ValidationError, match="a run file can hold"):
        excitation(period, force, mass)


def test_the_longest_run_s_file_reads_back(tmp_path):
    """:data:`MAX_RUN_TICKS` rows of the widest floats fit the reader's byte limit."""
    from hapticsdk.calibration.damping import MAX_CSV_BYTES, MAX_RUN_TICKS
    widest = repr(-1.2345678901234567e-300)
    assert MAX_RUN_TICKS * (2 * len(widest) + 2) <= MAX_CSV_BYTES


@pytest.mark.parametrize("share", [0.9, 1.1, 2.0])
def test_the_run_length_limit_holds_at_its_edge(share):
    """A run ``share`` times the longest a run file holds: below it the excitation is made
    and fits the file; above it, it is refused by name."""
    from hapticsdk.calibration.damping import FORCE_SHARE, MAX_RUN_TICKS, PATTERNS, TRAVEL_M
    segment_s = math.sqrt(TRAVEL_M * 0.045 / (FORCE_SHARE * 3.3))   # one segment's length
    period = segment_s / (share * MAX_RUN_TICKS / (8 * PATTERNS))
    if share < 1.0:
        assert excitation(period, 3.3, 0.045).size <= MAX_RUN_TICKS
    else:
        with pytest.raises(ValidationError, match="a run file can hold"):
            excitation(period, 3.3, 0.045)


def test_from_dict_takes_a_record_without_its_optional_fields():
    """``serial``, ``generated``, ``source`` and ``extra`` have defaults; a record without
    them is read (only the measured figures are required)."""
    d = {k: v for k, v in _cal().to_dict().items() if k not in ("serial", "generated", "source", "extra")}
    got = DampingCalibration.from_dict(d)
    assert got.serial is None and got.extra == {} and got.trusted_damping_ns_per_m == _cal().trusted_damping_ns_per_m


def test_the_standard_error_follows_correlated_reading_noise():
    """Reading errors that are correlated from tick to tick (a slow drift, a vibration
    slower than the period) carry less information than independent ones: the fit
    inflates its variance by ``(1 + rho) / (1 - rho)`` for the residuals' lag-one
    correlation ``rho``. Under AR(1) noise with rho = 0.9 the reported standard error
    still matches the spread of 60 refits (band as for independent noise above; without
    the inflation the ratio would be about 1/sqrt(19), 0.23)."""
    T = 5e-3
    f, y0 = simulated_run(T, 0.02, 1.0, 0.0)
    rng = np.random.default_rng(1)
    rho, sd = 0.9, 0.01

    def ar1(n):
        e = np.empty(n)
        e[0] = rng.normal(0.0, sd)
        for k in range(1, n):
            e[k] = rho * e[k - 1] + rng.normal(0.0, sd * math.sqrt(1.0 - rho * rho))
        return e
    fits = [fit_damping(f, y0 + ar1(y0.size), T, 0.0) for _ in range(60)]
    assert all(r.success for r in fits)
    assert np.median([r.residual_correlation for r in fits]) > 0.7
    spread = np.std([r.damping_ns_per_m for r in fits], ddof=1)
    assert 0.7 < np.median([r.damping_se_ns_per_m for r in fits]) / spread < 1.4


def test_the_fit_reports_the_mass_the_damping_and_a_constant_force():
    """``x = [mass, damping, offset force]``: on an exact run (no encoder) of an arm that
    also feels a constant force the run does not command (gravity, a cable), the fit
    recovers all three. The model is the arm's exact zero-order-hold response, so what is
    left is the search's tolerance on ``b/m`` (1e-10 relative) and rounding: 1e-6 leaves
    room for both."""
    T, m, b, f0 = 2e-3, 0.06, 0.4, 0.05
    f = excitation(T, 3.3, m)
    y = free_arm_readings_mm(T, ArmParams(mass_kg=m, damping_ns_per_m=b, encoder_resolution_mm=0.0), f + f0)
    fit = fit_damping(f, y, T, 0.0)
    assert fit.success, fit.message
    assert fit.x == pytest.approx([m, b, f0], rel=1e-6)
    assert fit.mass_kg == pytest.approx(m, rel=1e-6) and fit.damping_ns_per_m == pytest.approx(b, rel=1e-6)


def test_the_response_s_small_decay_series_meets_its_exact_form():
    """The response's coefficients near ``alpha T = 0`` come from a series below 1e-4 and
    from ``expm1`` above. At the switch both must give the same numbers: the series'
    error there is below (1e-4)^3 / 24, about 4e-14, and the exact form's is rounding over
    the cancellation in ``T - h`` (about 1e-16 / 5e-5 = 2e-12), so 1e-10 relative is far
    above both and far below a wrong term of the series (x^2 / 12 = 8e-10 for ``g``'s
    last term, x / 3 for a sign)."""
    from hapticsdk.calibration.damping import _hg

    dt = 1e-3
    below = _hg(1e-4 * (1 - 1e-9) / dt, dt)   # the series
    above = _hg(1e-4 * (1 + 1e-9) / dt, dt)   # expm1
    assert below == pytest.approx(above, rel=1e-10, abs=0.0), (below, above)


@pytest.mark.parametrize("n, ok", [(7, False), (8, True)])
def test_a_run_of_eight_forces_is_the_shortest_taken(n, ok):
    """At least 8 forces (and one reading more): 8 is taken, 7 is named."""
    f = np.tile([1.0, -1.0], 8)[:n]
    y = np.concatenate([[0.0], np.cumsum(np.cumsum(f))]) * 0.01
    if ok:
        assert isinstance(fit_damping(f, y, 1e-3, 0.0).message, str)
    else:
        with pytest.raises(ValidationError, match="at least 8 forces"):
            fit_damping(f, y, 1e-3, 0.0)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_the_measurement_drives_its_axis_alone(axis):
    """``measure_damping(device, axis=k)`` pushes along axis ``k`` only, both ways: every
    command's direction is the unit vector of that axis, +1 or -1, and 0 on the others."""
    from hapticsdk.calibration.damping import measure_damping

    dev = _omni(finger=FingerParams(0.0, 0.0, 0.0))
    seen = []
    real = dev.command

    def spy(cmd, *a, **kw):
        if cmd.force_n:
            seen.append(tuple(cmd.direction))
        return real(cmd, *a, **kw)
    dev.command = spy
    measure_damping(dev, axis=axis)
    signs = {d[axis] for d in seen}
    assert signs == {1.0, -1.0}, signs
    assert all(d[k] == 0.0 for d in seen for k in range(3) if k != axis)


def test_a_run_must_move_four_counts():
    """Below 4 encoder counts of travel the readings say nothing about the damping: 3
    counts are named, 5 are fitted."""
    q = 0.055
    f = excitation(1e-3, 3.3, 0.045)
    shape = np.concatenate([[0.0], np.cumsum(np.cumsum(f))])
    shape /= np.ptp(shape)
    three = fit_damping(f, np.round(3 * q * shape / q) * q, 1e-3, q)
    assert not three.success and "did not move by 4 encoder counts" in three.message
    five = fit_damping(f, np.round(5 * q * shape / q) * q, 1e-3, q)
    assert "did not move" not in five.message


def test_the_fit_reports_its_residual_and_its_own_time():
    """``fun`` is the residuals' root mean square (m): about the reading noise's standard
    deviation on a noisy run (10 um of white noise, some 480 readings: the RMS is known to
    about 3 %, so 15 % is five of those), about 0 on an exact one. ``runtime_s`` is the
    fit's own time, >= 0 and well below a minute, for a fit and for a run it refuses."""
    T = 5e-3
    f, y0 = simulated_run(T, 0.02, 1.0, 0.0)
    noisy = fit_damping(f, y0 + np.random.default_rng(2).normal(0.0, 0.01, y0.size), T, 0.0)
    assert noisy.fun == pytest.approx(1e-5, rel=0.15)
    assert fit_damping(f, y0, T, 0.0).fun < 1e-9
    still = fit_damping(f, np.zeros(f.size + 1), T, 0.055)
    assert not still.success
    for r in (noisy, still):
        assert 0.0 <= r.runtime_s < 60.0


def test_a_simulated_run_is_sized_by_the_declared_mass():
    """A run on a device is sized by the mass it declares, and the arm moves as its true
    mass makes it: ``simulated_run(..., declared_mass_kg=)`` plays the excitation of the
    declaration on the true arm (the randomised stability benchmark declares each arm's
    mass at 0.5x-2x the truth); without it, the true mass sizes the run."""
    f, y = simulated_run(1e-3, 0.05, 0.5, 0.01, declared_mass_kg=0.1)
    assert np.array_equal(f, excitation(1e-3, 3.3, 0.1))
    arm = ArmParams(mass_kg=0.05, damping_ns_per_m=0.5, max_force_n=3.3, encoder_resolution_mm=0.01)
    assert np.array_equal(y, free_arm_readings_mm(1e-3, arm, f))
    f0, _ = simulated_run(1e-3, 0.05, 0.5, 0.01)
    assert np.array_equal(f0, excitation(1e-3, 3.3, 0.05))
    assert not np.array_equal(f, f0)

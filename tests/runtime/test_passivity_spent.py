"""A spent energy bound is said, not silent. The stiff-wall controller's bound covers the
whole session (docs/runtime.md, Passivity item 7): once repeated presses have booked the
allowance, the force above the Colgate spring waits for credit, and an arm with no damping
credited (the default until it is measured hands off) then renders no wall at all. The
controller counts those ticks (``spent_ticks`` in ``report()`` and in the servo loop's
``passivity`` figures) and logs one warning naming the remedy.

Simulated Omni (45 g, 0.5 N s/m true and declared, 0.055 mm encoder, 3.3 N), 1 kHz,
simulated time, presses to 2 mm over 0.3 s, held 0.3 s, released over 0.3 s."""

from __future__ import annotations

import logging

import numpy as np

from hapticsdk.passivity import ControllerSettings

LOGGER = "hapticsdk.passivity.controller"


def _presses(gs: float, presses: int, settings=None):
    from hapticsdk.runtime import ServoLoop
    from hapticsdk.sim.finger import press_slide
    from hapticsdk_hardness.dimension import HardnessRenderer
    from hapticsdk_hardness.omni import OmniVirtual
    from hapticsdk_hardness.voicecoil import VoiceCoilVirtual

    cycle = press_slide(depth_mm=2.0, press_s=0.3, hold_s=0.3, slide_s=0.0, release_s=0.3, rest_s=0.2)
    tr = cycle
    for _ in range(presses - 1):
        tr = tr.then(cycle, gap_s=0.01)
    dev = OmniVirtual(trajectory=tr, finger="medium")
    kw = {} if settings is None else {"passivity_settings": settings(dev)}
    loop = ServoLoop(dev, [HardnessRenderer(gs)], {"force": dev, "coil": VoiceCoilVirtual()},
                     period_s=0.001, **kw)
    rep = loop.run(tr.duration_s)
    per = cycle.duration_s + 0.01
    t, pen, f = rep.log["t"], rep.log["penetration_mm"], rep.log["force_n"]
    last = (t >= (presses - 1) * per) & (pen > 0.5)   # the last press, deeper than the ramp's start
    return rep, f[last], pen[last]


def _spent_records(caplog):
    return [r for r in caplog.records if r.name == LOGGER and "energy bound is spent" in r.getMessage()]


def test_an_uncalibrated_arm_says_once_that_its_wall_is_gone(caplog):
    caplog.set_level(logging.WARNING, logger=LOGGER)
    rep, f_last, _ = _presses(1.0, 3)
    fig = rep.passivity["force"]
    assert fig["spent_ticks"] > 0 and fig["spent_ticks"] <= fig["active_ticks"]
    assert np.all(f_last == 0.0)            # what the warning says: no wall on the last press
    (rec,) = _spent_records(caplog)         # once, for three presses
    assert "no damping is credited" in rec.getMessage() and "hapticsdk calibrate damping" in rec.getMessage()


def _measured(dev):
    """The loop's settings with the arm's damping measured hands off (the same arm, no
    finger), as docs/devices.md tells a lab to do before stiff walls."""
    from hapticsdk.calibration.damping import DampingCalibration, measure_damping
    from hapticsdk.sim.finger import FingerParams
    from hapticsdk_hardness.omni import OmniVirtual

    fit, _, _ = measure_damping(OmniVirtual(finger=FingerParams(0.0, 0.0, 0.0)))
    cal = DampingCalibration.from_fit(fit, period_s=1e-3, resolution_mm=dev.encoder_resolution_mm,
                                      generated=True, source="test: simulated Omni, hands off")
    return ControllerSettings.for_device(dev, damping=cal)


def test_with_the_damping_measured_the_spring_stays_and_the_warning_says_so(caplog):
    caplog.set_level(logging.WARNING, logger=LOGGER)
    rep, f_last, pen = _presses(1.0, 3, _measured)
    assert rep.passivity["force"]["spent_ticks"] > 0
    (rec,) = _spent_records(caplog)
    assert "N s/m of credited damping" in rec.getMessage()
    # the Colgate spring on the measured damping is left: a force on every tick of the last press
    assert np.all(f_last > 0.0)


def test_a_first_soft_press_spends_nothing(caplog):
    # S7's stiffness on one press: the bound is not spent, nothing is said
    caplog.set_level(logging.WARNING, logger=LOGGER)
    rep, f_last, pen = _presses(0.16, 1)
    assert rep.passivity["force"]["spent_ticks"] == 0
    assert _spent_records(caplog) == []
    np.testing.assert_allclose(f_last, 0.16 * pen, rtol=0.1)


def test_a_ramp_that_holds_back_is_not_a_spent_bound():
    # a stylus still 0.5 mm inside a 3 N/mm wall: the first ticks send less than the wall
    # (the ramp's step), the bound untouched; only ticks with U >= E0 count as spent
    from hapticsdk.passivity import PassivityController
    from hapticsdk_hardness.omni import OmniVirtual

    pc = PassivityController(ControllerSettings.for_device(OmniVirtual()))
    for _ in range(3):
        f = pc.step(-0.5, 1e-3, 1.5)
        pc.commit(f)
    rep = pc.report()
    assert rep["active_ticks"] >= 2 and f < 1.5
    assert rep["energy_bound_j"] < ControllerSettings.for_device(OmniVirtual()).energy_budget_j(1e-3)
    assert rep["spent_ticks"] == 0


def test_the_remedy_the_warning_names_works_on_the_simulated_arm(tmp_path, monkeypatch, capsys, caplog):
    # the command the warning names, on the simulated Omni nobody holds, saved where the
    # loop looks: S7's wall is then delivered on every press, and nothing is spent
    from hapticsdk.cli import main
    from hapticsdk_hardness.omni import OmniVirtual

    monkeypatch.setenv("HAPTICSDK_CALIBRATION_DIR", str(tmp_path))
    assert main(["calibrate", "damping", "--device", "omni-virtual", "--device-option", "finger=none",
                 "--save", "--json"]) == 0
    capsys.readouterr()
    caplog.set_level(logging.WARNING, logger=LOGGER)
    rep, f_last, pen = _presses(0.16, 6)
    assert rep.passivity["force"]["spent_ticks"] == 0 and _spent_records(caplog) == []
    np.testing.assert_allclose(f_last, 0.16 * pen, rtol=0.1)
    # the calibration is the arm's: an arm with other physics is another serial, not credited
    assert ControllerSettings.for_device(OmniVirtual()).measured_damping_ns_per_m is not None
    assert ControllerSettings.for_device(OmniVirtual(damping_ns_per_m=0.0)).measured_damping_ns_per_m is None
    assert OmniVirtual(finger="stiff").serial_number == OmniVirtual(finger="soft").serial_number

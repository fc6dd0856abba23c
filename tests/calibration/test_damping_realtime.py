"""The hands-off damping run played in real time (``measure_damping(device,
realtime=True)``, :func:`hapticsdk.calibration.damping.play_damping_run`): paced on the
machine's clock, through the device's safety layer, fitted with the steps as measured.

The simulated Omni is stepped by the time that really passed between ticks, so these
runs see whatever the machine does to the loop (other processes share the CPU): nothing
here asserts a time; what holds on a busy machine is that the bound stays below the
truth, and that every exit leaves the device at 0 N and closed.
"""

import numpy as np
import pytest

from damping_faults import fail_at_step
from hapticsdk.calibration.damping import DampingCalibration, excitation, measure_damping, play_damping_run
from hapticsdk.calibration.store import load_calibration, save_calibration
from hapticsdk.errors import ValidationError
from hapticsdk.passivity import ControllerSettings
from hapticsdk.sim.finger import FingerParams


def _omni(**kw):
    from hapticsdk.devices.actuators import create_actuator
    return create_actuator("omni-virtual", finger=FingerParams(0.0, 0.0, 0.0), **kw)


def test_measured_in_real_time_on_the_simulated_omni_then_stored_and_credited(tmp_path):
    dev = _omni()
    fit, forces, readings = measure_damping(dev, realtime=True)
    true_b = dev.arm.damping_ns_per_m
    assert fit.success, fit.message
    assert 0.0 <= fit.trusted_damping_ns_per_m <= true_b
    assert not dev.is_open
    f = excitation(1e-3, 3.3, dev.apparent_mass_kg)
    assert forces.size == f.size and readings.size == f.size + 1
    assert np.all(np.abs(forces) <= np.abs(f) + 1e-12)       # the safety layer's read-back, never more
    cal = DampingCalibration.from_fit(fit, period_s=1e-3, resolution_mm=dev.encoder_resolution_mm,
                                      serial=dev.serial_number, generated=True,
                                      source="test: real-time run, simulated")
    save_calibration(cal, tmp_path)
    got = load_calibration("damping", dev.serial_number, directory=tmp_path)
    assert got.calibration == cal
    assert ControllerSettings.for_device(dev, directory=tmp_path).measured_damping_ns_per_m == \
        fit.trusted_damping_ns_per_m


def test_the_run_records_each_tick_s_timestamp_on_the_loop_s_clock():
    run = play_damping_run(_omni())
    n = run.forces_n.size
    assert run.times_s.size == n + 1 and run.times_s[0] == 0.0 and np.all(np.diff(run.times_s) > 0)
    assert run.simulated and run.latency_s == 0.0 and not run.read_s.any() and not run.command_s.any()
    assert run.late_ticks == int(np.sum(np.diff(run.times_s) > 1.5e-3))
    assert run.fit.trusted_damping_ns_per_m <= 0.5


def test_a_simulated_device_opened_and_stepped_before_is_timed_on_its_own_clock():
    """The caller opened the device and ran it for a while: its own clock is not at 0, and
    the commands carry its time, so its safety layer does not take them for stale (or
    for fresh ones too long) and the drops the fit models are the ones it makes."""
    from hapticsdk.runtime.clock import SimulatedClock

    dev = _omni()
    dev.open()
    for _ in range(1234):
        dev.step(1e-3)
    run = play_damping_run(dev, clock=SimulatedClock(compute_s=20e-6, stalls={350: 3e-3}))
    fit, b = run.fit, dev.arm.damping_ns_per_m
    assert fit.success and abs(fit.damping_ns_per_m - b) <= fit.worst_error_ns_per_m
    assert 0.5 * b < fit.trusted_damping_ns_per_m <= b
    assert dev.is_open and dev.read_back().force_n == 0.0
    dev.close()


def test_late_ticks_are_fitted_as_they_were():
    """Ticks made late on purpose (a simulated clock with stalls: one 3 periods late, one
    past the safety layer's restart gap, which ramps the force again): the steps are
    fitted as measured and the stale forces as dropped, so the fit is within its margin
    and the bound stays worth having."""
    from hapticsdk.runtime.clock import SimulatedClock

    clock = SimulatedClock(compute_s=20e-6, stalls={350: 3e-3, 420: 0.5e-3, 600: 0.06})
    dev = _omni()
    run = play_damping_run(dev, clock=clock)
    fit, b = run.fit, dev.arm.damping_ns_per_m
    assert run.late_ticks >= 2 and max(np.diff(run.times_s)) > 0.05
    assert dev.safety.events["faults"] == 1 and dev.safety.events["stale_zeroed"] >= 2   # the ramp ran again
    assert fit.success and abs(fit.damping_ns_per_m - b) <= fit.worst_error_ns_per_m
    assert 0.5 * b < fit.trusted_damping_ns_per_m <= b


class _Stop(Exception):
    pass


@pytest.mark.parametrize("exc", [_Stop, KeyboardInterrupt])
@pytest.mark.parametrize("opened_by_caller", [False, True])
def test_an_error_mid_run_leaves_the_device_at_zero_and_closed(exc, opened_by_caller):
    dev = _omni()
    if opened_by_caller:
        dev.open()
    sent = fail_at_step(dev, 305, exc)   # past the 0.3 s at 0 N at 1 kHz: mid-run, +F applied
    with pytest.raises(exc, match="mid-run"):
        play_damping_run(dev)
    assert any(s > 0 for s in sent[:-1]) and sent[-1] == 0.0
    assert dev.is_open == opened_by_caller
    if opened_by_caller:
        assert dev.read_back().force_n == 0.0
        dev.close()


def test_the_device_is_held_at_zero_through_its_start_ramp_first():
    dev = _omni()
    sent = []
    real_command = dev.command

    def record(cmd, **kw):
        sent.append((kw["now"], cmd.force_n))
        return real_command(cmd, **kw)

    dev.command = record
    play_damping_run(dev)
    first = next(i for i, (_, f) in enumerate(sent) if f != 0.0)
    ramp = dev.safety.settings.ramp_time_s
    assert sent[first][0] >= ramp and first >= ramp / 1e-3      # a 0 N command every tick of the ramp
    assert all(f == 0.0 for _, f in sent[:first])


class _RealOmni:
    """A device that is not simulated: the loop does not step it (so it never moves), and
    its reads and commands take real time."""

    def __new__(cls, **kw):
        from hapticsdk_hardness.omni import OmniVirtual

        class Real(OmniVirtual):
            simulated = False

        for k, v in kw.items():
            setattr(Real, k, v)
        return Real(finger=FingerParams(0.0, 0.0, 0.0))


def test_a_real_device_that_declares_no_latency_is_refused_before_it_is_opened():
    dev = _RealOmni()
    with pytest.raises(ValidationError, match="transport_latency_s"):
        play_damping_run(dev)
    assert not dev.is_open and dev.last_command is None


def test_a_device_that_declares_no_mass_or_force_limit_is_refused():
    class Bare:
        simulated = True
        is_open = False
    with pytest.raises(ValidationError, match="apparent_mass_kg"):
        play_damping_run(Bare())
    with pytest.raises(ValidationError, match="apparent_mass_kg"):
        measure_damping(Bare(), realtime=True)


def test_a_failed_fit_on_a_real_device_credits_nothing_and_leaves_it_at_zero_and_closed():
    """A real device (here one that does not move: nobody steps it) with a declared
    latency: the run's reads and commands take measured time, the fit finds the arm did
    not move and fails, credits nothing; the device is at 0 N and closed."""
    dev = _RealOmni(transport_latency_s=2e-4)
    run = play_damping_run(dev)
    assert not run.fit.success and run.fit.trusted_damping_ns_per_m == 0.0
    assert "did not move" in run.fit.message
    assert not run.simulated and run.latency_s == 2e-4
    assert (run.read_s >= 0).all() and (run.command_s > 0).all()
    assert not dev.is_open and dev.last_command.force_n == 0.0
    with pytest.raises(ValidationError, match="the fit failed"):
        DampingCalibration.from_fit(run.fit, period_s=1e-3, resolution_mm=0.055)

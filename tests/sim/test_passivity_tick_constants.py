"""The passivity controller's constants derived from its settings (issue 30, round 9): derived
once per configuration, not on every tick, and derived again when the configuration changes
(a field set on the settings, or new settings assigned), so a change takes effect at the
next step as before."""

import math

import pytest

from hapticsdk.passivity import ControllerSettings, PassivityController


def _settings(**kw):
    base = dict(device_damping_ns_per_m=2.0, position_resolution_mm=0.01, max_force_n=8.0,
                device_mass_kg=0.1, period_s=0.001)
    base.update(kw)
    return ControllerSettings(**base)


def _press(pc, ticks, depth_mm=3.0, k_n_per_mm=2.0):
    """Press slowly to ``depth_mm`` and hold; the controller's outputs."""
    out = []
    for i in range(ticks):
        x = -min(depth_mm, 0.01 * i)
        f = pc.step(x, 0.001, k_n_per_mm * max(-x, 0.0))
        pc.commit(f)
        out.append(f)
    return out


def test_derived_once_per_configuration_and_again_after_a_change(monkeypatch):
    calls = []
    derive = ControllerSettings._derive_tick_constants

    def counting(self):
        calls.append(self)
        return derive(self)

    monkeypatch.setattr(ControllerSettings, "_derive_tick_constants", counting)
    pc = PassivityController(_settings())
    _press(pc, 300)
    assert len(calls) == 1                  # not per tick
    pc.settings.energy_allowance_j = 5e-5   # a field set: derived again at the next step
    _press(pc, 50)
    assert len(calls) == 2
    pc.settings = _settings(max_force_n=4.0)   # new settings: derived from them
    _press(pc, 50)
    assert len(calls) == 3 and calls[-1] is pc.settings


def test_a_field_set_mid_contact_takes_effect_at_the_next_step():
    pc = PassivityController(_settings())
    held = _press(pc, 400)
    assert held[-1] > 4.0                   # pressed well above the new limit below
    pc.settings.max_force_n = 1.0
    f = pc.step(-3.0, 0.001, 6.0)
    assert f <= 1.0
    # and the same step of a controller configured that way from the start
    fresh = PassivityController(_settings(max_force_n=1.0))
    assert max(_press(fresh, 400)) <= 1.0


@pytest.mark.parametrize("kw", [{}, {"measured_damping_ns_per_m": 0.3}, {"declared_damping_trust": 0.5},
                                {"declared_damping_trust": 0.5, "position_resolution_mm": 0.0}, {"device_mass_kg": None},
                                {"max_force_n": None}, {"period_s": None}, {"position_resolution_mm": 0.0},
                                {"period_s": 0.01, "max_force_n": 3.3}, {"energy_allowance_j": 1e-6}])
def test_derived_constants_equal_the_settings_own_formulas(kw):
    s = _settings(**kw)
    q, h, c2, b_lo, b_s, m, fm, rt, tn, allowance, bound, kc_p, sp_p, e0_p = s._derive_tick_constants()
    assert q == s.position_resolution_mm * 1e-3 and h == 0.5 * q and c2 == 2.0 * s.position_resolution_mm
    assert b_lo == s.trusted_damping_ns_per_m()
    assert b_s == float(s.spring_damping_ns_per_m())
    assert m == s.trusted_mass_kg()
    assert (fm, rt, tn, allowance, bound) == (s.max_force_n, s.ramp_time_s, s.period_s, s.energy_allowance_j,
                                              s.energy_bound)
    if tn is None or fm is None:
        assert kc_p is None and sp_p is None and e0_p is None
    else:
        assert sp_p == s.ramp_step_n(tn)
        assert e0_p == s.energy_budget_j(tn)
        assert kc_p == (min(2.0 * b_s / tn, sp_p / q) if q > 0 else 2.0 * b_s / tn)
        assert math.isfinite(kc_p)


def test_not_a_field_of_the_settings():
    import dataclasses
    s = _settings()
    s._derive_tick_constants()
    assert "_tick_consts" not in {f.name for f in dataclasses.fields(s)}
    assert s == _settings()                 # derived or not, equal settings compare equal
    assert "_tick_consts" not in repr(s)

"""The declared limits are checked when the safety layer is configured, not per command
(issue 30): the per-tick path compares with floats it no longer converts, so a bad
declaration must be refused before the first tick, where before it either failed on the
tick that reached the limit (a string) or let every command through (NaN)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hapticsdk.devices.actuators import ActuatorLimits
from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.errors import ValidationError
from hapticsdk.devices.safety import SafetyLayer, declared_limits

NAN, INF = float("nan"), float("inf")

BAD = [
    ({"max_force_n": NAN}, "max_force_n"),
    ({"max_force_n": -1.0}, "max_force_n"),
    ({"max_force_n": "3.3"}, "max_force_n"),
    ({"max_force_n": True}, "max_force_n"),
    ({"max_amplitude": INF}, "max_amplitude"),
    ({"max_amplitude": -0.5}, "max_amplitude"),
    ({"max_stiffness_n_per_mm": NAN}, "max_stiffness_n_per_mm"),
    ({"max_force_rate_n_per_tick": -0.1}, "max_force_rate_n_per_tick"),
    ({"max_velocity_mm_s": 0.0}, "max_velocity_mm_s"),
    ({"max_velocity_mm_s": NAN}, "max_velocity_mm_s"),
    ({"frequency_range_hz": (120.0, 30.0)}, "frequency_range_hz"),
    ({"frequency_range_hz": (NAN, 30.0)}, "frequency_range_hz"),
    ({"frequency_range_hz": (-5.0, 30.0)}, "frequency_range_hz"),
    ({"frequency_range_hz": (30.0,)}, "frequency_range_hz"),
    ({"frequency_range_hz": 30.0}, "frequency_range_hz"),
    ({"max_amplitude": 1.0, "min_amplitude": 2.0}, "min_amplitude"),
    ({"min_amplitude": NAN}, "min_amplitude"),
]


@pytest.mark.parametrize("fields, name", BAD)
def test_a_bad_declaration_is_refused_when_the_layer_is_built(fields, name):
    with pytest.raises(ValidationError) as e:
        SafetyLayer(ActuatorLimits(**fields))
    assert e.value.field == f"limits.{name}"


@pytest.mark.parametrize("fields, name", BAD)
def test_assigning_a_bad_declaration_keeps_the_limits_in_force(fields, name):
    good = ActuatorLimits(max_force_n=3.3, frequency_range_hz=(30.0, 120.0), max_amplitude=1.0)
    lay = SafetyLayer(good, ramp_time_s=0.0, start_max_force_n=None, start_max_penetration_mm=None)
    with pytest.raises(ValidationError):
        lay.limits = ActuatorLimits(**fields)
    assert lay.limits is good
    out = lay.filter(ChannelCommand("force", force_n=50.0, frequency_hz=1000.0, amplitude=9.0), now=0.0)
    assert (out.force_n, out.frequency_hz, out.amplitude) == (3.3, 120.0, 1.0)


def test_an_actuator_declaring_bad_limits_fails_when_built_not_on_a_tick():
    from hapticsdk.devices.actuators import Actuator

    class Bad(Actuator):
        name = "bad-limits"
        channel = "force"
        limits = ActuatorLimits(max_force_n=NAN)

        def _command(self, cmd):
            pass

        def _stop(self):
            pass

    with pytest.raises(ValidationError) as e:
        Bad()
    assert e.value.field == "limits.max_force_n"


def test_declared_limits_are_floats_and_commands_stay_inside_them():
    """Seeded random valid declarations (ints and floats, numpy scalars): accepted, made
    floats, and every filtered command of random values (huge, negative, inside) lies
    within them, of type float."""
    rng = np.random.default_rng(30)
    for _ in range(200):
        lo = float(rng.uniform(0, 200))
        kinds = [int, float, np.float64]
        mk = kinds[int(rng.integers(3))]
        lim = ActuatorLimits(max_force_n=mk(int(rng.integers(1, 20))), max_amplitude=mk(int(rng.integers(1, 50))),
                             frequency_range_hz=(lo, lo + float(rng.uniform(0, 300))),
                             max_force_rate_n_per_tick=float(rng.uniform(0.1, 5)))
        d = declared_limits(lim)
        assert all(type(v) is float for k, v in d.items() if v is not None and k != "frequency_range_hz")
        assert all(type(v) is float for v in d["frequency_range_hz"])
        lay = SafetyLayer(lim, ramp_time_s=0.0, start_max_force_n=None, start_max_penetration_mm=None)
        for j in range(20):
            f, fr, a = (float(x) for x in rng.normal(0, [40, 400, 60]))
            out = lay.filter(ChannelCommand("x", force_n=f, frequency_hz=fr, amplitude=a), now=j * 1e-3)
            assert abs(out.force_n) <= d["max_force_n"] + 1e-12
            assert d["frequency_range_hz"][0] <= out.frequency_hz <= d["frequency_range_hz"][1]
            assert 0.0 <= out.amplitude <= d["max_amplitude"]
            assert type(out.frequency_hz) is float and type(out.amplitude) is float
            assert not math.isnan(out.force_n)


def test_a_nan_frequency_still_reaches_the_actuators_own_check():
    """The per-tick clamp leaves a NaN frequency NaN, as before (the public
    Actuator.command refuses non-finite values before the layer sees them)."""
    lay = SafetyLayer(ActuatorLimits(frequency_range_hz=(30.0, 120.0), max_amplitude=1.0))
    out = lay.filter(ChannelCommand("v", frequency_hz=NAN, amplitude=0.5), now=0.0)
    assert math.isnan(out.frequency_hz)


def test_the_edges_of_each_declared_range_are_taken():
    """Each range is closed at its ends (``declared_limits``): ``min_amplitude`` may equal
    ``max_amplitude`` (an actuator with one amplitude), a frequency band may be a single
    frequency, and ``max_*`` may be 0."""
    d = declared_limits(ActuatorLimits(max_amplitude=2.0, min_amplitude=2.0, frequency_range_hz=(60.0, 60.0),
                                       max_force_n=0.0))
    assert (d["min_amplitude"], d["max_amplitude"], d["frequency_range_hz"], d["max_force_n"]) == \
        (2.0, 2.0, (60.0, 60.0), 0.0)
    lay = SafetyLayer(ActuatorLimits(max_amplitude=2.0, min_amplitude=2.0), ramp_time_s=0.0,
                      start_max_force_n=None, start_max_penetration_mm=None)
    assert lay.filter(ChannelCommand("v", frequency_hz=60.0, amplitude=0.5), now=0.0).amplitude == 2.0

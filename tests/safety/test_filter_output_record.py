"""The safety layer's output record (issue 30): ``SafetyLayer.filter`` stores the fields
of its new :class:`ChannelCommand` itself, in the order the dataclass's ``__init__``
stores them, instead of calling the class. The record must be the object the constructor
would have made (same type, same fields in the same order, same values bit for bit), and
still a new one on every call: backends and callers keep what they get (a recording
backend keeps every command; ``last_command`` and ``current()`` hand the last one out)."""

from __future__ import annotations

import dataclasses
import math
import struct

import numpy as np
import pytest

from hapticsdk.devices.actuators import ActuatorLimits, DeviceState
from hapticsdk.devices.safety import SafetyLayer
from hapticsdk.perception.dimensions import ChannelCommand

LIMITS = ActuatorLimits(max_force_n=3.3, max_stiffness_n_per_mm=2.3, frequency_range_hz=(30.0, 120.0),
                        max_amplitude=25.0, amplitude_unit="V", max_velocity_mm_s=400.0,
                        max_force_rate_n_per_tick=0.5)


def _bits(v):
    return None if v is None else struct.pack("d", v)


def _commands(n=400, seed=3):
    rng = np.random.default_rng(seed)
    pick = lambda p, lo, hi: float(rng.uniform(lo, hi)) if rng.random() < p else None   # noqa: E731
    for _ in range(n):
        d = None if rng.random() < 0.5 else (0.0, float(rng.uniform(-1, 1)), 1.0)
        yield ChannelCommand(str(rng.choice(["force", "vib", "coil"])), pick(0.7, -8.0, 8.0),
                             pick(0.6, 0.0, 300.0), pick(0.6, -5.0, 40.0), d)


def test_the_output_record_is_the_constructors_object_and_a_new_one_each_call():
    lay = SafetyLayer(LIMITS, ramp_time_s=0.05)
    lay.reset(0.0)
    names = [f.name for f in dataclasses.fields(ChannelCommand)]
    kept = []
    for k, cmd in enumerate(_commands()):
        lay.observe(DeviceState(t=0.0, position_mm=np.array([0.0, -0.5 * (k % 7), 0.0]),
                                velocity_mm_s=np.array([float(k % 450), 0.0, 0.0])))
        out = lay.filter(cmd, k * 0.001)
        assert type(out) is ChannelCommand and out is not cmd
        assert all(out is not o for o, _ in kept)
        # what the class makes from the same values: same fields, same order, same bits
        again = ChannelCommand(*(getattr(out, n) for n in names))
        assert list(vars(out)) == list(vars(again)) == names
        assert out == again and repr(out) == repr(again)
        assert all(_bits(getattr(out, n)) == _bits(getattr(again, n))
                   for n in ("force_n", "frequency_hz", "amplitude"))
        assert out.role == cmd.role and out.direction is cmd.direction
        assert lay.current(k * 0.001) is out
        kept.append((out, dataclasses.astuple(out)))
    # nothing a caller kept was changed afterwards
    assert all(dataclasses.astuple(o) == t for o, t in kept)
    assert sum(lay.hits.values()) > 100   # the commands were clamped on many paths


def test_the_record_is_what_the_dataclass_init_stores():
    """The filter writes the fields itself: a ChannelCommand whose __init__ did more than
    store its arguments (a __post_init__, slots, a frozen class) would need the filter
    changed with it."""
    assert not hasattr(ChannelCommand, "__post_init__")
    assert not ChannelCommand.__dataclass_params__.frozen   # type: ignore[attr-defined]
    assert "__slots__" not in vars(ChannelCommand)
    lay = SafetyLayer(ActuatorLimits(), ramp_time_s=0.0, start_max_force_n=None, start_max_penetration_mm=None)
    out = lay.filter(ChannelCommand("x", math.nan, None, None, None), 0.0)
    assert math.isnan(out.force_n) and list(vars(out)) == [f.name for f in dataclasses.fields(ChannelCommand)]


@pytest.mark.parametrize("amp", [-0.0, 0.0, -1e-300, -2.0])
def test_a_negative_amplitude_is_counted_as_before(amp):
    lay = SafetyLayer(LIMITS, ramp_time_s=0.0)
    lay.reset(0.0)
    out = lay.filter(ChannelCommand("vib", None, 50.0, amp), 0.0)
    neg = amp < 0
    assert lay.hits.get("negative_amplitude", 0) == int(neg)
    assert _bits(out.amplitude) == _bits(0.0 if neg else amp)

"""The simulated arm's parameters refuse by name what is not a number in range, when the
class is built directly (not only through ``hs.create_actuator``, which names any error of
a plugin's options): ``ArmParams`` and the simulated Omni's ``mass_kg``,
``damping_ns_per_m``, ``encoder_resolution_mm``, ``velocity_filter_hz`` and ``y0_mm``.
Before, a list, a string or None reached numpy and came out as its ``TypeError`` or
``ValueError`` (``The truth value of an empty array is ambiguous``)."""

from __future__ import annotations

import math
from fractions import Fraction

import pytest

from hapticsdk.errors import ValidationError
from hapticsdk.sim.arm import ArmParams

NOT_NUMBERS = ([], [[]], [1.0], "x", "1.5", None, {"a": 1}, (1, 2), complex(1, 1), b"1", True,
               float("nan"), float("inf"), -float("inf"), 10 ** 400)


@pytest.mark.parametrize("value", NOT_NUMBERS, ids=repr)
@pytest.mark.parametrize("field", ["mass_kg", "damping_ns_per_m", "max_force_n", "encoder_resolution_mm"])
def test_arm_params_name_the_field(field, value):
    with pytest.raises(ValidationError) as err:
        ArmParams(**{field: value})
    assert err.value.field == f"arm.{field}"


@pytest.mark.parametrize("field, value", [("mass_kg", 0.0), ("mass_kg", -1.0), ("damping_ns_per_m", -0.1),
                                          ("max_force_n", -1.0), ("encoder_resolution_mm", -1e-9)])
def test_arm_params_out_of_range(field, value):
    with pytest.raises(ValidationError):
        ArmParams(**{field: value})


def test_arm_params_in_range_are_kept_as_given():
    a = ArmParams(mass_kg=1, damping_ns_per_m=0, max_force_n=Fraction(33, 10), encoder_resolution_mm=0.0)
    assert (a.mass_kg, a.damping_ns_per_m, a.max_force_n) == (1, 0, Fraction(33, 10))
    assert math.isclose(float(a.max_force_n), 3.3)


@pytest.mark.parametrize("value", NOT_NUMBERS, ids=repr)
@pytest.mark.parametrize("key", ["mass_kg", "damping_ns_per_m", "encoder_resolution_mm", "velocity_filter_hz",
                                 "y0_mm"])
@pytest.mark.parametrize("device", ["omni-virtual", "omni3-virtual"])
def test_the_simulated_omni_names_the_option(device, key, value):
    from hapticsdk.plugins import registry
    cls = registry("actuator").load(device)
    if value is None:   # None is each option's default
        cls(**{key: value}).close()
        return
    with pytest.raises(ValidationError) as err:
        cls(**{key: value})
    assert key in err.value.field


# -- finite but absurd values, built directly ---------------------------------------------
# Finite values from the whole float range (1e-308 to 1e308), each option alone: the class
# either refuses them by name at construction (where no exact hold or no encoder count
# exists in floating point) or runs a press through the servo loop with every force it
# sent and every reading finite, and stops. Before, a damping of 1e308 N s/m came out of
# the matrix exponential as ``ValueError: expm needs a finite matrix`` and a start of
# 1e308 mm as ``OverflowError`` (the three-axis Omni built both and failed on its first tick).
from hypothesis import example, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_HUGE_OR_TINY = st.one_of(st.floats(1e-308, 1e-30), st.floats(1e30, 1e308), st.sampled_from([1e-308, 1e308]))


@settings(max_examples=40, deadline=None, derandomize=True)
@given(device=st.sampled_from(["omni-virtual", "omni3-virtual"]),
       key=st.sampled_from(["mass_kg", "damping_ns_per_m", "encoder_resolution_mm", "velocity_filter_hz",
                            "y0_mm"]),
       value=_HUGE_OR_TINY, sign=st.sampled_from([1.0, -1.0]))
@example(device="omni-virtual", key="damping_ns_per_m", value=1e308, sign=1.0)
@example(device="omni3-virtual", key="damping_ns_per_m", value=1e308, sign=1.0)
@example(device="omni-virtual", key="y0_mm", value=1e308, sign=-1.0)
@example(device="omni3-virtual", key="y0_mm", value=1e308, sign=1.0)
def test_absurd_finite_values_are_refused_by_name_or_run_finite(device, key, value, sign):
    value = value * sign if key == "y0_mm" else value
    _refused_by_name_or_run_finite(device, {key: value}, key)


@pytest.mark.parametrize("device", ["omni-virtual", "omni3-virtual"])
@pytest.mark.parametrize("y0", [5.0, -5.0])
def test_an_encoder_finer_than_the_float_reads_the_position(device, y0):
    # 5 mm / 1e-308 mm is not a finite count: the reading is the position itself
    _refused_by_name_or_run_finite(device, {"encoder_resolution_mm": 1e-308, "y0_mm": y0}, None)


def _refused_by_name_or_run_finite(device, options, key):
    from hapticsdk.plugins import registry
    from hapticsdk.runtime import ServoLoop
    from renderers import Spring

    cls = registry("actuator").load(device)
    try:
        dev = cls(**options)
    except ValidationError as err:
        assert key is not None and (key in err.field or (err.field == "arm" and key in ("mass_kg", "damping_ns_per_m")))
        return
    loop = ServoLoop(dev, (), {"force": dev}, period_s=1e-3, passivity=True, objects=[("A", [Spring(2.0)])])
    loop.start(0.05)
    while loop.tick():
        st_ = dev.read_state()
        assert all(math.isfinite(float(v)) for v in st_.position_mm)
        sent = dev.read_back().force_n
        assert sent is None or math.isfinite(sent)
    loop.finish()
    dev.close()

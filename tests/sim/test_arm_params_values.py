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

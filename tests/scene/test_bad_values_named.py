"""Values of the wrong JSON type where a name or a number is expected: a named
ValidationError, never a TypeError from inside (found by mutating the example scenes at
random: an unhashable `shape`, and an option a plugin fed to numpy unchecked)."""

import pytest

from hapticsdk.argcheck import call_with_options
from hapticsdk.errors import ValidationError
from hapticsdk.scene.geometry import shape_from_dict


@pytest.mark.parametrize("shape", [[], {}, ["box"], 3, None, True, 1.5])
def test_a_shape_that_is_not_a_name(shape):
    with pytest.raises(ValidationError) as ei:
        shape_from_dict({"shape": shape, "half_size_mm": [1, 1, 1]}, field="scene.objects[0].geometry")
    assert ei.value.field == "scene.objects[0].geometry.shape"


def _numpy_minded(*, gain=1.0, taps=4):
    import numpy as np
    if not np.isfinite(gain):          # TypeError for a dict or a string
        raise RuntimeError("unreachable for a number")
    return [0.0] * int(taps)           # ValueError for "many", TypeError for a list


@pytest.mark.parametrize("opts", [{"gain": {"a": 1}}, {"gain": "x"}, {"taps": "many"}, {"taps": [1]}])
def test_a_callee_that_chokes_on_an_option_value_is_named(opts):
    with pytest.raises(ValidationError) as ei:
        call_with_options(_numpy_minded, options=opts, field="plan.settings.renderer_options.x")
    assert ei.value.field == "plan.settings.renderer_options.x"
    assert "_numpy_minded" in str(ei.value)


def test_an_unknown_option_is_still_named_by_its_key():
    with pytest.raises(ValidationError) as ei:
        call_with_options(_numpy_minded, options={"gian": 2.0}, field="f")
    assert ei.value.field == "f.gian"


def test_other_errors_of_the_callee_are_not_hidden():
    def broken(**kw):
        raise RuntimeError("a bug, not bad input")
    with pytest.raises(RuntimeError):
        call_with_options(broken, options={}, field="f")

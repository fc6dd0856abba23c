"""Any value of any option of any installed actuator ends in a named error or an
actuator, never a raw exception (docs/safety.md, "Named errors").

Actuator options come from scene files (``devices.<role>.options``), plans, the device
configuration, ``--device-option`` and code, and reach the plugin's constructor through
``argcheck.call_with_options``, which named a plugin's TypeError / ValueError on a value
but let its other failures through: a scene's ``"frequency_range_hz": []`` raised
IndexError, ``{"a": 1}`` KeyError, ``"keep_s": 1e308`` / ``"y0_mm": 1e308`` /
``"encoder_resolution_mm": 5e-324`` OverflowError (a float that became an infinite int; such
an encoder now reads the position itself, as one of resolution 0),
and from code ``Decimal("sNaN")`` decimal.InvalidOperation.

A property test over the class: hypothesis draws an installed actuator, one of its keyword
options (those that name a library, port or file are privileged and left out: opening
them is not this test's business) and a value.
"""

from __future__ import annotations

import inspect
import json
from decimal import Decimal
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import hapticsdk as hs
from hapticsdk.argcheck import call_with_options
from hapticsdk.errors import HapticSDKError, ValidationError
from hapticsdk.plugins import registry

ROOT = Path(__file__).resolve().parents[2]
#: options that open something (a library, a port, a file, an audio device) or replay a run
OPENING = {"library", "port", "sdk", "backend", "device", "sink", "run", "config"}


def _options():
    reg = registry("actuator")
    out = []
    for name in sorted(reg.names()):
        try:
            cls = reg.load(name)
        except HapticSDKError:
            continue
        for p in list(inspect.signature(cls.__init__).parameters.values())[1:]:
            if p.kind == p.KEYWORD_ONLY and p.name not in OPENING:
                out.append((name, p.name))
    return out


OPTIONS = _options()
NUMBERS = st.sampled_from([10 ** 400, -10 ** 400, 1e308, -1e308, 5e-324, -5e-324, -0.0, 0, 2 ** 63, True,
                           float("nan"), float("inf"), Decimal("sNaN"), Decimal("NaN"), Decimal("1e400"),
                           Fraction(1, 3), np.longdouble("1e400"), np.float32("inf"), np.int64(-1)])
VALUES = st.one_of(NUMBERS, st.floats(), st.integers(), st.text(max_size=6), st.none(),
                   st.lists(NUMBERS | st.floats(), max_size=3), st.tuples(NUMBERS, NUMBERS),
                   st.dictionaries(st.text(max_size=3), NUMBERS, max_size=2), st.just([]), st.just([[]]))


def test_the_options_are_found():
    assert ("piezo-virtual", "frequency_range_hz") in OPTIONS and ("omni-virtual", "y0_mm") in OPTIONS


@settings(max_examples=800, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
@given(option=st.sampled_from(OPTIONS), value=VALUES)
def test_any_value_of_any_actuator_option(option, value):
    name, key = option
    try:
        act = hs.create_actuator(name, **{key: value})
    except HapticSDKError:
        return
    act.close()


@pytest.mark.parametrize("role, actuator, key, value", [
    ("vibration", "piezo-virtual", "frequency_range_hz", []), ("vibration", "piezo-virtual", "frequency_range_hz", {"a": 1}),
    ("vibration", "piezo-virtual", "keep_s", 1e308), ("force", "omni-virtual", "y0_mm", 1e308)])
def test_a_scene_file_with_such_an_option_is_refused_by_its_path(tmp_path, role, actuator, key, value):
    with pytest.raises(ValidationError) as err:
        _render_with(tmp_path, role, actuator, key, value)
    assert key in err.value.field or err.value.field.endswith(f"{role}.options") or "options" in err.value.field


def test_an_encoder_finer_than_the_float_renders_as_an_exact_one(tmp_path):
    # 5e-324 mm (was an OverflowError, named as the option's): a count that is no finite
    # number reads the position itself, as a resolution of 0 does (hapticsdk.sim.arm.readings_mm)
    fine = _render_with(tmp_path, "force", "omni-virtual", "encoder_resolution_mm", 5e-324)
    exact = _render_with(tmp_path, "force", "omni-virtual", "encoder_resolution_mm", 0.0)
    assert fine.fault is None and exact.fault is None
    assert fine.ticks == exact.ticks > 0


def _render_with(tmp_path, role, actuator, key, value):
    d = json.loads((ROOT / "examples/scenes/desk-spatial.json").read_text())
    d.setdefault("devices", {})[role] = {"actuator": actuator, "options": {key: value}}
    d["settings"]["solver"]["method"] = "polish"
    (tmp_path / "s.json").write_text(json.dumps(d))
    return hs.render_plan(hs.compile_scene(hs.load_scene(tmp_path / "s.json")), seconds=0.005)


def test_a_bug_of_the_callee_without_options_is_not_hidden():
    def broken(**kw):
        return [][0]
    with pytest.raises(IndexError):
        call_with_options(broken, options={}, field="f")

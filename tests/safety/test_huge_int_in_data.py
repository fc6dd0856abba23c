"""JSON reads ``1`` followed by 400 zeros as an int no float holds. Where a scene, plan or
run file gives one, the checks that guard the device (the energy ceiling of a piezo
``gain``, a plan's feature ranges, a run file's safety settings) refuse it by name, as
they refuse 1e308 -- they raised OverflowError instead."""

import json

import pytest

from hapticsdk.checks import check_number
from hapticsdk.devices.device_options import PrivilegedOptionError
from hapticsdk.errors import RecordingError, ValidationError

BIG = 10 ** 400


@pytest.mark.parametrize("value", [BIG, -BIG])
def test_check_number_names_an_int_beyond_the_float_range(value):
    with pytest.raises(ValidationError, match="must be finite") as exc:
        check_number(value, "x")
    assert exc.value.field == "x"


@pytest.mark.parametrize("value", [BIG, -BIG])
def test_scene_gain_beyond_the_float_range_is_refused(value):
    from hapticsdk.compiler import compile_scene
    from hapticsdk.scene import Scene

    # refused when the scene is read (every SDK format refuses a number no float holds);
    # the compiler's energy ceiling refuses it too, for a scene built past the check
    data = {"objects": [{"material": "S7"}], "settings": {"solver": {"method": "polish"}},
            "devices": {"vibration": {"actuator": "piezo-virtual", "options": {"gain": value}}}}
    with pytest.raises(ValidationError) as exc:
        Scene.from_dict(data)
    assert exc.value.field == "scene.devices.vibration.options.gain"
    scene = Scene.from_dict({**data, "devices": {"vibration": {"actuator": "piezo-virtual", "options": {"gain": 1}}}})
    scene.devices["vibration"].options["gain"] = value
    with pytest.raises(PrivilegedOptionError) as exc:
        compile_scene(scene)
    assert exc.value.field == "scene.devices.vibration.options.gain"


def test_plan_feature_beyond_the_float_range_is_refused():
    from hapticsdk.compiler import compile_scene
    from hapticsdk.runtime.render import render_plan
    from hapticsdk.scene import Scene

    plan = json.loads(json.dumps(compile_scene(Scene.for_material("S7", solver={"method": "polish"})).to_dict(),
                                 default=str))
    plan["materials"]["S7"]["features"]["GS"] = BIG
    with pytest.raises(ValidationError) as exc:
        render_plan(plan, seconds=0.01)
    assert exc.value.field == "plan.materials.S7.features.GS"


@pytest.mark.parametrize("key", ["ramp_time_s", "stiffness_offset_n", "start_max_force_n"])
def test_run_file_safety_setting_beyond_the_float_range_is_refused(key):
    from hapticsdk.runlog import recorded_settings

    with pytest.raises(RecordingError) as exc:
        recorded_settings({key: BIG})
    assert exc.value.field == f"runlog.header_json.device.safety_settings.{key}"

"""Every public reader (and the calibration writer's folder) takes a file path: None, a
number, a list or bytes raise a named hapticsdk error -- they raised TypeError from
pathlib / os (and compile_scene(None) AttributeError)."""

import pytest

import hapticsdk as hs
from hapticsdk.errors import HapticSDKError


def _readers():
    from hapticsdk.calibration import VoiceCoilCalibration, read_calibration, read_measurements_csv, save_calibration
    from hapticsdk.calibration.damping import read_excitation_csv, read_run_csv
    from hapticsdk.compiler import compile_scene
    from hapticsdk.interop.ahap import read_ahap
    from hapticsdk.interop.hjif_model import read_hjif
    from hapticsdk.plan import RenderPlan
    from hapticsdk.runlog import load_run
    from hapticsdk.runtime.recorder import load_recording
    from hapticsdk.schemas_io import read_json

    return {"load_scene": hs.load_scene, "read_calibration": read_calibration,
            "read_measurements_csv": read_measurements_csv, "read_run_csv": read_run_csv,
            "read_excitation_csv": read_excitation_csv, "load_recording": load_recording, "load_run": load_run,
            "RenderPlan.load": RenderPlan.load, "read_hjif": read_hjif, "read_ahap": read_ahap,
            "load_library": hs.load_library, "read_json": lambda v: read_json(v, field="file"),
            "save_calibration": lambda v: save_calibration(VoiceCoilCalibration(), v),
            "compile_scene": compile_scene}


@pytest.mark.parametrize("name", sorted(_readers()))
@pytest.mark.parametrize("value", [5, 1.5, ["a"], b"x.json", ""])
def test_a_path_that_is_no_path_is_a_named_error(name, value):
    with pytest.raises(HapticSDKError):
        _readers()[name](value)


@pytest.mark.parametrize("name", sorted(set(_readers()) - {"load_library", "save_calibration"}))
def test_none_is_no_path(name):
    # load_library(None) and save_calibration(cal, None) mean the defaults
    with pytest.raises(HapticSDKError):
        _readers()[name](None)

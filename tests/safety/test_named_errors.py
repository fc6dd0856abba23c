"""Named errors for API arguments and file content (issue 31, item 5): every case raises a
ValidationError (or the SDK's own error class) naming the field, never a raw TypeError,
ValueError or a crash deep in numpy, matplotlib, onnx or the operating system."""

from __future__ import annotations

import numpy as np
import pytest

import hapticsdk as hs
from hapticsdk.argcheck import MAX_SERIAL_CHARS, number, number_array, serial_number
from hapticsdk.budgets import MAX_SAMPLE_RATE_HZ
from hapticsdk.calibration import PiezoTable, VoiceCoilCalibration, save_calibration
from hapticsdk.compiler import compile_scene
from hapticsdk.errors import CalibrationError, ModelError, ValidationError
from hapticsdk.runtime.render import render_plan
from hapticsdk.schemas_io import read_json

DIMS = ["hardness", "roughness"]


@pytest.mark.parametrize("targets,field", [
    ([[0.5, "x"]], "targets[0][1]"), ([[0.5, 0.5], [None, 0.2]], "targets[1][0]"),
    ([0.5, "0.3"], "targets[1]"), ([[0.5, True]], "targets[0][1]"), ("0.5,0.5", "targets"),
])
def test_solve_array_targets_with_non_numbers_are_named(targets, field):
    with pytest.raises(ValidationError) as ei:
        hs.solve(targets, dimensions=DIMS, seed=0)
    assert ei.value.field == field


@pytest.mark.parametrize("tol", ["x", "0.1", None, True, float("nan"), -1.0, 0.0, [0.1]])
def test_solve_tolerance_must_be_a_positive_number(tol):
    with pytest.raises(ValidationError) as ei:
        hs.solve({"hardness": 0.5}, tolerance=tol, seed=0)
    assert ei.value.field == "tolerance"


def _random_value(rng, depth=0):
    """A random JSON-ish value: numbers (some non-finite), strings, bools, None, lists."""
    kind = rng.integers(0, 7 if depth < 3 else 5)
    if kind == 0:
        return float(rng.choice([rng.normal(), np.nan, np.inf, -np.inf, 1e308, -0.0]))
    if kind == 1:
        return int(rng.integers(-10, 10))
    if kind == 2:
        return rng.choice(["", "x", "0.5", "nan", "1e3"])
    if kind == 3:
        return bool(rng.integers(0, 2))
    if kind == 4:
        return None
    return [_random_value(rng, depth + 1) for _ in range(rng.integers(0, 4))]


def test_number_and_number_array_are_total():
    """Whatever the value, number() / number_array() return finite floats or raise a
    ValidationError naming the field (2000 random values, fixed seed)."""
    rng = np.random.default_rng(31)
    for _ in range(2000):
        value = _random_value(rng)
        try:
            v = number(value, "f")
        except ValidationError as exc:
            assert exc.field == "f"
        else:
            assert isinstance(v, float) and np.isfinite(v)
        try:
            arr = number_array(value, "a")
        except ValidationError as exc:
            assert exc.field.startswith("a")
        else:
            assert np.isfinite(arr).all()


def test_serial_numbers_are_bounded(tmp_path):
    ok = "s" * MAX_SERIAL_CHARS
    assert serial_number(ok) == ok
    for bad in ("s" * (MAX_SERIAL_CHARS + 1), "", "a\nb", 5):
        with pytest.raises(ValidationError):
            serial_number(bad, "serial")
    with pytest.raises(ValidationError) as ei:
        save_calibration(VoiceCoilCalibration(serial="s" * 300), tmp_path)
    assert ei.value.field == "calibration.serial"
    # the longest allowed serial, made of multibyte letters, still fits a file name
    p = save_calibration(VoiceCoilCalibration(serial="é" * MAX_SERIAL_CHARS), tmp_path)
    assert len(p.name.encode()) <= 255 and p.is_file()


def test_piezo_table_with_a_string_frequency_is_named():
    d = PiezoTable([100.0, 200.0], [0.0, 10.0], [[0.0, 1.0], [0.0, 2.0]]).to_dict()
    d["frequencies_hz"][1] = "x"
    with pytest.raises(CalibrationError, match=r"frequencies_hz\[1\]"):
        PiezoTable.from_dict(d)
    from hapticsdk_roughness.table import table_from_dict
    d["frequencies_hz"][1] = 200.0
    d["acceleration_m_s2"][1][0] = [1.0]
    with pytest.raises(CalibrationError, match=r"acceleration_m_s2: must be a rectangular array"):
        table_from_dict(d)


@pytest.mark.parametrize("opts,field", [
    ({"sink": "buffer"}, "renderer_options.hardness.sink"),
    ({"calibration": "paper"}, "renderer_options.hardness.calibration"),
    ({"calibration": {"coefficients": "x"}}, "renderer_options.hardness.calibration"),
    ({"coil_amplitude": "0.5"}, "renderer_options.hardness.coil_amplitude"),
    ({"gs_max_n_per_mm": None}, "renderer_options.hardness.gs_max_n_per_mm"),
])
def test_renderer_options_are_named_in_scene_and_plan(opts, field):
    scene = {"objects": [{"material": {"name": "h", "intensities": {"hardness": 1.0}}}]}
    with pytest.raises(ValidationError) as ei:
        compile_scene({**scene, "settings": {"renderer_options": {"hardness": opts}}})
    assert ei.value.field.startswith(f"scene.settings.{field}")
    plan = compile_scene(scene).to_dict()
    plan["settings"]["renderer_options"] = {"hardness": opts}
    with pytest.raises(ValidationError) as ei:
        render_plan(plan, seconds=0.01)
    assert ei.value.field.startswith(f"plan.settings.{field}")


@pytest.mark.parametrize("text,field", [
    ('{"a": [1, NaN]}', "x.a[1]"), ('{"a": {"b": -Infinity}}', "x.a.b"),
    ('{"a": [' + "[" * 150 + "]" * 150 + "]}", "x.a[0][0]"), ('{"a": [1, 2,]}', "x.a"),
])
def test_json_errors_name_the_path_in_the_file(tmp_path, text, field):
    p = tmp_path / "f.json"
    p.write_text(text)
    with pytest.raises(ValidationError) as ei:
        read_json(p, field="x")
    assert ei.value.field.startswith(field) and str(p) in str(ei.value)


def test_calibration_file_nan_is_named(tmp_path):
    good = save_calibration(VoiceCoilCalibration(serial="A"), tmp_path)
    good.write_text(good.read_text().replace('"coefficients": [', '"coefficients": [NaN, ', 1))
    from hapticsdk.calibration import list_calibrations
    (entry,) = list_calibrations(tmp_path)
    assert "coefficients[0]" in entry.error and "NaN" in entry.error


def test_onnx_external_data_outside_its_folder_is_a_named_error(tmp_path):
    onnx = pytest.importorskip("onnx")
    from hapticsdk_onnx import OnnxModel, load_default
    src = load_default().metadata["source_path"]
    m = onnx.load(src)
    for loc in ("../../../etc/passwd", "/etc/passwd", "weights.bin"):
        t = m.graph.initializer[0]
        t.ClearField("raw_data")
        del t.float_data[:]
        del t.external_data[:]
        t.data_location = onnx.TensorProto.EXTERNAL
        for k, v in (("location", loc), ("offset", "0"), ("length", "64")):
            e = t.external_data.add()
            e.key, e.value = k, v
        p = tmp_path / "m.onnx"
        p.write_bytes(m.SerializeToString())
        with pytest.raises(ModelError) as ei:
            OnnxModel(p)
        msg = str(ei.value)
        assert repr(t.name) in msg and "nothing was read" in msg
        assert ("outside the model's folder" in msg) == (loc != "weights.bin")


def test_sample_rate_ceilings():
    from hapticsdk_hardness.voicecoil import VoiceCoilVirtual
    from hapticsdk_roughness.virtual import PiezoVirtual
    assert VoiceCoilVirtual(sample_rate_hz=MAX_SAMPLE_RATE_HZ).fs == MAX_SAMPLE_RATE_HZ
    for bad in (1e9, float("inf"), "5000", 0.0):
        with pytest.raises(ValidationError) as ei:
            VoiceCoilVirtual(sample_rate_hz=bad)
        assert ei.value.field == "sample_rate_hz"
        with pytest.raises(ValidationError) as ei:
            PiezoVirtual(fs=bad)
        assert ei.value.field == "fs"



@pytest.mark.parametrize("cls_path,key", [("hapticsdk_hardness.voicecoil:VoiceCoilVirtual", "sample_rate_hz"),
                                          ("hapticsdk_hardness.audio:VoiceCoilAudio", "samplerate"),
                                          ("hapticsdk_roughness.virtual:PiezoVirtual", "fs")])
def test_sample_rate_floor_is_the_nyquist_rate_of_the_band(cls_path, key):
    """Every waveform actuator checks its rate with hapticsdk.budgets.check_sample_rate,
    from twice the top of its declared band (a lower rate aliases the drive frequencies it
    accepts) up to the ceiling."""
    import importlib
    mod, name = cls_path.split(":")
    cls = getattr(importlib.import_module(mod), name)
    top = cls(**{}).limits.frequency_range_hz[1]
    assert isinstance(cls(**{key: 2 * top}), cls)
    for bad in (2 * top * 0.99, top, MAX_SAMPLE_RATE_HZ * 1.01):
        with pytest.raises(ValidationError) as ei:
            cls(**{key: bad})
        assert ei.value.field.endswith(key)

def test_figure_format_is_checked_by_the_api(tmp_path):
    pytest.importorskip("matplotlib")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hapticsdk.plotting import save_figure
    fig = plt.figure()
    with pytest.raises(ValidationError, match="'exe'"):
        save_figure(fig, tmp_path / "out.exe")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("role,actuator,opts,key", [
    ("force", "omni-virtual", {"arm": {"max_force_n": 100}}, "arm"),
    ("coil", "voicecoil-virtual", {"sample_rate_hz": "5000"}, "sample_rate_hz"),
])
def test_actuator_options_from_a_plan_are_named(role, actuator, opts, key):
    scene = {"objects": [{"material": {"name": "h", "intensities": {"hardness": 1.0}}}],
             "devices": {role: {"actuator": actuator, "options": opts}}}
    with pytest.raises(ValidationError) as ei:
        render_plan(compile_scene(scene), seconds=0.01)
    assert ei.value.field == f"plan.materials.h.actuator_options.{role}.{key}"

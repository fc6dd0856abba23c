"""A run file (``.npz``) changed anywhere -- any value at any place of its header, or an
array made NaN / inf / 1e308 at one element, cut short, emptied, given another shape or
strings, or dropped -- is read, played back through PlaybackDevice and summarised, or
refused with a RecordingError naming the field: never a raw exception.

Found by this test: a header ``period_s`` of 401 digits, a list or an object (playback
steps by it: OverflowError, TypeError), and ``buttons`` holding NaN or 1e308 (cast to
int64 they became an arbitrary button mask, silently).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from json_leaves import nodes, replaced

from hapticsdk.errors import HapticSDKError, RecordingError
from hapticsdk.runlog import PlaybackDevice
from hapticsdk.runtime.recorder import load_recording

#: the values of tests/core/test_garbage_in_scene_and_plan.py (half extreme numbers)
EXTREMES = st.sampled_from([float("nan"), float("inf"), float("-inf"), 10 ** 400, -10 ** 400, 1e308, -1e308,
                            -1, 0, 2 ** 63, True])
VALUES = st.one_of(EXTREMES, st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=12)),
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=4)),
    max_leaves=8))
CHANGES = ["nan", "inf", "big", "short", "empty", "3d", "str", "drop"]


@pytest.fixture(scope="module")
def run_arrays(tmp_path_factory):
    import hapticsdk as hs
    from hapticsdk.runlog import RunRecorder
    path = tmp_path_factory.mktemp("run") / "run.npz"
    rec = RunRecorder(path)
    hs.render_plan(hs.compile_scene(hs.Scene.for_material("S7", solver={"method": "polish"})), seconds=0.02,
                   recorder=rec)
    rec.close()
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _play(tmp_path, arrays):
    p = tmp_path / "m.npz"
    with open(p, "wb") as fh:
        np.savez(fh, **arrays)
    run = load_recording(p)
    dev = PlaybackDevice(run=run)
    with dev:
        for _ in range(len(run)):
            dev.read_state()
            dev.step(run.period_s or 1e-3)
    json.dumps(run.summary(), default=str, allow_nan=False)   # strict JSON, as --json prints it


def _no_constant(name):
    raise ValueError(f"not JSON: {name}")


@pytest.mark.parametrize("v,speed", [(1e308, 3 ** 0.5 * 1e308), (1.5e308, None)])
def test_a_speed_near_the_float_range_is_strict_json(tmp_path, run_arrays, capsys, v, speed):
    """A run whose recorded velocity is ``v`` mm/s on every axis at one tick: ``hapticsdk
    replay --json`` prints strict JSON (it printed ``Infinity``, which JSON parsers refuse).
    Components of 1e308 have a length of sqrt(3) x 1e308, still a float, so that is the
    speed reported; components of 1.5e308 have one beyond the float range: null, named
    in ``not_finite`` with the reason."""
    from hapticsdk.cli import main
    vel = run_arrays["velocity_mm_s"].astype(float)
    vel[len(vel) // 2] = v
    p = tmp_path / "fast.npz"
    with open(p, "wb") as fh:
        np.savez(fh, **{**run_arrays, "velocity_mm_s": vel})
    assert main(["replay", str(p), "--json"]) == 0
    out = json.loads(capsys.readouterr().out, parse_constant=_no_constant)
    if speed is None:
        assert out["speed_mm_s_max"] is None and out["not_finite"]["speed_mm_s_max"].startswith("overflow")
    else:
        assert out["speed_mm_s_max"] == pytest.approx(speed, rel=1e-12) and "not_finite" not in out
    assert main(["replay", str(p)]) == 0     # and the text summary says it
    text = capsys.readouterr().out
    assert ("speed_mm_s_max: not finite, overflow" in text) is (speed is None)


def test_the_unchanged_run_plays(tmp_path, run_arrays):
    _play(tmp_path, run_arrays)


def _changed(a, change, i):
    a = a.astype(float) if a.dtype.kind in "biu" else a.copy()
    if change in ("nan", "inf", "big"):
        a.flat[i % a.size] = {"nan": np.nan, "inf": np.inf, "big": 1e308}[change]
        return a
    return {"short": a[: len(a) // 2], "empty": a[:0], "3d": np.zeros((2, 2, 2)),
            "str": np.array(["x"] * max(len(a), 1))}[change]


@settings(max_examples=600, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
@given(data=st.data(), value=VALUES)
def test_any_change_to_a_run_file(tmp_path_factory, run_arrays, data, value):
    arrays = dict(run_arrays)
    header = json.loads(str(arrays["header_json"]))
    if data.draw(st.booleans(), label="header"):
        groups = [[()]] + [[p for p, _ in nodes(header) if p[:1] == (k,)] for k in header]
        path = data.draw(st.sampled_from(groups).flatmap(st.sampled_from), label="place")
        try:
            arrays["header_json"] = np.array(json.dumps(value if not path else replaced(header, path, value)))
        except (TypeError, ValueError):   # not JSON at all (a dict with a NaN key, ...)
            return
    else:
        key = data.draw(st.sampled_from(sorted(k for k in arrays if k != "header_json")), label="array")
        change = data.draw(st.sampled_from(CHANGES), label="change")
        if change == "drop":
            arrays.pop(key)
        else:
            arrays[key] = _changed(arrays[key], change, data.draw(st.integers(0, 10 ** 6), label="at"))
    try:
        _play(tmp_path_factory.mktemp("m"), arrays)
    except HapticSDKError:
        pass


@pytest.mark.parametrize("period", [10 ** 400, [0.001], {"a": 1}, "0.001", 0, -1e-3, True])
def test_header_period_must_be_a_positive_number(tmp_path, run_arrays, period):
    header = json.loads(str(run_arrays["header_json"]))
    arrays = {**run_arrays, "header_json": np.array(json.dumps({**header, "period_s": period}))}
    with pytest.raises(RecordingError) as exc:
        _play(tmp_path, arrays)
    assert exc.value.field == "runlog.header_json.period_s"


@pytest.mark.parametrize("bad", [np.nan, np.inf, 1e308, 0.5, -2.0 ** 64])
def test_buttons_must_be_a_bit_mask(tmp_path, run_arrays, bad):
    b = run_arrays["buttons"].astype(float)
    b[len(b) // 2] = bad
    with pytest.raises(RecordingError) as exc:
        _play(tmp_path, {**run_arrays, "buttons": b})
    assert exc.value.field == "runlog.buttons"

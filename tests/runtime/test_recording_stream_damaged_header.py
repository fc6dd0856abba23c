"""A recording stream (``.part``) left by a crashed session may be damaged anywhere: a
header that is not the writer's (missing or wrong ``columns`` / ``roles``, a
``period_s`` that is no period, ``objects`` that map nothing) raises RecordingError
naming the field, for both writers (``.npz`` and ``.h5`` streams) -- not KeyError,
ZeroDivisionError, TypeError, AttributeError or ValueError, and no run file is written
with a period of "x"."""

import json
import struct

import numpy as np
import pytest

from hapticsdk.errors import RecordingError
from hapticsdk.runtime import recording_layout as layout
from hapticsdk.runtime.recorder import MAGIC, load_recording

COLS = layout.columns(["force"])
GOOD = {"columns": COLS, "roles": ["force"], "period_s": 0.001, "objects": {"0": "a"}}
DROP = object()

CASES = [
    ("columns", DROP, "record.columns"), ("columns", [], "record.columns"), ("columns", 5, "record.columns"),
    ("columns", ["a", "b"], "record.columns"), ("roles", DROP, "record.roles"), ("roles", "force", "record.roles"),
    ("roles", ["force", "coil"], "record.columns"), ("roles", ["force", "force"], "record.roles"),
    ("period_s", DROP, "record.period_s"), ("period_s", "x", "record.period_s"),
    ("period_s", None, "record.period_s"), ("period_s", -1, "record.period_s"),
    ("period_s", 10 ** 400, "record.period_s"), ("objects", [1], "record.objects"),
    ("objects", {"x": "a"}, "record.objects"), ("objects", {"0": 5}, "record.objects"),
    # ids that str.isdigit() takes and int() does not (a superscript, a second minus, more
    # digits than int() reads), or that no float64 object-id column holds exactly
    ("objects", {"\u00b2": "a"}, "record.objects"), ("objects", {"--1": "a"}, "record.objects"),
    ("objects", {"9" * 5000: "a"}, "record.objects"), ("objects", {str(2 ** 53 + 1): "a"}, "record.objects"),
]


def _header(key, value):
    h = dict(GOOD)
    if value is DROP:
        del h[key]
    else:
        h[key] = value
    return h


def _npz_part(tmp_path, header, text=None):
    p = tmp_path / "run.npz.part"
    head = (text if text is not None else json.dumps(header) if header is not None else "[1, 2]").encode(
        "utf-8", "surrogateescape")
    head += b" " * (-len(head) % 8)
    p.write_bytes(MAGIC + struct.pack("<Q", len(head)) + head + np.arange(3.0 * len(COLS)).tobytes())
    return p


@pytest.mark.parametrize("key, value, field", CASES)
def test_npz_stream_with_a_damaged_header(tmp_path, key, value, field):
    with pytest.raises(RecordingError) as exc:
        load_recording(_npz_part(tmp_path, _header(key, value)))
    assert exc.value.field == field
    assert not (tmp_path / "run.npz").exists()


def test_npz_stream_whose_header_is_no_object(tmp_path):
    with pytest.raises(RecordingError) as exc:
        load_recording(_npz_part(tmp_path, None))
    assert exc.value.field == "record.header"


@pytest.mark.parametrize("key, value, field", CASES)
def test_h5_stream_with_a_damaged_header(tmp_path, key, value, field):
    pytest.importorskip("h5py")
    from hapticsdk.runtime.recorder_h5 import H5Appender

    p = tmp_path / "run.h5.part"
    app = H5Appender(p, GOOD, 4)
    app.append(np.zeros((2, len(COLS))))
    app.close()
    import h5py
    with h5py.File(p, "r+") as f:
        f.attrs["stream_header_json"] = json.dumps(_header(key, value))
    with pytest.raises(RecordingError) as exc:
        load_recording(p)
    assert exc.value.field == field


def test_good_stream_still_loads(tmp_path):
    run = load_recording(_npz_part(tmp_path, GOOD))
    assert run.n_ticks == 3 if hasattr(run, "n_ticks") else run is not None


#: header texts no JSON reader of the SDK accepts: nested past its depth bound (the
#: stream reader's bare json.loads raised RecursionError), a NaN literal, not UTF-8
TEXTS = ["[" * 100000 + "]" * 100000, json.dumps(GOOD)[:-1] + ', "period_s": NaN}', "\udcff"]
IDS = ["deep", "nan", "not-utf8"]


@pytest.mark.parametrize("text", TEXTS, ids=IDS)
def test_npz_stream_whose_header_is_no_plain_json(tmp_path, text):
    with pytest.raises(RecordingError) as exc:
        load_recording(_npz_part(tmp_path, None, text))
    assert exc.value.field.startswith("record")
    assert not (tmp_path / "run.npz").exists()


@pytest.mark.parametrize("text", TEXTS, ids=IDS)
def test_h5_stream_whose_header_is_no_plain_json(tmp_path, text):
    pytest.importorskip("h5py")
    from hapticsdk.runtime.recorder_h5 import H5Appender

    p = tmp_path / "run.h5.part"
    app = H5Appender(p, GOOD, 4)
    app.append(np.zeros((2, len(COLS))))
    app.close()
    import h5py
    with h5py.File(p, "r+") as f:  # str as the writer stores it; bytes where str cannot hold it
        f.attrs["stream_header_json"] = np.bytes_(text.encode("utf-8", "surrogateescape")) if "\udcff" in text else text
    with pytest.raises(RecordingError) as exc:
        load_recording(p)
    assert exc.value.field.startswith("record")
